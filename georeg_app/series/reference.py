"""The reference of a series: its surface, cameras and images, built once for every frame.

The reference is frame 0: the measured surface and calibrated cameras of the reference pair
(``[images]``), either measured here first (as ``georeg measure`` does) or read from a
``georeg measure`` output folder (``[reference]``: a plate, a mesh, a region of interest, or a
CAD part of several faces, rebuilt from its nominal faces and its nodes' face parameters).
The reference state (images,
quadratures, cameras, operators) is built once (:class:`SeriesReference`) and, with Dask
(:mod:`georeg_app.series.dask`), shipped once to every worker.
"""
from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path

import cv2
import meshio
import numpy as np

from adapters.fesdic_core import NominalModel, displacement_space
from fesdic_core.cameras.rig import read_cameras_json
from fesdic_core.displacement.driver import (DisplacementReference, DisplacementSettings,
                                             displacement_reference)
from fesdic_core.displacement.solvers import ComponentTikhonovSolver
from fesdic_core.displacement.start import FeatureReference, feature_reference
from fesdic_core.fe.mesh import SurfaceMesh
from fesdic_core.fe.mesh_io import read_mesh
from fesdic_core.imaging.image import Image, read_image
from fesdic_core.solve.solvers import CachedFactorization, DirectSolver
from georeg_plugin.io.spline_io import read_part_json, read_spline_json
from georeg_plugin.levels.solver import GeometricRegularization

from georeg_app.config.measure import AUTO, Config, OutputConfig
from georeg_app.config.track import REFERENCE_NOMINAL, TrackConfig
from georeg_app.errors import InputError, MeasurementFailed
from georeg_app.shape.methods import measure_specs
from georeg_app.shape.pipeline import run_methods

logger = logging.getLogger(__name__)

__all__ = ["SeriesReference", "load_reference", "displacement_solver", "check_frames",
           "series_reference"]


@dataclasses.dataclass(frozen=True, eq=False)
class SeriesReference:
    """Everything a frame needs, built once: the displacement reference (surface, cameras,
    reference pyramids and quadratures, with ``jacobian = "reference"`` the reference
    Jacobian and H of each scale) and the step solver's prototype (copied per frame: a
    Tikhonov solver keeps per-scale state; a :class:`CachedFactorization`, the modified
    Gauss-Newton's, is shared: its factors of the reference's H serve every frame).
    ``start``: the frames' starting field (``[displacement] start``); ``features``: the
    reference pair's features on the surface for ``start = "features"``."""

    displacement: DisplacementReference
    solver: object | None
    prefilter_px: float
    label: str
    interpolation_order: int = 3
    element_face: np.ndarray | None = None       # a CAD part's face of each element
    start: str = "previous"
    features: FeatureReference | None = None
    #: with ``[displacement] levels = "auto"``: the nominal spline the levels are chosen in
    #: (:func:`georeg_app.series.levels.with_chosen_levels`; dropped once they are)
    levels_model: NominalModel | None = None
    #: the record of that choice (:class:`~adapters.displacement_levels.DisplacementLevels`)
    levels: object | None = None
    #: with ``tikhonov_length_mm = "auto"``, the record of the length's choice
    #: (:class:`~georeg_app.series.tikhonov_length.TikhonovLength`)
    tikhonov_length: object | None = None


def _reference_images(config: TrackConfig, prefilter_px: float | None = None) -> tuple[Image, Image]:
    """The reference pair with the shape's image model, or with ``prefilter_px``."""
    prefilter = config.method.prefilter_px if prefilter_px is None else prefilter_px
    order = config.method.interpolation_order
    return tuple(read_image(p, prefilter_px=prefilter, order=order) for p in (config.images.cam0,
                                                                               config.images.cam1))


def load_reference(config: TrackConfig, progress=False
                   ) -> tuple[SurfaceMesh, tuple, tuple, NominalModel | None, str]:
    """The reference surface, calibrated cameras, reference images, the spline model (for
    the georeg displacement) and a label saying where they come from."""
    images = _reference_images(config)
    if config.reference is not None:
        ref = config.reference
        mesh = read_mesh(ref.mesh)
        cameras = tuple(read_cameras_json(ref.cameras))
        model = None
        if ref.nominal is not None:                  # a CAD part: its faces, as measured
            model = _part_model(ref.nominal, ref.mesh, mesh)
        elif ref.spline is not None:
            try:
                doc = json.loads(Path(ref.spline).read_text(encoding="utf-8"))
            except (json.JSONDecodeError, UnicodeDecodeError) as err:
                raise InputError(f"{ref.spline}: not valid JSON ({err})") from None
            if isinstance(doc, dict) and "faces" in doc:
                raise InputError(f"{ref.spline}: the reference is a part of several faces but "
                                 f"its folder lacks {REFERENCE_NOMINAL} (written by `georeg "
                                 "measure` since this release, with the nodes' face parameters "
                                 "in the VTU): measure the reference again, or give the part's "
                                 '[geometry] (kind = "cad") and its [cameras] without [reference]')
            model = NominalModel(patch=read_spline_json(ref.spline), mesh=mesh, uv=None)
        return mesh, cameras, images, model, f"{ref.dir} ({ref.label})"
    shape_config = Config(images=config.images, cameras=config.cameras, geometry=config.geometry,
                          method=config.method, output=OutputConfig(config.output.dir),
                          source=config.source)
    specs = measure_specs(shape_config)[:1]
    logger.info("reference shape: %s on the reference pair", specs[0].label)
    run = run_methods(shape_config, specs, images=images, progress=progress)
    result = run.results[0]
    if not result.ok:
        raise MeasurementFailed(f"the shape measurement of the reference pair failed "
                                f"({result.spec.label}): {result.failure}")
    m = result.measurement
    mesh = result.mesh.with_nodes(np.asarray(m.nodes, float))
    model = dataclasses.replace(result.nominal, mesh=mesh)  # as measured; a part keeps its faces
    return mesh, tuple(m.cameras), images, model, f"measured here ({result.spec.label})"


def _part_model(nominal: Path, vtu: Path, mesh: SurfaceMesh) -> NominalModel:
    """A CAD part of a `georeg measure` folder: its nominal faces (``nominal``, the coarsest
    splines) and, from the VTU ``vtu`` (``mesh`` as read), the measured nodes with their face
    and parameters on it (point data ``node_face``, ``face_uv``) and each element's face."""
    try:
        faces = read_part_json(nominal)
        names = [f.get("name") for f in json.loads(Path(nominal).read_text("utf-8"))["faces"]]
        raw = meshio.read(vtu)
        node_face = np.asarray(raw.point_data["node_face"]).astype(int).ravel()
        uv = np.asarray(raw.point_data["face_uv"], dtype=float).reshape(-1, 2)
        element_face = np.concatenate([np.asarray(d).ravel() for d in raw.cell_data["face"]])
    except KeyError as err:
        raise InputError(f"{vtu}: lacks the part's {err} data (measured by an older georeg? "
                         "measure the reference again)") from None
    except (ValueError, OSError) as err:
        raise InputError(f"{nominal}: {err}") from None
    if len(node_face) != mesh.n_nodes or node_face.max(initial=-1) >= len(faces):
        raise InputError(f"{vtu}: its node_face ({len(node_face)} nodes, faces up to "
                         f"{node_face.max(initial=-1)}) does not match its mesh ({mesh.n_nodes} "
                         f"nodes) and {nominal} ({len(faces)} faces)")
    return NominalModel(patch=faces[0], mesh=mesh, uv=uv, faces=tuple(faces),
                        node_face=node_face, element_face=element_face.astype(int),
                        face_names=tuple(names))


#: image scales a displacement solver's schedule covers (0: full resolution)
MAX_SCALES = 16

#: the displacement's levels of a series' first measurement when they are chosen from the data
START_LEVELS = 2
#: the Tikhonov length of ``tikhonov_length_mm = "auto"`` before its choice (mm; the first
#: length of :func:`georeg_app.series.tikhonov_length.length_ladder`)
START_LENGTH_MM = 10.0


def displacement_solver(method: str, mesh: SurfaceMesh, model: NominalModel | None = None,
                        tikhonov_length_mm: float = 10.0, levels: int = 2):
    """The step solver of a displacement method on the node-major dofs: None (plain FE),
    Tikhonov on each component, or the spline levels of ``model`` on each component
    (``kron(C_s, I3)``, image scale s -> level min(s, levels - 1)).

    The georeg solver holds one level finer than it solves with where the mesh reproduces it:
    its bias indicator (the step of the next finer level, for the displacement's uncertainty)
    is then that level's, not the unregularized FE step's (which carries the noise of every
    FE dof)."""
    if method == "fe":
        return None
    if method == "tikhonov":
        return ComponentTikhonovSolver(mesh, tikhonov_length_mm)
    if method != "georeg":
        raise ValueError(f"unknown displacement method {method!r}")
    if model is None:
        raise InputError("[displacement] method = \"georeg\" needs the spline of the reference")
    try:
        finer = displacement_space(model, levels + 1)
    except ValueError:                          # the mesh does not reproduce a finer level
        return GeometricRegularization(displacement_space(model, levels))
    return GeometricRegularization(finer, {s: min(s, levels - 1) + 1 for s in range(MAX_SCALES)})


def check_frames(config: TrackConfig, size: tuple[int, int]) -> None:
    """Refuse, before any computing, a frame that cannot be read or whose size (h, w)
    differs from the reference pair's (the error names the file)."""
    for k, (p0, p1) in enumerate(zip(config.series.cam0, config.series.cam1), start=1):
        for path in (p0, p1):
            a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if a is None:
                raise InputError(f"frame {k}: cannot read image file {path} (not an image "
                                 "OpenCV can decode)")
            if tuple(a.shape[:2]) != tuple(size):
                raise InputError(f"frame {k}: {path} is {a.shape[1]} x {a.shape[0]} px but the "
                                 f"reference images are {size[1]} x {size[0]} px")


def series_reference(config: TrackConfig, progress=False) -> SeriesReference:
    """Load or measure the reference and build the displacement reference and solver."""
    mesh, cameras, images, model, label = load_reference(config, progress)
    d = config.displacement
    settings = DisplacementSettings(scales=d.scale_sequence,
                                    normalisation=config.method.normalisation,
                                    jacobian=d.jacobian,
                                    max_invalid_share=d.max_invalid_share,
                                    uncertainty=d.uncertainty)
    if d.prefilter_px != config.method.prefilter_px:     # the frames' image model
        images = _reference_images(config, d.prefilter_px)
    reference = displacement_reference(mesh, images, cameras, settings)
    auto = d.method == "georeg" and d.levels == AUTO
    length = START_LENGTH_MM if d.tikhonov_length_mm == AUTO else float(d.tikhonov_length_mm)
    solver = displacement_solver(d.method, mesh, model, length,
                                 START_LEVELS if auto else d.levels)
    if d.jacobian == "reference":      # H of each scale factorized once for the whole series
        solver = CachedFactorization(DirectSolver() if solver is None else solver)
    features = feature_reference(reference) if d.start == "features" else None
    return SeriesReference(displacement=reference, solver=solver,
                           prefilter_px=d.prefilter_px, label=label,
                           interpolation_order=config.method.interpolation_order,
                           element_face=None if model is None else model.element_face,
                           start=d.start, features=features,
                           levels_model=model if auto else None)
