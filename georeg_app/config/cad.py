"""The keys of ``[geometry] kind = "cad"``: the part's file, its faces, and how it is placed.

::

    [geometry]
    kind = "cad"
    file = "part.step"            # IGES or STEP (see georeg_app.config.measure)
    faces = [0, "lid"]            # faces by index or name (default all)
    pose = "auto"                 # no landmarks: the rig's triangulation places the part
    # pose = {rotation_deg = [180, 0, 0], translation_mm = [0, 0, 400]}   # a rough pose

Without ``pose``, a calibration file (``pyvale_csv``, ``opencv``, ``vic3d``, ``dice``) needs
at least 4 ``[[landmarks]]`` and ``file`` cameras are taken as posed in the CAD's frame.
With ``pose`` (and no landmarks), the stereo matches of the reference pair, triangulated by
the calibrated rig, are fitted to the selected faces by point-to-plane ICP
(:mod:`georeg_app.inputs.cad_pose`), from the principal axes (``"auto"``) or from the given
rough pose of the part in camera 0's frame, ``X_cam0 = R X_cad + translation_mm``, ``R`` the
rotation of the rotation vector ``rotation_deg`` (axis times angle, degrees: OpenCV's
``rvec``); one 6 degrees and 8 mm off gave the automatic pose on the Stereo DIC Challenge's
part, 5 degrees and 5 mm off on a rendered folded plate. The gray-level calibration then
refines that pose as it refines the landmarks' one.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from georeg_app.config.toml_schema import Table, existing_file, show, vector

__all__ = ["AUTO_POSE", "RoughPose", "take_cad", "cad_file"]

#: ``pose = "auto"``: the rough pose from the principal axes of the part and of the points
AUTO_POSE = "auto"


@dataclasses.dataclass(frozen=True)
class RoughPose:
    """The part in camera 0's frame: ``X_cam0 = R(rotation_deg) X_cad + translation_mm``."""

    rotation_deg: tuple[float, float, float]
    translation_mm: tuple[float, float, float]


def _pose(t: Table, value: Any) -> str | RoughPose:
    if value == AUTO_POSE or isinstance(value, RoughPose):
        return value
    if not isinstance(value, dict):
        raise t.error("pose", f'expected "auto" or a table {{rotation_deg = [3 numbers], '
                              f"translation_mm = [3 numbers]}}, got {show(value)}")
    pose = Table(value, "[geometry] pose", t.source)
    rotation = pose.take("rotation_deg", vector(3), "a list of 3 numbers (deg)", required=True)
    translation = pose.take("translation_mm", vector(3), "a list of 3 numbers (mm)",
                            required=True)
    pose.finish()
    return RoughPose(tuple(float(v) for v in rotation), tuple(float(v) for v in translation))


def _face_list(value: Any) -> tuple:
    if not isinstance(value, list) or not value or not all(
            isinstance(v, str) or (isinstance(v, int) and not isinstance(v, bool)) for v in value):
        raise TypeError(value)
    return tuple(value)


def take_cad(t: Table, kind: str) -> dict:
    """Take ``faces`` and ``pose`` of ``[geometry]`` (before ``t.finish()``): the keyword
    arguments of ``GeometryConfig`` they give. ConfigError naming the key: either with
    another kind, a face list that is not one, a pose that is neither "auto" nor a table of
    ``rotation_deg`` and ``translation_mm``."""
    faces = t.take("faces", _face_list, "a list of face indices (integers) or names (strings)")
    raw = t.take("pose", lambda v: v, '"auto" or a table')
    for key, value in (("faces", faces), ("pose", raw)):
        if value is not None and kind != "cad":
            raise t.error(key, f'not used with kind = "{kind}"; remove it')
    return {"faces": faces, "pose": None if raw is None else _pose(t, raw)}


def cad_file(t: Table, value: str | None, base: Path, faces: tuple | None) -> Path:
    """The CAD file of ``[geometry] file`` (relative to ``base``), checked: an IGES or STEP
    suffix (STEP without the ``cad`` extra is named before looking for the file), the file
    exists and reads, ``faces`` name faces of it."""
    from georeg_app.inputs.cad import cad_faces, check_cad_file
    if value is not None:
        try:
            check_cad_file(Path(value))
        except ValueError as err:
            raise t.error("file", str(err)) from None
    path = existing_file(t, "file", value, base)
    for key, selection in (("file", None), ("faces", faces)):
        try:
            cad_faces(path, selection)        # the file reads, the faces exist
        except ValueError as err:
            raise t.error(key, str(err)) from None
    return path
