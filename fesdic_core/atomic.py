"""Atomic output files: written under a temporary name beside the target, then renamed.

A reader (or a crashed run) never sees a half-written file: either the old file or the
complete new one. The temporary file is created with mode ``0666`` and the kernel applies
the process umask, as for any new file (not the owner-only ``0600`` of
:func:`tempfile.mkstemp`). Nothing here changes the umask, so writers may run on several
threads at once.
"""
from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path
from typing import Callable, Iterator

__all__ = ["atomic_path", "write_bytes_atomic", "write_text_atomic", "temporary_folder",
           "public_mode", "process_umask"]

#: the umask assumed where the system does not tell it (no ``/proc/self/status``)
DEFAULT_UMASK = 0o022


def process_umask() -> int:
    """The umask of this process, read without changing it.

    Linux reports it in ``/proc/self/status`` (line ``Umask:``); elsewhere the usual
    :data:`DEFAULT_UMASK` (``0o022``) is assumed. Calling ``os.umask`` twice to read it
    would briefly set a process-wide umask of 0 under the feet of other threads.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return DEFAULT_UMASK


def public_mode(directory: bool = False) -> int:
    """Mode of a newly created file (``0o666``) or folder (``0o777``) under the current umask."""
    return (0o777 if directory else 0o666) & ~process_umask()


def _create_unique(folder: Path, prefix: str, suffix: str,
                   create: Callable[[Path], None]) -> Path:
    """``create(folder/prefix<random>suffix)`` for a name that does not exist yet."""
    for _ in range(100):
        candidate = folder / f"{prefix}{secrets.token_hex(6)}{suffix}"
        try:
            create(candidate)
        except FileExistsError:
            continue
        return candidate
    raise FileExistsError(f"{folder}: no free temporary name {prefix}*{suffix}")


def _new_file(path: Path) -> None:
    os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))   # less the umask


def temporary_folder(parent: str | os.PathLike, prefix: str) -> Path:
    """Create a new empty folder ``parent/prefix<random>`` with a new folder's mode.

    Unlike :func:`tempfile.mkdtemp` (owner-only ``0700``) the folder gets ``0777`` less the
    umask, applied by the kernel, so it can be published (renamed) as it is.
    """
    return _create_unique(Path(parent), prefix, "", lambda p: os.mkdir(p, 0o777))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds.

    ``suffix`` (default: that of ``path``) lets writers that choose a format from the file
    name (meshio, matplotlib) see the right extension. On error the temporary file is removed
    and ``path`` is left as it was.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path}: folder {path.parent} does not exist")
    tmp = _create_unique(path.parent, f".{path.name}.",
                         path.suffix if suffix is None else suffix, _new_file)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (flushed to disk before the rename)."""
    with atomic_path(path, ".tmp") as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str, encoding: str = "utf-8",
                      newline: str | None = None) -> Path:
    """Write ``text`` to ``path`` atomically; ``newline`` as for :func:`open` (e.g. "\\r\\n")."""
    with atomic_path(path, ".tmp") as tmp:
        with open(tmp, "w", encoding=encoding, newline=newline) as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)
