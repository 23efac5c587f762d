"""Checked reading of TOML configuration files: the machinery shared by all readers.

A reader loads the file with :func:`load_toml`, wraps each table in a :class:`Table`,
takes every key with a converter (``integer``, ``number``, ``vector(3)``, ...) and calls
:meth:`Table.finish`, which turns any key left over into an "unknown key" error. Every
error is a :class:`ConfigError` on one line that names the file, the table and the key::

    config.toml: [method] levels: expected an integer or "auto", got "three"
    config.toml: [geometry] radius: unknown key (did you mean hole_radius_mm?)

A converter takes the TOML value and returns the Python value, or raises ``TypeError`` or
``ValueError`` (the table then reports ``expected <what>, got <value>``). Used by
:mod:`georeg_app.config.measure` and by the Stereo DIC Challenge example's reader.
"""
from __future__ import annotations

import difflib
import json
import math
import re
import tomllib
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from georeg_app.errors import GeoregError

__all__ = ["ConfigError", "ConfigFileNotFoundError", "Table", "load_toml", "show", "show_key",
           "show_path", "integer", "count", "number", "positive", "boolean", "string", "table",
           "table_list", "one_of", "strings", "vector", "array", "numbers", "pair", "check",
           "resolve_path", "existing_file"]

Converter = Callable[[Any], Any]


class ConfigError(GeoregError, ValueError):
    """A configuration file is unusable; the message names the file, section and key."""


class ConfigFileNotFoundError(ConfigError, FileNotFoundError):
    """A configuration file, or a file it references, does not exist."""


def load_toml(source: Path) -> dict:
    """The parsed TOML file ``source``.

    Raises
    ------
    ConfigFileNotFoundError
        If ``source`` is not a file.
    ConfigError
        If it is not valid TOML (or not UTF-8 text), or cannot be read.
    """
    if not source.is_file():
        raise ConfigFileNotFoundError(f"{source}: configuration file not found")
    try:
        with open(source, "rb") as f:
            return tomllib.load(f)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{source}: not valid TOML: {err}") from None
    except OSError as err:
        raise ConfigError(f"{source}: cannot read: {err.strerror or err}") from None


def show(value: Any) -> str:
    """A value as it would read in TOML (strings quoted, booleans lower case)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "[" + ", ".join(show(v) for v in value) + "]"
    return str(value)


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def show_key(key: str) -> str:
    """A key as TOML writes it: bare if it can be, else quoted (so a message stays one line)."""
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key)


def show_path(path: Path) -> str:
    """A path as it is, or quoted if it holds characters that do not print (newlines...)."""
    text = str(path)
    return text if text.isprintable() else json.dumps(text)


class Table:
    """The keys of one TOML table, taken with type checks; leftovers are unknown keys.

    Parameters
    ----------
    data : the parsed table (anything else is an error "expected a table").
    where : how messages name the table, e.g. ``"[method]"`` or ``"[[landmarks]][2]"``;
        ``""`` for the top level, whose keys are named as sections (``[images]``).
    source : the file, named first in every message.
    """

    def __init__(self, data: Any, where: str, source: Path):
        self.where, self.source = where, source
        if not isinstance(data, dict):
            raise self.error(None, f"expected a table, got {show(data)}")
        self.data = dict(data)
        self.known: list[str] = []

    def error(self, key: str | None, message: str, cls: type = ConfigError) -> ConfigError:
        """An error ``<file>: <table> <key>: <message>`` (to raise)."""
        if key is None:
            at = self.where
        else:
            key = show_key(key)
            at = f"{self.where} {key}" if self.where else f"[{key}]"   # top level: a section
        return cls(f"{self.source}: {at}: {message}" if at else f"{self.source}: {message}")

    def take(self, key: str, convert: Converter, what: str, *, required: bool = False,
             default: Any = None) -> Any:
        """``convert(value)`` of ``key`` (removed from the table), or ``default`` if absent.

        ``what`` says what was expected when ``convert`` raises TypeError or ValueError.
        """
        self.known.append(key)
        if key not in self.data:
            if required:
                raise self.error(key, "missing required key")
            return default
        value = self.data.pop(key)
        try:
            return convert(value)
        except (TypeError, ValueError):
            raise self.error(key, f"expected {what}, got {show(value)}") from None

    def finish(self) -> None:
        """Raise on the first key that was not taken, suggesting the closest known one."""
        for key in self.data:
            close = difflib.get_close_matches(key, self.known, n=1, cutoff=0.5)
            hint = (f" (did you mean {close[0]}?)" if close
                    else f" (known keys: {', '.join(self.known)})")
            raise self.error(key, "unknown key" + hint)


# --------------------------------------------------------------------------- converters

def integer(value: Any) -> int:
    """An integer (not a boolean)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError
    return value


def count(value: Any) -> int:
    """An integer >= 1."""
    if integer(value) < 1:
        raise ValueError
    return value


def number(value: Any) -> float:
    """A finite number (integer or float, not a boolean), as a float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise TypeError
    return float(value)


def positive(value: Any) -> float:
    """A finite number > 0, as a float."""
    if number(value) <= 0:
        raise ValueError
    return float(value)


def boolean(value: Any) -> bool:
    """``true`` or ``false``."""
    if not isinstance(value, bool):
        raise TypeError
    return value


def string(value: Any) -> str:
    """A string."""
    if not isinstance(value, str):
        raise TypeError
    return value


def table(value: Any) -> dict:
    """A table (checked again, key by key, by a :class:`Table`)."""
    if not isinstance(value, dict):
        raise TypeError
    return value


def table_list(value: Any) -> list:
    """An array (of tables, each checked by a :class:`Table`)."""
    if not isinstance(value, list):
        raise TypeError
    return value


def one_of(choices: Sequence[str]) -> Converter:
    """A converter accepting only the strings of ``choices``."""
    def convert(value: Any) -> str:
        if not isinstance(value, str) or value not in choices:
            raise ValueError
        return value
    return convert


def strings(value: Any) -> tuple[str, ...]:
    """A list of strings, as a tuple."""
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise TypeError
    return tuple(value)


def array(shape: tuple[int, ...]) -> Converter:
    """A converter to a read-only float array of ``shape`` from nested lists of numbers."""
    def convert(value: Any) -> np.ndarray:
        a = np.array(value, dtype=object)
        if a.shape != tuple(shape):
            raise TypeError
        out = np.vectorize(number, otypes=[float])(a)
        out.setflags(write=False)
        return out
    return convert


def vector(n: int) -> Converter:
    """A converter to a read-only float array (n,) from a list of ``n`` numbers."""
    def convert(value: Any) -> np.ndarray:
        if not isinstance(value, list) or len(value) != n:
            raise TypeError
        return array((n,))(value)
    return convert


def numbers(value: Any) -> tuple[float, ...]:
    """One number or a non-empty list of numbers, as a tuple of floats."""
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ValueError
    return tuple(number(v) for v in values)


def pair(convert: Converter) -> Converter:
    """A converter of a list of two values, each converted by ``convert``, to a tuple."""
    def convert_pair(value: Any) -> tuple:
        if not isinstance(value, list) or len(value) != 2:
            raise TypeError
        return tuple(convert(v) for v in value)
    return convert_pair


# --------------------------------------------------------------------------- checks

def check(table: Table, key: str, value: Any, ok: bool, requirement: str) -> None:
    """Raise ``<key>: must be <requirement>, got <value>`` unless ``ok`` (or value is None)."""
    if value is not None and not ok:
        raise table.error(key, f"must be {requirement}, got {show(value)}")


def resolve_path(value: str, base: Path) -> Path:
    """The path ``value`` with ``~`` expanded, relative to the folder ``base``."""
    path = Path(value)
    try:
        path = path.expanduser()
    except RuntimeError:                      # "~user" of no known user: taken as written
        pass
    return path if path.is_absolute() else base / path


def existing_file(table: Table, key: str, value: str | None, base: Path) -> Path | None:
    """The file ``value`` (``~`` expanded, relative to ``base``), which must exist."""
    if value is None:
        return None
    path = resolve_path(value, base)
    if not path.is_file():
        raise table.error(key, f"file not found: {show_path(path)}", ConfigFileNotFoundError)
    return path
