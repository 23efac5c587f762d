"""The results of ``georeg measure``/``compare``/``demo`` and ``georeg track`` as objects
that save themselves.

:class:`ShapeRun` wraps a :class:`~georeg_app.shape.pipeline.RunResult`, :class:`SeriesRun`
a :class:`~georeg_app.series.track.TrackRun`. Both are what the command line writes from
(:mod:`georeg_app.cli`) and what the Python API returns (:mod:`georeg`): ``save`` writes
exactly the command line's files (through :func:`~georeg_app.shape.outputs.write_all` and
:func:`~georeg_app.series.outputs.write_track`, all published together or none), and refuses,
as the command line does, a run it would not deliver (:class:`MeasurementFailed`).
"""
from __future__ import annotations

import dataclasses
import logging
import os
import tempfile
from pathlib import Path

import meshio
import numpy as np

from georeg_app.errors import MeasurementFailed
from georeg_app.series.outputs import frame_file, track_summary, write_frame_vtu, write_track
from georeg_app.series.track import TrackRun
from georeg_app.shape.outputs import method_stems, summary_dict, write_all, write_method_vtu
from georeg_app.shape.pipeline import MethodResult, RunResult

logger = logging.getLogger(__name__)

__all__ = ["MeasurementFailed", "check_output_folder", "ShapeRun", "SeriesRun"]

#: the commands a shape run comes from: ``measure`` delivers only if every method is
#: trusted; ``compare`` and ``demo`` deliver while at least one is
SHAPE_COMMANDS = ("measure", "compare", "demo")


def check_output_folder(out: str | os.PathLike, overwrite: bool,
                        option: str = "--overwrite") -> None:
    """Refuse, before any computing, an output folder that cannot or must not be written
    (``option``: how the message names the way to replace a folder's contents).

    Raises
    ------
    NotADirectoryError
        If ``out`` exists and is not a folder.
    PermissionError
        If the folder (or its first existing parent) is not writable.
    FileExistsError
        If ``out`` is a non-empty folder and ``overwrite`` is false.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"output folder {out} exists and is not a folder")
    parent = out.resolve().parent
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent if not out.exists() else out.resolve().parent, os.W_OK | os.X_OK):
        raise PermissionError(f"output folder {out}: {parent} is not writable")
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"output folder {out} is not empty; choose another folder or "
                              f"use {option} to replace its contents")


def _trusted(result) -> bool:
    """A method's verdict, from its ``status`` ("ok" or "failed"), as summary.json says it."""
    return getattr(result, "status", "ok") == "ok"


def _read_vtu(write) -> meshio.Mesh:
    """The mesh a VTU writer ``write(path)`` writes, read back with meshio."""
    with tempfile.TemporaryDirectory(prefix="georeg_vtu_") as folder:
        path = Path(folder) / "surface.vtu"
        write(path)
        return meshio.read(path)


@dataclasses.dataclass(frozen=True, eq=False)
class ShapeRun:
    """A shape measurement: every method of one run, and the chosen one.

    Parameters
    ----------
    run : the run (:func:`~georeg_app.shape.pipeline.run_methods`).
    command : "measure", "compare" or "demo": what the run delivers (``measure``: only if
        every method is trusted; the others while one is).
    method : the label (or method name: "fe", "tikhonov", "georeg") of the method that
        ``ok``, ``failure``, ``nodes``, ``shape_std_mm`` and ``residual_percent`` report;
        default: the first method of ``measure``, the first georeg method of the others.
    """

    run: RunResult
    command: str = "measure"
    method: str | None = None

    def __post_init__(self) -> None:
        if self.command not in SHAPE_COMMANDS:
            raise ValueError(f"command {self.command!r}: expected one of {', '.join(SHAPE_COMMANDS)}")
        if not self.run.results:
            raise ValueError("a shape run needs at least one method, got none")
        self.result(self.method)                      # an unknown method is named now

    @property
    def labels(self) -> tuple[str, ...]:
        """The label of each method, in the run's order."""
        return tuple(r.spec.label for r in self.run.results)

    def result(self, method: str | None = None) -> MethodResult:
        """One method's result, by label or by name ("fe", "tikhonov", "georeg": the first
        of that name); None: the chosen method (see the class docstring)."""
        results = self.run.results
        if method is None:
            method = self.method
        if method is None:
            georeg = [r for r in results if r.spec.name == "georeg"]
            return georeg[0] if georeg and self.command != "measure" else results[0]
        for r in results:
            if r.spec.label == method:
                return r
        for r in results:
            if r.spec.name == method:
                return r
        raise ValueError(f"method {method!r}: not in this run (methods: {', '.join(self.labels)})")

    @property
    def chosen(self) -> str:
        """The label of the chosen method."""
        return self.result().spec.label

    @property
    def ok(self) -> bool:
        """The chosen method's measurement is trusted (passed its checks)."""
        return _trusted(self.result())

    @property
    def failure(self) -> str | None:
        """Why the chosen method failed (None when ``ok``)."""
        return None if self.ok else self.result().failure

    @property
    def failed(self) -> tuple[str, ...]:
        """The labels of every method that failed."""
        return tuple(r.spec.label for r in self.run.results if not _trusted(r))

    def _measurement(self):
        r = self.result()
        if r.measurement is None:
            raise ValueError(f"{r.spec.label} failed without a measured state: {r.failure}")
        return r.measurement

    @property
    def nodes(self) -> np.ndarray:
        """(n_nodes, 3) the measured FE nodes of the chosen method (world frame, mm)."""
        return np.asarray(self._measurement().nodes, float)

    @property
    def shape_std_mm(self) -> np.ndarray | None:
        """(n_nodes,) standard deviation of the measured shape from the image noise (mm)."""
        std = getattr(self._measurement(), "shape_std_mm", None)
        return None if std is None else np.asarray(std, float)

    @property
    def residual_percent(self) -> float:
        """The chosen method's final gray-level residual (percent of the dynamic range)."""
        return float(self._measurement().residual_percent)

    @property
    def summary(self) -> dict:
        """The ``summary.json`` document (:func:`~georeg_app.shape.outputs.summary_dict`)."""
        return summary_dict(self.run)

    def check(self) -> None:
        """Raise :class:`MeasurementFailed` if the command line would not deliver this run
        (``measure``: a method failed; ``compare``, ``demo``: every method failed)."""
        failed = [r for r in self.run.results if not _trusted(r)]
        if failed and (self.command == "measure" or len(failed) == len(self.run.results)):
            raise MeasurementFailed("; ".join(f"{r.spec.label} failed: {r.failure}" for r in failed))

    def save(self, folder: str | os.PathLike, overwrite: bool = False) -> list[Path]:
        """Write the command line's output files into ``folder`` (all or nothing).

        ``folder`` must be new or empty unless ``overwrite`` (its previous contents are
        then replaced as a whole). Returns the paths written.

        Raises
        ------
        MeasurementFailed
            If the command line would not deliver the run (:meth:`check`); nothing is written.
        FileExistsError, NotADirectoryError, PermissionError
            For an output folder that must not or cannot be written.
        """
        self.check()
        check_output_folder(folder, overwrite, option="overwrite=True")
        return write_all(folder, self.run, overwrite=overwrite)

    def to_meshio(self, method: str | None = None) -> meshio.Mesh:
        """The measured surface of ``method`` (default: the chosen one) as a ``meshio.Mesh``
        with the point and cell data of its VTU (:func:`~georeg_app.shape.outputs.write_method_vtu`)."""
        result = self.result(method)
        if result.measurement is None:
            raise ValueError(f"{result.spec.label} failed without a measured state: {result.failure}")
        return _read_vtu(lambda path: write_method_vtu(path, result))

    def mesh_file(self, method: str | None = None) -> str:
        """The name of ``method``'s VTU among the saved files."""
        result = self.result(method)
        return method_stems(self.run)[self.run.results.index(result)] + ".vtu"


@dataclasses.dataclass(frozen=True, eq=False)
class SeriesRun:
    """A displacement series (``georeg track``): one field per deformed stereo pair."""

    run: TrackRun

    @property
    def frames(self) -> tuple:
        """Each frame's :class:`~georeg_app.series.frames.FrameResult` (index 1, 2, ...)."""
        return self.run.frames

    @property
    def ok(self) -> bool:
        """Every frame is trusted."""
        return all(f.ok for f in self.run.frames)

    @property
    def failure(self) -> str | None:
        """Why frames failed (None when ``ok``)."""
        failed = [f for f in self.run.frames if not f.ok]
        return "; ".join(f"frame {f.index}: {f.failure}" for f in failed) or None

    @property
    def summary(self) -> dict:
        """The ``summary.json`` document (:func:`~georeg_app.series.outputs.track_summary`)."""
        return track_summary(self.run)

    def frame(self, index: int):
        """The frame of ``index`` (1 = the first deformed pair)."""
        for f in self.run.frames:
            if f.index == index:
                return f
        raise ValueError(f"frame {index!r}: not in this series (frames 1 to {len(self.run.frames)})")

    def check(self) -> None:
        """Raise :class:`MeasurementFailed` if every frame failed (the command line's rule)."""
        failed = [f for f in self.run.frames if not f.ok]
        if failed and len(failed) == len(self.run.frames):
            raise MeasurementFailed("every frame failed: " + "; ".join(
                f"frame {f.index}: {f.failure}" for f in failed[:3]) + (" ..." if len(failed) > 3 else ""))

    def save(self, folder: str | os.PathLike, overwrite: bool = False) -> list[Path]:
        """Write ``georeg track``'s output files into ``folder`` (all or nothing; see
        :meth:`ShapeRun.save`), failed frames too and even when every frame failed (their
        untrusted fields and reasons are there to inspect; :meth:`check` says whether the
        series counts as measured)."""
        check_output_folder(folder, overwrite, option="overwrite=True")
        return write_track(folder, self.run, overwrite=overwrite)

    def to_meshio(self, frame: int) -> meshio.Mesh:
        """Frame ``frame``'s field on the reference surface as a ``meshio.Mesh``, with the
        point data of its VTU (``displacement_mm``, ``residual``, ``strain_*``)."""
        f = self.frame(frame)
        if frame_file(f) is None:
            raise ValueError(f"frame {frame}: failed without a field: {f.failure}")
        return _read_vtu(lambda path: write_frame_vtu(path, self.run.mesh, f, self.run.element_face))
