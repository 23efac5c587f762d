"""The estimated shape error of a level (georeg_plugin.levels.risk) against a known truth."""
import numpy as np
import pytest

from georeg_plugin.levels.risk import estimated_risk, node_metric


def _nested_bases(x: np.ndarray, degrees=(1, 3, 7)) -> list[np.ndarray]:
    """Polynomial spaces of rising degree on the nodes x: nested, C_s (m_s, n)."""
    return [np.vander(x, d + 1, increasing=True).T for d in degrees]


def _step_map(C: np.ndarray, H: np.ndarray) -> np.ndarray:
    return C.T @ np.linalg.solve(C @ H @ C.T, C)                       # G_s (Eqs. 18-21)


def test_node_metric_leaves_out_the_modes_and_weighs_by_area():
    rng = np.random.default_rng(0)
    n = 40
    w = rng.uniform(0.5, 2.0, n)
    modes = np.stack([np.ones(n), np.linspace(-1, 1, n)], axis=1)
    metric = node_metric(w, modes)
    assert metric.norm2(modes @ np.array([0.3, -2.0])) == pytest.approx(0.0, abs=1e-12)
    d = rng.standard_normal(n)
    W = np.diag(w / w.sum())
    fit = modes @ np.linalg.solve(modes.T @ W @ modes, modes.T @ W @ d)    # weighted LS fit
    assert metric.norm2(d) == pytest.approx(float((d - fit) @ W @ (d - fit)), rel=1e-10)
    G = rng.standard_normal((n, n))
    G = G @ G.T
    M = W - W @ modes @ np.linalg.solve(modes.T @ W @ modes, modes.T @ W)
    assert metric.trace(np.diag(G), lambda V: G @ V) == pytest.approx(np.trace(M @ G), rel=1e-10)


def test_node_metric_refuses_bad_weights():
    with pytest.raises(ValueError, match="weights"):
        node_metric(np.array([1.0, -1.0, 2.0]))


def test_estimated_risk_is_unbiased_for_every_level():
    """Linear Gauss-Newton problem with Cov(b) = v H: the mean over noise draws of each level's
    estimated risk matches the mean of its true squared error (modulo a rigid mode) within
    their Monte Carlo spread, for levels too coarse (bias), right, and too fine (noise)."""
    rng = np.random.default_rng(1)
    n, n_obs, v = 30, 400, 0.04
    x = np.linspace(-1.0, 1.0, n)
    J = rng.standard_normal((n_obs, n)) * rng.uniform(0.5, 1.5, n)
    H = J.T @ J
    q_true = 0.6 * x ** 2 - 0.5 * x ** 3 + 0.05 * np.cos(9 * x)          # not in any coarse level
    bases = _nested_bases(x) + [np.eye(n)]                                # the finest holds it
    G = [_step_map(C, H) for C in bases]
    metric = node_metric(np.full(n, 1.0 / n), np.ones((n, 1)))
    traces = [metric.trace(np.diag(g), lambda V, g=g: g @ V) for g in G]
    estimated, true = np.zeros((400, len(G))), np.zeros((400, len(G)))
    for k in range(estimated.shape[0]):
        b = J.T @ (J @ q_true + np.sqrt(v) * rng.standard_normal(n_obs))
        q = [g @ b for g in G]
        for s in range(len(G)):
            estimated[k, s] = estimated_risk(q[s] - q[-1], traces[s], traces[-1], v, metric)[0]
            true[k, s] = metric.norm2(q[s] - q_true)
    spread = np.sqrt(estimated.var(axis=0) / estimated.shape[0]
                     + true.var(axis=0) / true.shape[0])
    assert np.all(np.abs(estimated.mean(axis=0) - true.mean(axis=0)) < 4 * spread + 1e-4 * true.mean(axis=0))
    # the least estimated risk picks the level of least true risk in most draws
    assert np.mean(estimated.argmin(axis=1) == true.mean(axis=0).argmin()) > 0.8
