"""The optional hooks of a step solver as runtime-checkable protocols (fesdic_core.solve).

The core finds each hook with ``isinstance(solver, Hook)``: a class is recognised by having
the method (no inheritance, no import of the core), and a driver still calls the hooks of a
solver that has them. (The plugin's solver: tests/adapters/test_fesdic_core_adapter.py.)
"""
import numpy as np
import pytest
import scipy.sparse as sps

import fesdic_core
from fesdic_core.displacement.solvers import ComponentTikhonovSolver
from fesdic_core.fe.mesh import rectangle_mesh
from fesdic_core.shape.driver import MeasurementSettings, measure
from fesdic_core.shape.uncertainty import NoiseModel, shape_std
from fesdic_core.solve import (BiasStepHook, CachedFactorization, DirectSolver, FactorizeHook,
                               StartScaleHook, StepCovarianceHook, StepSolver, TikhonovSolver)

#: each hook and the method that makes it
HOOKS = {StartScaleHook: "start_scale", StepCovarianceHook: "step_covariance",
         BiasStepHook: "bias_step", FactorizeHook: "factorize"}


def _solvers():
    mesh = rectangle_mesh(10.0, 8.0, 4, 3, family="Q4")
    return {"DirectSolver": DirectSolver(), "TikhonovSolver": TikhonovSolver(mesh, 2.0),
            "ComponentTikhonovSolver": ComponentTikhonovSolver(mesh, 2.0),
            "CachedFactorization": CachedFactorization(DirectSolver())}


#: the hooks each of the core's solvers implements
IMPLEMENTS = {
    "DirectSolver": {StepCovarianceHook, BiasStepHook, FactorizeHook},
    "TikhonovSolver": {StartScaleHook, StepCovarianceHook, BiasStepHook},
    "ComponentTikhonovSolver": {StartScaleHook, FactorizeHook},
    "CachedFactorization": set(),
}


@pytest.mark.parametrize("name", sorted(IMPLEMENTS))
def test_each_core_solver_is_recognised_by_the_hooks_it_has(name):
    solver = _solvers()[name]
    assert isinstance(solver, StepSolver)
    for hook, method in HOOKS.items():
        assert isinstance(solver, hook) == (hook in IMPLEMENTS[name]), (name, hook.__name__)
        assert isinstance(solver, hook) == callable(getattr(solver, method, None)), method


class _SolveOnly:
    def solve(self, H, b, q, scale):
        return DirectSolver().solve(H, b, q, scale)


class _HookSetToNone(_SolveOnly):
    start_scale = None        # an attribute of that name that is no method is no hook


@pytest.mark.parametrize("hook", list(HOOKS), ids=lambda h: h.__name__)
def test_a_solver_without_the_method_is_not_a_hook(hook):
    assert isinstance(_SolveOnly(), StepSolver)
    assert not isinstance(_SolveOnly(), hook)
    assert not isinstance(_HookSetToNone(), hook)
    assert not isinstance(object(), StepSolver)


def test_the_hooks_are_exported_by_the_package():
    for hook in HOOKS:
        assert hook.__name__ in fesdic_core.__all__ and getattr(fesdic_core, hook.__name__) is hook
        assert hook.__name__ in fesdic_core.solve.__all__
    from fesdic_core.solve.solvers import StepSolver as again      # the old path still works
    assert again is StepSolver


class _Recorder(_SolveOnly):
    """A plain step solver that implements start_scale and step_covariance, recording calls."""

    def __init__(self):
        self.started, self.covariances = [], []

    def start_scale(self, scale, noise):
        self.started.append((scale, noise))

    def step_covariance(self, H, scale):
        self.covariances.append(scale)
        return DirectSolver().step_covariance(H, scale)


def test_the_shape_driver_calls_the_hooks_a_solver_has(twisted_scene):
    """start_scale once per image scale, coarse to fine, with the noise model of that scale;
    step_covariance once at the end, at the finest scale, giving the shape's std."""
    _, cameras, images = twisted_scene
    mesh = rectangle_mesh(60.0, 40.0, 6, 4, family="Q4")
    solver = _Recorder()
    m = measure(mesh, images, cameras, solver, MeasurementSettings(scales=(1, 0), max_iter=3))
    assert [scale for scale, _ in solver.started] == [1, 0]
    for scale, noise in solver.started:
        assert isinstance(noise, NoiseModel) and noise.scale == scale
        assert np.isfinite(noise.variance) and noise.variance > 0.0
    assert solver.covariances == [0]
    assert m.shape_std_mm is not None and np.all(np.isfinite(m.shape_std_mm))
    assert m.shape_bias_mm is None                     # no bias_step: no bias indicator
    np.testing.assert_array_equal(m.shape_uncertainty_mm, m.shape_std_mm)   # the std alone


def test_shape_std_is_none_for_a_solver_without_step_covariance():
    H = sps.identity(4, format="csr") * 2.0
    assert shape_std(H, 1.0, _SolveOnly()) is None
    np.testing.assert_allclose(shape_std(H, 1.0, DirectSolver()), np.sqrt(0.5))
