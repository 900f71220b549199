"""The progress bar: a terminal gets redraws, a log file gets a line every 30 s at most."""
import io
import sys
import time

from saltation.io.progress import LOG_INTERVAL, progress_bar


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


def test_compile_notice_speaks_once_per_cache_and_quotes_the_wait(tmp_path, monkeypatch, capsys):
    """A cold cache: a notice with the expected time before the compile, heartbeats while it
    lasts, the measured time after; a warm one (marker written): silence."""
    import numba

    from flowfields._numba_cache import kernel_version
    from saltation.io import progress

    version = kernel_version()
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(progress, "COMPILE_HEARTBEAT_S", 0.05)
    with progress.compile_notice(True, "spheres"):
        time.sleep(0.2)
    err = capsys.readouterr().err
    assert "compiling the spheres kernels, once per installation" in err
    assert f"~{progress.COMPILE_ESTIMATE_S['spheres']:.0f} s" in err
    assert "still compiling" in err and "kernels compiled in" in err
    assert (tmp_path / "cache" / f"compiled-spheres-{version}.json").exists()
    with progress.compile_notice(True, "spheres"):
        pass
    assert capsys.readouterr().err == ""
    with progress.compile_notice(False, "composites"):  # --quiet: nothing, and no marker
        pass
    assert capsys.readouterr().err == "" and not (tmp_path / "cache" / f"compiled-composites-{version}.json").exists()
