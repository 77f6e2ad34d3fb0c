// Selection of the k-th smallest of a few values, for per-texel medians (private to the
// library).
#pragma once

#include <cstddef>
#include <utility>

namespace digitize {

// The k-th smallest of a[0, n) (0 <= k < n): the value std::nth_element puts at k. Quickselect
// whose partition has no branch: each value is written to both halves' ends and only the right
// end advances. For the ~60 samples of a texel, std::nth_element's unpredictable branches were
// most of the fit's dark-outlier prefilter (reflectance_fit.cpp), itself an eighth of the fit on
// fit_bench; this takes about half nth_element's time (measured). Terminates on any input (each
// round keeps fewer values: the pivot is one of them); NaN compares equal to every pivot.
// `a` is overwritten; b and c are scratch of n values each.
inline double SelectKth(double* a, double* b, double* c, size_t n, size_t k) {
  double* src = a;
  double* spare[2] = {b, c};
  while (n > 1) {
    double x0 = src[0], x1 = src[n / 2], x2 = src[n - 1];  // the pivot: a median of three
    if (x0 > x1) std::swap(x0, x1);
    if (x1 > x2) std::swap(x1, x2);
    if (x0 > x1) std::swap(x0, x1);
    const double pivot = x1;
    double *below = spare[0], *above = spare[1];
    size_t n_below = 0, n_above = 0;
    for (size_t j = 0; j < n; ++j) {
      const double x = src[j];
      below[n_below] = x;
      above[n_above] = x;
      n_below += x < pivot;
      n_above += x > pivot;
    }
    if (k < n_below) {
      spare[0] = src, spare[1] = above, src = below, n = n_below;
    } else if (k < n - n_above) {
      return pivot;  // the values equal to the pivot, which is one of them
    } else {
      k -= n - n_above;
      spare[0] = src, spare[1] = below, src = above, n = n_above;
    }
  }
  return src[0];
}

}  // namespace digitize
