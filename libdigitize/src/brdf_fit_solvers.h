// The seam between the per-texel front end (brdf_fit.cpp: the diffuse-only test, the coarse grid
// over k, the texel's status; the samples are filtered into a TexelProblem, brdf_fit_problem.h)
// and the solvers that fit the lobe from the grid's start. One solver a file, each behind the
// same signature: a new solver is a new file, one declaration here, one BrdfFitMethod value
// (brdf_fit.h) and one case in LobeSolverFor (brdf_fit.cpp); the other solvers stay untouched.
// Private to the BRDF layer.
#pragma once

#include <limits>

#include "brdf_fit_problem.h"
#include "digitize/brdf_fit.h"

namespace digitize::brdf_detail {

// What a solver hands back: the lobe shape (inside the bounds), the linear part for it, the
// squared error of the samples (no priors), measured by TexelProblem::Sse so every solver
// reports alike, and how the solver ended.
struct LobeFitOutcome {
  Shape shape;
  LinearFit linear;
  double sse = 0;
  int iterations = 0;
  bool converged = false;
  bool failed = false;
};

// Fits the lobe of `problem` from `init` within `bounds` (options: the iteration limit and the
// energy bound); `problem` holds the texel's samples and is the solver's scratch.
using LobeSolver = LobeFitOutcome (*)(TexelProblem& problem, Shape init, const Bounds& bounds,
                                      const BrdfFitOptions& options);

// Bounded Levenberg-Marquardt on (cx, cy, log k) of the variable-projection cost
// (brdf_fit_varpro.cpp).
LobeFitOutcome FitLobeVarPro(TexelProblem& problem, Shape init, const Bounds& bounds,
                             const BrdfFitOptions& options);
// ceres::Solve on the full problem, the reference (brdf_fit_ceres.cpp; the only file that
// includes Ceres).
LobeFitOutcome FitLobeCeres(TexelProblem& problem, Shape init, const Bounds& bounds,
                            const BrdfFitOptions& options);

// The solver of `method`.
LobeSolver LobeSolverFor(BrdfFitMethod method);

// GGX (brdf_fit_problem.h): only t = log alpha is nonlinear. `start` comes from the front end's
// grid: the best grid point and its neighbours (the bracket), inside [t_lo, t_hi], the bounds,
// and the grid's costs there (from the sums; NaN where a bracket end is t itself).
struct GgxStart {
  double t = 0, bracket_lo = 0, bracket_hi = 0, t_lo = 0, t_hi = 0;
  double cost_lo = std::numeric_limits<double>::quiet_NaN(),
         cost_hi = std::numeric_limits<double>::quiet_NaN();
};
struct GgxFitOutcome {
  double t = 0;      // log alpha, inside the bounds
  LinearFit linear;  // (rho_d, F0) per channel for it
  double sse = 0;    // weighted squared error, TexelProblem::GgxSse (every solver alike)
  int iterations = 0;
  bool converged = false;
  bool failed = false;
};
using GgxSolver = GgxFitOutcome (*)(TexelProblem& problem, const GgxStart& start,
                                    const BrdfFitOptions& options);
// Brent's 1-D minimisation of the variable-projection cost over log alpha in the bracket
// (brdf_fit_varpro.cpp).
GgxFitOutcome FitGgxVarPro(TexelProblem& problem, const GgxStart& start,
                           const BrdfFitOptions& options);
// ceres::Solve on all 7 unknowns from the grid's start (brdf_fit_ceres.cpp).
GgxFitOutcome FitGgxCeres(TexelProblem& problem, const GgxStart& start,
                          const BrdfFitOptions& options);
GgxSolver GgxSolverFor(BrdfFitMethod method);

}  // namespace digitize::brdf_detail
