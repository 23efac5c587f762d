"""The Levenberg-Marquardt guard: the residual never grows; mu rises tenfold per refusal."""
from types import SimpleNamespace

from fesdic_core.solve.damping import ACCEPT_RTOL, MU_START, damped_step, relaxed


def _proposals(stds):
    tried = []

    def propose(mu):
        tried.append(mu)
        return ("step", SimpleNamespace(std_percent=stds[len(tried) - 1]))
    return propose, tried


def test_the_first_step_that_does_not_raise_the_residual_is_taken():
    propose, tried = _proposals([2.0, 1.5, 0.9])
    step, mu = damped_step(propose, 1.0, 0.0, max_damping=5)
    assert step[1].std_percent == 0.9
    assert tried == [0.0, MU_START, 10 * MU_START] and mu == 10 * MU_START


def test_round_off_is_not_a_rise_but_more_is():
    propose, _ = _proposals([1.0 * (1 + 0.5 * ACCEPT_RTOL)])
    assert damped_step(propose, 1.0, 0.0, 0)[0] is not None
    propose, _ = _proposals([1.0 * (1 + 2 * ACCEPT_RTOL)])
    assert damped_step(propose, 1.0, 0.0, 0)[0] is None


def test_no_acceptable_step_after_the_allowed_increases():
    propose, tried = _proposals([2.0] * 4)
    step, mu = damped_step(propose, 1.0, 1.0, max_damping=3)
    assert step is None and tried == [1.0, 10.0, 100.0, 1000.0] and mu == 10000.0
    assert relaxed(10.0) == 1.0 and relaxed(1e-9) == 0.0
