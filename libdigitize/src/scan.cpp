// Scan clean-up: garbage and isolated spikes to NaN; merging exposures of one pose.
#include "digitize/scan.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace digitize {
namespace {

// Rows per TBB task: large enough that scheduling is negligible against a row of 4096 samples.
constexpr int kRowGrain = 16;

std::string Size(const Grid<Vec3f>& g) {
  return std::to_string(g.width) + "x" + std::to_string(g.height);
}

struct SanitizeCounts {
  size_t missing = 0, non_finite = 0;
};

// Median of values[0..n) (the mean of the two middle ones for even n), and max - min in *spread.
// n is the number of valid exposures at a pixel: a handful, so small cases are spelled out and
// the rest use insertion sort (in place).
float MedianAndSpread(float* values, int n, float* spread) {
  if (n == 1) {
    *spread = 0;
    return values[0];
  }
  if (n == 2) {
    *spread = std::abs(values[0] - values[1]);
    return 0.5f * (values[0] + values[1]);
  }
  if (n == 3) {
    const float a = values[0], b = values[1], c = values[2];
    *spread = std::max({a, b, c}) - std::min({a, b, c});
    return std::max(std::min(a, b), std::min(std::max(a, b), c));
  }
  for (int i = 1; i < n; ++i) {
    const float v = values[i];
    int j = i - 1;
    for (; j >= 0 && values[j] > v; --j) values[j + 1] = values[j];
    values[j + 1] = v;
  }
  *spread = values[n - 1] - values[0];
  return n % 2 == 1 ? values[n / 2] : 0.5f * (values[n / 2 - 1] + values[n / 2]);
}

struct MergeCounts {
  size_t filled = 0, disagreeing = 0;
};

}  // namespace

Status SanitizeOptions::Validate() const {
  if (!(max_abs_coordinate_mm > 0)) {  // also rejects NaN
    return Error{"max_abs_coordinate_mm must be > 0, got " + std::to_string(max_abs_coordinate_mm)};
  }
  if (!(spike_mm > 0)) return Error{"spike_mm must be > 0, got " + std::to_string(spike_mm)};
  return Status::Ok();
}

SanitizeStats SanitizeScan(Scan& scan, const SanitizeOptions& options) {
  const Status valid_options = options.Validate();
  DIGITIZE_CHECK(valid_options.ok(), "SanitizeScan: " + valid_options.message());
  Grid<Vec3f>& xyz = scan.xyz_mm;
  const int width = xyz.width, height = xyz.height;
  const auto max_abs = static_cast<float>(std::min<double>(options.max_abs_coordinate_mm, 3e38));
  const auto spike = static_cast<float>(std::min<double>(options.spike_mm, 3e38));
  const Vec3f missing = Vec3f::Constant(kMissing);

  // Pass 1: every sample that is not a usable point becomes all-NaN, so that pass 2 can tell
  // valid neighbours by their Z alone.
  const auto pass1 = [&](const tbb::blocked_range<int>& rows, SanitizeCounts counts) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      Vec3f* p = xyz.Row(y);
      for (int x = 0; x < width; ++x) {
        const Vec3f a = p[x].cwiseAbs();
        if (a.x() <= max_abs && a.y() <= max_abs && a.z() <= max_abs) continue;  // NaN fails too
        if (std::isnan(p[x].x()) || std::isnan(p[x].y()) || std::isnan(p[x].z())) {
          ++counts.missing;
        } else {
          ++counts.non_finite;
        }
        p[x] = missing;
      }
    }
    return counts;
  };
  // Pass 2: a valid sample whose Z is farther than spike_mm from every valid 8-neighbour is an
  // isolated outlier. One with no valid neighbour has nothing to disagree with and stays. Spikes
  // are listed per row (they are rare) and cleared only after all rows have been judged.
  std::vector<std::vector<int>> spike_columns(static_cast<size_t>(height));
  const auto pass2 = [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      const Vec3f* up = y > 0 ? xyz.Row(y - 1) : nullptr;
      const Vec3f* row = xyz.Row(y);
      const Vec3f* down = y + 1 < height ? xyz.Row(y + 1) : nullptr;
      for (int x = 0; x < width; ++x) {
        const float z = row[x].z();
        if (std::isnan(z)) continue;
        bool has_neighbour = false, close = false;
        const auto visit = [&](const Vec3f* r, int nx) {
          const float zn = r[nx].z();
          if (std::isnan(zn)) return;
          has_neighbour = true;
          close = close || std::abs(z - zn) <= spike;
        };
        const int x0 = std::max(x - 1, 0), x1 = std::min(x + 1, width - 1);
        for (int nx = x0; nx <= x1 && !close; ++nx) {
          if (nx != x) visit(row, nx);
          if (up) visit(up, nx);
          if (down) visit(down, nx);
        }
        if (has_neighbour && !close) spike_columns[y].push_back(x);
      }
    }
  };
  const tbb::blocked_range<int> all_rows(0, height, kRowGrain);
  const SanitizeCounts garbage = tbb::parallel_reduce(
      all_rows, SanitizeCounts{}, pass1, [](SanitizeCounts a, const SanitizeCounts& b) {
        return SanitizeCounts{a.missing + b.missing, a.non_finite + b.non_finite};
      });
  tbb::parallel_for(all_rows, pass2);
  size_t spikes = 0;
  for (int y = 0; y < height; ++y) {
    for (int x : spike_columns[y]) xyz(x, y) = missing;
    spikes += spike_columns[y].size();
  }

  SanitizeStats stats;
  stats.total = xyz.size();
  stats.missing = garbage.missing;
  stats.non_finite = garbage.non_finite;
  stats.spikes = spikes;
  stats.valid = stats.total - stats.missing - stats.non_finite - stats.spikes;
  return stats;
}

Status MergeOptions::Validate() const {
  if (!(disagree_mm > 0))
    return Error{"disagree_mm must be > 0, got " + std::to_string(disagree_mm)};
  return Status::Ok();
}

Result<Scan> MergeExposures(const std::vector<Scan>& exposures, const MergeOptions& options,
                            MergeStats* stats) {
  if (exposures.empty()) return Error{"MergeExposures: no exposures to merge (empty list)"};
  const Scan& first = exposures.front();
  if (const Status valid = options.Validate(); !valid.ok()) {
    return Error{first.source + ": merging exposures: " + valid.message()};
  }
  for (size_t i = 1; i < exposures.size(); ++i) {
    const Grid<Vec3f>& g = exposures[i].xyz_mm;
    if (g.width != first.xyz_mm.width || g.height != first.xyz_mm.height) {
      return Error{exposures[i].source + ": exposure " + std::to_string(i + 1) + " is " + Size(g) +
                   " samples but the first exposure (" + first.source + ") is " +
                   Size(first.xyz_mm) + "; exposures of one pose must share one grid"};
    }
  }

  const int n = static_cast<int>(exposures.size());
  const int width = first.xyz_mm.width, height = first.xyz_mm.height;
  const auto disagree = static_cast<float>(options.disagree_mm);
  Scan merged;
  for (const Scan& e : exposures) merged.source += (merged.source.empty() ? "" : " + ") + e.source;
  // Every sample is written below; Eigen's default constructor leaves the storage untouched, so
  // the pages are first touched by the parallel loop instead of by a serial fill.
  merged.xyz_mm.width = width;
  merged.xyz_mm.height = height;
  merged.xyz_mm.data.resize(static_cast<size_t>(width) * static_cast<size_t>(height));

  const auto merge_rows = [&](const tbb::blocked_range<int>& rows, MergeCounts counts) {
    std::vector<float> values(static_cast<size_t>(3 * n));  // per coordinate, the valid samples
    float* coord[3] = {values.data(), values.data() + n, values.data() + 2 * n};
    std::vector<const Vec3f*> in(static_cast<size_t>(n));
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int e = 0; e < n; ++e) in[e] = exposures[e].xyz_mm.Row(y);
      Vec3f* out = merged.xyz_mm.Row(y);
      for (int x = 0; x < width; ++x) {
        int k = 0;
        for (int e = 0; e < n; ++e) {
          const Vec3f& p = in[e][x];
          if (!IsValid(p)) continue;
          coord[0][k] = p.x(), coord[1][k] = p.y(), coord[2][k] = p.z();
          ++k;
        }
        if (k == 0) {
          out[x] = Vec3f::Constant(kMissing);
          continue;
        }
        if (k < n) ++counts.filled;
        float spread[3];
        for (int c = 0; c < 3; ++c) out[x][c] = MedianAndSpread(coord[c], k, &spread[c]);
        if (std::max({spread[0], spread[1], spread[2]}) > disagree) ++counts.disagreeing;
      }
    }
    return counts;
  };
  const MergeCounts counts =
      tbb::parallel_reduce(tbb::blocked_range<int>(0, height, kRowGrain), MergeCounts{}, merge_rows,
                           [](MergeCounts a, const MergeCounts& b) {
                             a.filled += b.filled;
                             a.disagreeing += b.disagreeing;
                             return a;
                           });
  if (stats) {
    stats->exposures = n;
    stats->filled_from_others = counts.filled;
    stats->disagreeing = counts.disagreeing;
  }
  return merged;
}

}  // namespace digitize
