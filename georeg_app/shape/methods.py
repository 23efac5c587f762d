"""The methods of a run: what ``georeg measure`` and ``georeg compare`` measure with.

FE without regularization, Tikhonov (Eq. 10) at fixed lengths or a length chosen from the
data, and the geometric regularization with fixed or automatically chosen spline levels,
each on a sequence of image scales (Remark 3).
"""
from __future__ import annotations

import dataclasses

from georeg_app.config.measure import AUTO, Config

__all__ = ["MethodSpec", "tikhonov_spec", "georeg_spec", "default_specs", "measure_specs"]


@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """One method of a comparison."""

    name: str                 # "fe" | "tikhonov" | "georeg"
    param: float | str | None  # Tikhonov length (mm) or "auto" for "tikhonov", else None
    scales: tuple[int, ...]   # image scales, coarse to fine
    label: str
    levels: int | str | None = None   # georeg: spline levels, or "auto" (the level search)


def tikhonov_spec(length, scales: tuple[int, ...]) -> MethodSpec:
    """Tikhonov at a length (mm) or "auto"."""
    if length == AUTO:
        return MethodSpec("tikhonov", AUTO, scales, "Tikhonov auto")
    return MethodSpec("tikhonov", float(length), scales, f"Tikhonov {length:g} mm")


def georeg_spec(levels, scales: tuple[int, ...]) -> MethodSpec:
    """georeg with automatic or ``levels`` fixed spline levels."""
    kind = "auto" if levels == AUTO else f"{int(levels)} levels"
    mode = "multiscale" if len(scales) > 1 else "monoscale"
    return MethodSpec("georeg", None, scales, f"georeg {kind} ({mode})", levels=levels)


def default_specs(config: Config) -> list[MethodSpec]:
    """All methods on the same data: FE, Tikhonov x lengths, georeg with its levels (and, when
    automatic, with the fixed levels it starts from), fixed levels monoscale."""
    method = config.method
    scales = method.scale_sequence
    specs = [MethodSpec("fe", None, scales, "FE (multiscale)")]
    specs += [tikhonov_spec(length, scales) for length in method.tikhonov_length_mm]
    if method.levels == AUTO:
        specs.append(georeg_spec(AUTO, scales))
    specs.append(georeg_spec(method.fixed_levels, scales))
    if len(scales) > 1:
        specs.append(georeg_spec(method.fixed_levels, (0,)))
    return specs


def measure_specs(config: Config) -> list:
    """The method(s) of ``[method]``: one spec, or one per Tikhonov length."""
    m = config.method
    scales = m.scale_sequence
    if m.name == "tikhonov":
        return [tikhonov_spec(length, scales) for length in m.tikhonov_length_mm]
    if m.name == "georeg":
        return [georeg_spec(m.levels, scales)]
    return [MethodSpec("fe", None, scales, "FE" + (" (multiscale)" if len(scales) > 1 else ""))]
