"""The linear solve of a Gauss-Newton step (the one extension point), the damped Gauss-Newton loop and Tikhonov (Eq. 10)."""

from fesdic_core.solve.damping import ACCEPT_RTOL, MU_START, damped_step, relaxed
from fesdic_core.solve.gauss_newton import (GaussNewtonOutcome, damped, predicted_change,
                                            damped_gauss_newton)
from fesdic_core.solve.solvers import (SingularSystemError, StepSolver, StartScaleHook,
                                       StepCovarianceHook, BiasStepHook, FactorizeHook,
                                       sparse_solve, sparse_factor,
                                       seen_dofs, DirectSolver, CachedFactorization,
                                       inverse_diagonal, inverse_covariance)
from fesdic_core.solve.tikhonov import (surface_gradient_operator, tikhonov_weight, WEAKER_FACTOR,
                                        TikhonovSolver)
from fesdic_core.solve.tikhonov_choice import (DENSE_CP_MAX_DOFS, DENSE_COVARIANCE_MAX_DOFS,
                                               HUTCHINSON_PROBES, HUTCHINSON_SEED, COLUMN_BLOCK,
                                               GRID_SIZE, CpCurve, element_size, mesh_extent,
                                               length_grid, mallows_cp, covariance_diagonal)

__all__ = ["ACCEPT_RTOL", "MU_START", "damped_step", "relaxed", "GaussNewtonOutcome", "damped",
           "predicted_change", "damped_gauss_newton", "SingularSystemError", "StepSolver",
           "StartScaleHook", "StepCovarianceHook", "BiasStepHook", "FactorizeHook",
           "sparse_solve", "sparse_factor", "seen_dofs", "DirectSolver", "CachedFactorization",
           "inverse_diagonal", "inverse_covariance", "surface_gradient_operator", "tikhonov_weight",
           "WEAKER_FACTOR", "TikhonovSolver", "DENSE_CP_MAX_DOFS", "DENSE_COVARIANCE_MAX_DOFS",
           "HUTCHINSON_PROBES", "HUTCHINSON_SEED", "COLUMN_BLOCK", "GRID_SIZE", "CpCurve",
           "element_size", "mesh_extent", "length_grid", "mallows_cp", "covariance_diagonal"]
