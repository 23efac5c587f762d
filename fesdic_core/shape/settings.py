"""What a shape measurement is asked to do, and what it returns.

:class:`MeasurementSettings` (the schedule of scales, the fixed point's tolerances, the
verdict's thresholds), :class:`ScaleReport` (how one image scale ended) and
:class:`Measurement` (the measured shape, the final cameras and the verdict) of
:func:`fesdic_core.shape.driver.measure`; the displacement driver shares the first two.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fesdic_core.fe.quadrature import PixelQuadrature
from fesdic_core.imaging.noise import CONSISTENCY_FACTOR
from fesdic_core.residual.edges import DEFAULT_EDGE_MARGIN_PX
from fesdic_core.residual.graylevel import NORMALISATIONS, GrayLevelResidual
from fesdic_core.residual.validity import NodeValidity
from fesdic_core.residual.visibility import VisibilitySettings
from fesdic_core.shape.joint import COUPLINGS
from fesdic_core.shape.uncertainty import LinearisedState, NoiseModel

__all__ = ["SHAPE_MAX_INVALID_SHARE", "MeasurementSettings", "ScaleReport", "Measurement"]

#: by default a shape measurement reports its nodes' local validity without failing on it.
#: Measured (tests/fesdic_core/shape/test_shape_validity.py, the noise-free 60 x 40 mm twisted
#: plate, the mesh over the whole plate): calibrated, 18 % of the nodes are invalid, along the
#: plate's edges, most of them within 1-3 um of the truth (a few 17-44 um); without the edge
#: margin, 24 % (the band's drag, 7 um against 2 um for the valid nodes). No share separates
#: the two, where the displacement's 3 % does (noisy images, local divergences): set it (e.g.
#: :data:`~fesdic_core.residual.validity.DEFAULT_MAX_INVALID_SHARE`) to fail on it
SHAPE_MAX_INVALID_SHARE = 1.0


@dataclass(frozen=True)
class MeasurementSettings:
    """How to run a measurement.

    scales : image scales coarse to fine, e.g. (2, 1, 0); 0 is the full resolution.
    calibrate : run the fixed point with calibration of the extrinsics (Eq. 6).
    tol_mm, fixed_point_tol_mm : stagnation of q at scale 0 (mm); at scale s they are
        multiplied by 2**s (a coarse pixel is 2**s fine pixels).
    fixed_point_tol_px : stagnation of the poses: largest shift of the projected nodes
        between two fixed-point iterations, in pixels of the current scale. The fixed point
        has also stagnated when two iterations fit the images equally well (chi-square
        changes by less than 1, :func:`~fesdic_core.shape.operators.chi_square_change`): p and q
        then move within their own noise; and when the calibration of a later iteration
        takes no step (its step is stagnant before it is evaluated), since the shape that
        ended the previous iteration already sits at its optimum for these poses. The
        calibration inside the fixed point does not damp a step that would move the points
        by less than ``fixed_point_tol_px``: if that step does not lower the residual, the
        poses have stagnated (such a step cannot change the fixed point's verdict).
    fixed_point_rtol : at a coarse scale (not the finest), the shape Gauss-Newton and the
        fixed point also hand over to the next scale when the residual falls by less than
        this fraction in an iteration (a coarse scale only starts the next, Remark 3); at
        the finest scale only the stagnation of p and q ends them.
    keep_stereo : when calibrating, keep the stereo relation of the initial cameras
        (6 unknowns) instead of freeing both cameras (12 unknowns).
    coupling : when calibrating, "joint" (one Gauss-Newton on the poses and the shape
        together, :mod:`fesdic_core.shape.joint`, ``max_joint_iter`` iterations at most per
        scale) or "alternate" (the fixed point of section 2.2: calibration and shape in turn,
        ``max_fixed_point`` times at most, each Gauss-Newton ``max_iter`` iterations at most).
    consistency_factor : the final residual may be at most this many times the noise
        floor of the images (:data:`fesdic_core.imaging.noise.CONSISTENCY_FACTOR`).
    max_shape_fraction : the correction may reach at most this fraction of the mesh's
        diagonal; a larger one is a diverged measurement (checked at the end of every scale:
        a coarse scale beyond it raises :class:`ShapeDivergedError`).
    uncertainty : at the end, estimate the noise model and the shape's standard deviation
        and bias indicator (:mod:`fesdic_core.shape.uncertainty`); costs about two Gauss-Newton
        iterations at the finest scale.
    edge_margin_px : at the finest scale of ``scales``, leave out the points that project
        within this many pixels (of the full-resolution images, scaled to that scale) of the
        mesh's boundary in either camera, where the image model mixes the speckle with what
        lies beyond the edge (:mod:`fesdic_core.residual.edges`); 0 keeps them. The coarser scales
        keep every point: they only start the next scale, and their elements are a few
        pixels wide, so a margin there took most of a boundary element's points and threw
        the boundary nodes of plain FE off by tenths of a millimetre.
    visibility : at every scale, leave out the points that either camera does not see on
        the current surface (self-occlusion, extra occluders, grazing angle;
        :func:`~fesdic_core.residual.visibility.visibility_mask`); None: every point is kept. Combined
        with the ``visibility`` callable of :func:`measure` when both are given.
    max_invalid_share : the measurement fails when more than this share of its seen nodes
        fail their local checks (:mod:`fesdic_core.shape.validity`); the default
        :data:`SHAPE_MAX_INVALID_SHARE` (1: never) is measured there.
    """

    scales: tuple[int, ...] = (0,)
    calibrate: bool = False
    keep_stereo: bool = True
    coupling: str = "joint"
    normalisation: str = "element"
    max_fixed_point: int = 10
    max_iter: int = 20
    max_joint_iter: int = 50
    tol_mm: float = 1e-4
    fixed_point_tol_mm: float = 2e-3
    fixed_point_tol_px: float = 1e-2
    fixed_point_rtol: float = 1e-4
    points_per_px: float = 1.0
    consistency_factor: float = CONSISTENCY_FACTOR
    max_shape_fraction: float = 0.25
    uncertainty: bool = True
    edge_margin_px: float = DEFAULT_EDGE_MARGIN_PX
    visibility: VisibilitySettings | None = None
    max_invalid_share: float = SHAPE_MAX_INVALID_SHARE

    def __post_init__(self):
        if not self.scales or any(int(s) != s or s < 0 for s in self.scales):
            raise ValueError(f"scales must be non-negative integers, got {self.scales!r}")
        if list(self.scales) != sorted(self.scales, reverse=True):
            raise ValueError(f"scales must go coarse to fine (decreasing), got {self.scales!r}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"coupling must be one of {COUPLINGS}, got {self.coupling!r}")
        if self.normalisation not in NORMALISATIONS:
            raise ValueError(f"normalisation must be one of {NORMALISATIONS}, got {self.normalisation!r}")
        if not self.edge_margin_px >= 0:
            raise ValueError(f"edge_margin_px must be >= 0, got {self.edge_margin_px!r}")
        if self.visibility is not None and not isinstance(self.visibility, VisibilitySettings):
            raise ValueError(f"visibility must be a VisibilitySettings or None, got "
                             f"{self.visibility!r}")
        if isinstance(self.max_invalid_share, str) or not 0.0 <= self.max_invalid_share <= 1.0:
            raise ValueError(f"max_invalid_share must be a share in [0, 1], got "
                             f"{self.max_invalid_share!r}")


@dataclass(frozen=True)
class ScaleReport:
    """How one image scale ended.

    ``shape_converged``: the last shape Gauss-Newton stopped before its iteration limit (q
    stagnated; at a coarse scale, or the residual did); ``fixed_point_converged``: the
    fixed point likewise (p and q; True when not calibrating); ``noise_percent``: the
    residual the images' noise explains at this scale (:mod:`fesdic_core.imaging.noise`).
    """

    scale: int
    residual_percent: float
    noise_percent: float
    fixed_point_iterations: int
    shape_converged: bool
    fixed_point_converged: bool
    n_points: int

    @property
    def converged(self) -> bool:
        return self.shape_converged and self.fixed_point_converged


@dataclass(frozen=True)
class Measurement:
    """Result of a shape measurement (world coordinates of the final cameras, mm).

    ``failure``: None for a trusted measurement, else one line saying what failed and by
    how much (residual against the noise floor, an unbounded shape, no stagnation at the
    finest scale). ``converged``: no failure and every scale stagnated (a coarse scale
    that stopped on its iteration limit only starts the next one, Remark 3, but is
    reported here). ``scales``: one :class:`ScaleReport` per scale, coarse to fine.
    ``validity``: each node's local checks at the finest scale (:mod:`fesdic_core.shape.validity`),
    whose :attr:`valid` and :attr:`residual_to_noise` are the measurement's.
    """

    q: np.ndarray
    nodes: np.ndarray
    normals: np.ndarray
    cameras: tuple
    residual: GrayLevelResidual
    quadrature: PixelQuadrature
    history: tuple = field(repr=False)
    iterations: int = 0
    time_s: float = 0.0
    converged: bool = True
    noise_percent: float = float("nan")
    failure: str | None = None
    scales: tuple = ()
    shape_std_mm: np.ndarray | None = field(default=None, repr=False)
    shape_bias_mm: np.ndarray | None = field(default=None, repr=False)
    noise: NoiseModel | None = None
    state: LinearisedState | None = field(default=None, repr=False)
    validity: NodeValidity | None = field(default=None, repr=False)

    @property
    def residual_percent(self) -> float:
        return self.residual.std_percent

    @property
    def shape_uncertainty_mm(self) -> np.ndarray | None:
        """(n,) mm: how far off a node may be, ``sqrt(std^2 + bias^2)`` of ``shape_std_mm`` (the
        image noise through the step's map) and ``shape_bias_mm`` (the step a richer space
        would still take: the bias that the regularization leaves), or the std alone when the
        solver gives no bias indicator; None without the std."""
        if self.shape_std_mm is None:
            return None
        std = np.asarray(self.shape_std_mm, dtype=float)
        if self.shape_bias_mm is None:
            return std
        return np.hypot(std, np.asarray(self.shape_bias_mm, dtype=float))

    @property
    def valid(self) -> np.ndarray:
        """(n,) bool: the node passed its local checks (all True without them)."""
        if self.validity is None:
            return np.ones(len(self.nodes), dtype=bool)
        return self.validity.valid

    @property
    def residual_to_noise(self) -> np.ndarray:
        """(n,) the residual over each node's support against its local noise floor (NaN
        without the local checks)."""
        if self.validity is None:
            return np.full(len(self.nodes), np.nan)
        return self.validity.residual_to_noise

    @property
    def ok(self) -> bool:
        """True when the measurement can be trusted (``failure`` is None)."""
        return self.failure is None
