"""The progress bar: a terminal gets redraws, a log file gets a line every 30 s at most."""
import io
import sys

from saltation.progress import LOG_INTERVAL, progress_bar


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_log_file_gets_sparse_progress_lines(monkeypatch):
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    bar = progress_bar(1000, desc="case", enabled=True)
    assert bar.mininterval == LOG_INTERVAL >= 10
    bar.close()


def test_terminal_gets_frequent_redraws(monkeypatch):
    monkeypatch.setattr(sys, "stderr", _Tty())
    bar = progress_bar(1000, desc="case", enabled=True)
    assert bar.mininterval <= 0.5
    bar.close()


def test_disabled_bar_writes_nothing(monkeypatch):
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    bar = progress_bar(10, desc="case", enabled=False)
    for _ in range(10):
        bar.update(1)
    bar.close()
    assert log.getvalue() == ""
