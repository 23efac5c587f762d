"""georeg_app.cli logging: third-party loggers stay at WARNING (no DEBUG flood under
--verbose), ours follow --quiet/--verbose; progress bars only on a terminal."""
import io
import logging

from georeg_app import cli


def _emit_all(stream) -> str:
    for name in ("matplotlib.font_manager", "PIL.PngImagePlugin", "numba.core", "urllib3",
                 "asyncio", "distributed.worker", "somelib"):
        logging.getLogger(name).debug("third-party debug %s", name)
        logging.getLogger(name).info("third-party info %s", name)
    logging.getLogger(name).warning("third-party warning")
    logging.getLogger("georeg_app.shape.pipeline").debug("our debug")
    logging.getLogger("fesdic_core.shape.driver").info("our info")
    logging.getLogger("fesdic_core.fe.mesh_io").info("chatty info")
    return stream.getvalue()


def _stderr(monkeypatch) -> io.StringIO:
    """Replace sys.stderr in the test body (pytest swaps it between setup and call)."""
    stream = io.StringIO()
    monkeypatch.setattr("sys.stderr", stream)
    return stream


def test_verbose_shows_our_debug_but_no_third_party_chatter(monkeypatch):
    stderr = _stderr(monkeypatch)
    levels_before = {n: logging.getLogger(n).level for n in ("", "matplotlib", "georeg_app")}
    with cli._logging_to_stderr(quiet=False, verbose=True):
        text = _emit_all(stderr)
    assert "our debug" in text and "our info" in text and "chatty info" in text
    assert "third-party debug" not in text and "third-party info" not in text
    assert "third-party warning" in text
    assert {n: logging.getLogger(n).level for n in levels_before} == levels_before   # restored


def test_default_and_quiet_levels(monkeypatch):
    stderr = _stderr(monkeypatch)
    with cli._logging_to_stderr(quiet=False, verbose=False):
        text = _emit_all(stderr)
    assert "our info" in text and "our debug" not in text and "chatty info" not in text
    assert "third-party info" not in text
    with cli._logging_to_stderr(quiet=True, verbose=False):
        text = _emit_all(stderr)[len(text):]
    assert "our info" not in text and "third-party warning" in text


class _Stream(io.StringIO):
    def __init__(self, tty: bool):
        super().__init__()
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty


def test_progress_only_on_a_terminal_and_not_quiet(monkeypatch):
    monkeypatch.setattr("sys.stderr", _Stream(True))
    assert cli.progress_enabled(quiet=False) is True
    assert cli.progress_enabled(quiet=True) is False
    monkeypatch.setattr("sys.stderr", _Stream(False))
    assert cli.progress_enabled(quiet=False) is False
