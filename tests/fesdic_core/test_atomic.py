"""Atomic output files (fesdic_core.atomic): all or nothing, with a new file's permissions."""
import os
import stat

import pytest

from fesdic_core.atomic import (DEFAULT_UMASK, atomic_path, process_umask, public_mode,
                                temporary_folder, write_bytes_atomic, write_text_atomic)


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def test_written_files_have_the_permissions_of_a_new_file(tmp_path):
    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "a.txt", "hello")
        write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01")
        assert _mode(tmp_path / "a.txt") == _mode(tmp_path / "b.bin") == 0o644 == public_mode()
        assert public_mode(directory=True) == 0o755
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").read_text() == "hello"


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "mesh.vtu"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            assert tmp.suffix == ".vtu" and tmp.parent == tmp_path
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.vtu"]


def test_missing_folder_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere"):
        write_text_atomic(tmp_path / "nowhere" / "x.txt", "x")


def test_umask_is_read_without_changing_it(tmp_path, monkeypatch):
    calls = []
    real_umask = os.umask
    old = real_umask(0o027)
    monkeypatch.setattr(os, "umask", lambda mask: calls.append(mask) or real_umask(mask))
    try:
        assert process_umask() == 0o027 or not os.path.exists("/proc/self/status")
        write_text_atomic(tmp_path / "a.txt", "x")
        assert _mode(tmp_path / "a.txt") == 0o640                 # the kernel applied it
        assert calls == []                                         # never toggled
    finally:
        real_umask(old)


def test_umask_falls_back_to_the_usual_default_without_proc(monkeypatch):
    import builtins
    real_open = builtins.open

    def no_proc(file, *args, **kwargs):
        if str(file).startswith("/proc/"):
            raise FileNotFoundError(file)
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", no_proc)
    assert process_umask() == DEFAULT_UMASK == 0o022
    assert public_mode() == 0o644 and public_mode(directory=True) == 0o755


def test_temporary_folder_has_a_new_folders_mode(tmp_path):
    old = os.umask(0o027)
    try:
        a = temporary_folder(tmp_path, ".out.staging-")
        b = temporary_folder(tmp_path, ".out.staging-")
    finally:
        os.umask(old)
    assert a != b and a.parent == b.parent == tmp_path and a.name.startswith(".out.staging-")
    assert _mode(a) == _mode(b) == 0o750 and list(a.iterdir()) == []
