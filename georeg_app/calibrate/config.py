"""The TOML configuration of ``georeg calibrate``: target images, the target, the model.

Relative paths are resolved against the folder of the configuration file; every error
names the file, the section and the key. A complete example (optional keys show their
default in parentheses)::

    [images]                       # required: the target's views, one pair per view
    cam0 = "target/cam0_*.tif"     # a glob (natural sort: 2 before 10) or a list of paths
    cam1 = "target/cam1_*.tif"     # the same count as cam0, paired in order

    [target]                       # required
    kind = "dots"                  # "dots" (ring markers) | "checkerboard" | "charuco" |
                                   # "circles" | "asymmetric_circles"
    rows = 10                      # dots per column (checkerboard: inner corners; charuco:
    columns = 14                   # squares)
    pitch_mm = 7.0                 # between neighbouring points (charuco: the square's side)
    markers = [[2, 2], [2, 7], [11, 7]]   # "dots": (column, row) of the ring markers
    dot_diameter_mm = 2.15         # dots and circles: corrects the perspective bias of the
                                   # centres (none)
    # marker_mm = 5.0              # "charuco": the ArUco marker's side
    # dictionary = "DICT_4X4_50"   # "charuco": OpenCV's dictionary

    [model]                        # optional section
    distortion = "k1k2p1p2k3"      # "k1" | "k1k2" | "k1k2k3" | "k1k2p1p2" | "k1k2p1p2k3"
    fix_principal_point = false    # at the image centre                       (false)
    fix_aspect = false             # fy / fx fixed at 1                        (false)
    refine_target = false          # estimate the target's points too: a target as printed,
                                   # not as drawn (its deviations in summary.json) (false)

    [compare]                      # optional: another tool's calibration of the same rig,
    vic3d = "cal.xml"              # one key as in `georeg measure`'s [cameras] (file, opencv,
                                   # vic3d, dice, pyvale_csv): parameters side by side, the
                                   # differences in units of our standard deviations

    [check]                        # optional: a speckle pair of the rig (e.g. a reference
    cam0 = "ref_cam0.tif"          # image pair): the epipolar distance of its SIFT matches
    cam1 = "ref_cam1.tif"          # with our calibration (and the compared one)

    [output]
    dir = "calibration_out"        # (default "calibration_out"; `--out` overrides)
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fesdic_core.cameras.targets.calibration import DISTORTION_MODELS, CalibrationModel
from fesdic_core.cameras.targets.target import TARGET_KINDS, Target

from georeg_app.config.measure import CamerasConfig, OutputConfig, cameras_table
from georeg_app.config.toml_schema import (ConfigError, Table, boolean, existing_file, integer,
                                           load_toml, one_of, positive, resolve_path, string)
from georeg_app.config.track import series_table

__all__ = ["CalibrateConfig", "load_calibrate_config", "target_table", "model_table",
           "DEFAULT_CALIBRATION_DIR"]

DEFAULT_CALIBRATION_DIR = "calibration_out"


@dataclass(frozen=True)
class CalibrateConfig:
    """What ``georeg calibrate`` reads: the pairs of target images, the target, the model."""

    cam0: tuple[Path, ...]
    cam1: tuple[Path, ...]
    target: Target
    model: CalibrationModel
    output: OutputConfig
    source: Path
    compare: CamerasConfig | None = None
    check: tuple[Path, Path] | None = None

    def with_output_dir(self, out_dir: str | os.PathLike) -> CalibrateConfig:
        return dataclasses.replace(self, output=OutputConfig(Path(out_dir)))


def _markers(value: Any) -> tuple[tuple[int, int], ...]:
    if not isinstance(value, list):
        raise TypeError(value)
    out = []
    for m in value:
        if not (isinstance(m, list) and len(m) == 2 and all(isinstance(v, int) and
                                                            not isinstance(v, bool) for v in m)):
            raise TypeError(m)
        out.append((int(m[0]), int(m[1])))
    return tuple(out)


def target_table(data: Any, source: Path) -> Target:
    """The ``[target]`` table, checked."""
    t = Table(data, "[target]", source)
    kind = t.take("kind", one_of(TARGET_KINDS), "one of " + ", ".join(f'"{k}"' for k in TARGET_KINDS),
                  required=True)
    values = dict(kind=kind,
                  rows=t.take("rows", integer, "an integer", required=True),
                  columns=t.take("columns", integer, "an integer", required=True),
                  pitch_mm=t.take("pitch_mm", positive, "a positive number (mm)", required=True),
                  markers=t.take("markers", _markers, "a list of [column, row] integer pairs",
                                 default=()),
                  dot_diameter_mm=t.take("dot_diameter_mm", positive, "a positive number (mm)"),
                  marker_mm=t.take("marker_mm", positive, "a positive number (mm)"),
                  dictionary=t.take("dictionary", string, "a string", default="DICT_4X4_50"))
    t.finish()
    if kind != "dots" and values["markers"]:
        raise t.error("markers", f'only for kind = "dots", not "{kind}"')
    if kind != "charuco" and values["marker_mm"] is not None:
        raise t.error("marker_mm", f'only for kind = "charuco", not "{kind}"')
    try:
        return Target(**values)
    except ValueError as err:
        raise t.error(None, str(err).removeprefix("target ")) from None


def model_table(data: Any, source: Path) -> CalibrationModel:
    """The ``[model]`` table, checked (defaults for the keys it lacks)."""
    t = Table(data, "[model]", source)
    d = CalibrationModel()
    model = CalibrationModel(
        distortion=t.take("distortion", one_of(tuple(DISTORTION_MODELS)),
                          "one of " + ", ".join(f'"{k}"' for k in DISTORTION_MODELS),
                          default=d.distortion),
        fix_principal_point=t.take("fix_principal_point", boolean, "true or false",
                                   default=d.fix_principal_point),
        fix_aspect=t.take("fix_aspect", boolean, "true or false", default=d.fix_aspect),
        refine_target=t.take("refine_target", boolean, "true or false", default=d.refine_target))
    t.finish()
    return model


def load_calibrate_config(path: str | os.PathLike) -> CalibrateConfig:
    """Read and check the configuration of ``georeg calibrate`` (:class:`ConfigError` naming
    the file, section and key of anything wrong; missing files are named too)."""
    source = Path(path)
    top = Table(load_toml(source), "", source)
    base = source.resolve().parent
    images = top.take("images", lambda v: v, "a table", required=True)
    target = top.take("target", lambda v: v, "a table", required=True)
    model = top.take("model", lambda v: v, "a table", default={})
    compare = top.take("compare", lambda v: v, "a table")
    check = top.take("check", lambda v: v, "a table")
    output = top.take("output", lambda v: v, "a table", default={})
    top.finish()
    try:
        pairs = series_table(images, source, base)
    except ConfigError as err:
        raise type(err)(str(err).replace("[series]", "[images]").replace(" frames", " images")
                          .replace("a stereo pair per frame", "a pair per view")) from None
    o = Table(output, "[output]", source)
    out_dir = o.take("dir", string, "a folder path (string)", default=DEFAULT_CALIBRATION_DIR)
    o.finish()
    compared = None
    if compare is not None:
        try:
            compared = cameras_table(compare, None, source, base, roi=True)
        except ConfigError as err:
            raise type(err)(str(err).replace("[cameras]", "[compare]")) from None
    pair = None
    if check is not None:
        c = Table(check, "[check]", source)
        raw = [c.take(k, string, "a file path (string)", required=True) for k in ("cam0", "cam1")]
        c.finish()
        pair = tuple(existing_file(c, k, v, base) for k, v in zip(("cam0", "cam1"), raw))
    return CalibrateConfig(cam0=pairs.cam0, cam1=pairs.cam1, target=target_table(target, source),
                           model=model_table(model, source),
                           output=OutputConfig(resolve_path(out_dir, base)), source=source,
                           compare=compared, check=pair)
