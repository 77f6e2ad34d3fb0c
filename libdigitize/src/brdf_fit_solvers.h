// The seam between the per-texel front end (brdf_fit.cpp: the diffuse-only test, the coarse grid
// over k, the texel's status; the samples are filtered into a TexelProblem, brdf_fit_problem.h)
// and the solvers that fit the lobe from the grid's start. One solver a file, each behind the
// same signature: a new solver is a new file, one declaration here, one BrdfFitMethod value
// (brdf_fit.h) and one case in LobeSolverFor (brdf_fit.cpp); the other solvers stay untouched.
// Private to the BRDF layer.
#pragma once

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

}  // namespace digitize::brdf_detail
