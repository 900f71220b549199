"""Bad input and faults at the command line (issue 16 items 6 and 7): an unusable --out,
a missing [sweep] extra, a bad --set value, a broken meta.json and Ctrl-C at any moment
are one clear line on stderr and an exit status, never a traceback."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

import saltation.engine.simulation
import saltation.studies.sweep
import saltation.studies.validate
from flowfields import DatasetError, open_dataset
from flowfields.dataset import write_dataset
from saltation.cli import main
from saltation.io.run_directory import (
    CHECKPOINT_NAME,
    OutputDirectoryError,
    check_output_directory,
)

ROOT = Path(__file__).resolve().parents[1]
LOGLAW = str(ROOT / "cases" / "loglaw.toml")
TINY = ["--set", "run.duration=0.05", "--set", "run.n_particles=10"]


@pytest.fixture
def no_long_work(monkeypatch):
    """Fail the test if the command gets as far as the simulation / sweep / validation."""
    def boom(*a, **k):
        raise AssertionError("the bad input was not caught before the long work")

    monkeypatch.setattr(saltation.engine.simulation, "run", boom)
    monkeypatch.setattr(saltation.studies.sweep, "run_case", boom)
    monkeypatch.setattr(saltation.studies.validate, "run_validation", boom)


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("saltation: error: "), err
    return lines[0]


# --------------------------------------------------------------------------- --out


def out_cases(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    return {"file": (f, "is an existing file"), "under_file": (f / "run", "lies under")}


@pytest.mark.parametrize("which", ["file", "under_file"])
@pytest.mark.parametrize("command", [
    ["run", LOGLAW, "--quiet", *TINY],
    ["sweep", str(ROOT / "cases" / "concentration_sweep_reduced.toml")],
    ["validate", "nino-garcia", "--no-ablation"],
    ["flow", "check"],
])
def test_unusable_out_is_an_error_before_any_work(tmp_path, capsys, no_long_work, which, command):
    path, problem = out_cases(tmp_path)[which]
    assert main([*command, "--out", str(path)]) == 2
    line = one_error_line(capsys)
    assert str(path) in line and problem in line


def test_default_run_directory_is_checked_too(tmp_path, capsys, no_long_work, monkeypatch):
    (tmp_path / "runs").write_text("a file where the default runs/ folder goes")
    monkeypatch.chdir(tmp_path)
    assert main(["run", LOGLAW, "--quiet", *TINY]) == 2
    line = one_error_line(capsys)
    assert "run directory" in line and "runs" in line and "lies under" in line


def test_out_that_cannot_be_written(tmp_path, capsys, no_long_work, monkeypatch):
    """A folder the file system refuses (read-only mount, no permission): detected by really
    creating a file, since permission bits do not stop root."""
    target = tmp_path / "ro"
    target.mkdir()

    def refuse(*a, dir=None, **k):
        raise PermissionError(13, "Permission denied", str(dir))

    monkeypatch.setattr("saltation.io.run_directory.tempfile", types.SimpleNamespace(mkstemp=refuse))
    assert main(["run", LOGLAW, "--quiet", "--out", str(target / "run"), *TINY]) == 2
    line = one_error_line(capsys)
    assert str(target / "run") in line and "cannot be written" in line and "Permission denied" in line


def test_read_only_folder_by_permissions(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        try:  # root (this sandbox, many containers) writes through the permission bits
            (ro / "probe").write_text("x")
            (ro / "probe").unlink()
            pytest.skip("running as a user that can write into a mode-555 folder (root)")
        except PermissionError:
            pass
        with pytest.raises(OutputDirectoryError, match="cannot be written"):
            check_output_directory(ro / "run")
    finally:
        ro.chmod(0o755)


def test_check_output_directory_creates_nothing(tmp_path):
    assert check_output_directory(tmp_path) == tmp_path
    deep = tmp_path / "a" / "b" / "c"
    assert check_output_directory(deep) == deep
    assert list(tmp_path.iterdir()) == []  # neither the folders nor the probe file are left


# --------------------------------------------------------------------------- sweep extra


def test_sweep_without_dask_names_the_extra(tmp_path, capsys, monkeypatch):
    sweep = tiny_sweep(tmp_path)
    monkeypatch.setitem(sys.modules, "dask", None)  # as if the extra were not installed
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    assert main(["sweep", str(sweep), "--out", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys)
    assert "the sweep needs the [sweep] extra: pip install 'saltation[sweep]'" in line


def tiny_sweep(tmp_path) -> Path:
    sweep = tmp_path / "s.toml"
    sweep.write_text('[particle]\ndiameter = 0.69e-3\n[flow]\nsource = "loglaw"\ntau_ratio = 1.79\n'
                     '[run]\nn_particles = 4\nduration = 0.05\n[sweep]\n"run.seed" = [0, 1]\n')
    return sweep


@pytest.mark.parametrize("address, words", [("foo", "missing port number"), ("nonsense://x:1", "unknown address scheme")])
def test_sweep_scheduler_address_is_checked(tmp_path, capsys, no_long_work, address, words):
    assert main(["sweep", str(tiny_sweep(tmp_path)), "--out", str(tmp_path / "out"), "--scheduler", address]) == 2
    line = one_error_line(capsys)
    assert f"--scheduler {address!r}" in line and words in line


def test_sweep_scheduler_that_cannot_be_reached(tmp_path, capsys, no_long_work):
    import dask

    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        assert main(["sweep", str(tiny_sweep(tmp_path)), "--out", str(tmp_path / "out"),
                     "--scheduler", "tcp://127.0.0.1:1"]) == 2
    line = one_error_line(capsys)
    assert "--scheduler tcp://127.0.0.1:1: cannot reach the Dask scheduler" in line


# --------------------------------------------------------------------------- --set


@pytest.mark.parametrize("item, words", [
    ("run.dt_particle=abc", ["must be a number", "'abc'"]),
    ("bed.model=wrong", ['"virtual"', '"packed"']),
    ("bed.restitusion=0.5", ["did you mean bed.restitution"]),
    ("run.concentration=1e-15", ["fewer than one grain"]),  # a check after loading (domain rules)
])
def test_bad_set_value_blames_the_set_option(capsys, no_long_work, item, words):
    assert main(["run", LOGLAW, "--quiet", "--set", item]) == 2
    line = one_error_line(capsys)
    assert line.startswith(f"saltation: error: --set {item}: "), line
    assert "loglaw.toml" not in line  # the case file is not to blame
    for w in words:
        assert w in line


def test_malformed_set_is_exit_2(capsys, no_long_work):
    assert main(["run", LOGLAW, "--set", "run.seed"]) == 2
    assert "--set 'run.seed': expects TABLE.KEY=VALUE" in one_error_line(capsys)


def test_case_file_errors_still_name_the_file(tmp_path, capsys, no_long_work):
    case = tmp_path / "bad.toml"
    case.write_text((ROOT / "cases" / "loglaw.toml").read_text().replace("seed = ", "seed = -1 #"))
    assert main(["run", str(case), "--set", "run.duration=0.05"]) == 2
    line = one_error_line(capsys)
    assert str(case) in line and "run.seed" in line and "--set run.duration" not in line


# --------------------------------------------------------------------------- other input


def test_validate_data_file_is_checked_first(tmp_path, capsys, no_long_work):
    assert main(["validate", "nino-garcia", "--data", str(tmp_path / "none.csv"), "--out", str(tmp_path / "v")]) == 2
    assert "--data" in one_error_line(capsys)
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    assert main(["validate", "nino-garcia", "--data", str(bad), "--out", str(tmp_path / "v")]) == 2
    assert "missing column" in one_error_line(capsys)


@pytest.mark.parametrize("content, words", [("{bad", "not valid JSON"), ("[1, 2]", "must hold a JSON object")])
def test_flow_import_provenance_file(tmp_path, capsys, content, words):
    prov = tmp_path / "prov.json"
    prov.write_text(content)
    assert main(["flow", "import", str(tmp_path), "--out", str(tmp_path / "ds"), "--nu", "1e-6",
                 "--provenance", str(prov)]) == 2
    assert words in one_error_line(capsys)


# --------------------------------------------------------------------------- meta.json


def tiny_dataset(path) -> Path:
    x = 5.0 + 10.0 * np.arange(4)
    y = np.array([1.0, 2.0, 4.0, 8.0])
    z = 10.0 * np.arange(4)
    u = np.zeros((2, 4, 4, 4, 3))
    u[..., 0] = y[None, None, :, None]
    return write_dataset(path, x, y, z, u, 180.0, [0.0, 1.0], {"test": True})


def edit_meta(path, **changes):
    meta = json.loads((path / "meta.json").read_text())
    for k, v in changes.items():
        if v is KeyError:
            meta.pop(k)
        else:
            meta[k] = v
    (path / "meta.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("key, value, shown", [
    ("re_tau", "395", '"395"'),
    ("re_tau", -180.0, "-180.0"),
    ("re_tau", 0, "= 0 "),
    ("re_tau", float("nan"), "NaN"),
    ("re_tau", True, "true"),
    ("re_tau", KeyError, "missing"),
    ("format_version", 2, "= 2 "),
    ("times_plus", ["0", 1.0], '"0"'),
    ("times_plus", [], "[]"),
    ("storage", {"dtype": "float32", "scale": [1, 1, 0], "offset": [0, 0, 0]}, "[1, 1, 0]"),
    ("storage", {"dtype": "float64", "scale": [1, 1, 1], "offset": [0, 0, 0]}, '"float64"'),
    ("storage", {"dtype": "float32", "scale": [1, 1, 1], "offset": "0"}, '"0"'),
    ("provenance", "me", '"me"'),
    ("box_plus", [40.0, -8.0, 40.0], "-8.0"),
    ("grid", [4, 4, 5], "[4, 4, 5]"),
])
def test_bad_meta_json_is_named_when_opened(tmp_path, key, value, shown):
    ds = tiny_dataset(tmp_path / "ds")
    open_dataset(ds)  # as written: fine
    edit_meta(ds, **{key: value})
    with pytest.raises(DatasetError) as info:
        open_dataset(ds)
    msg = str(info.value)
    assert str(ds / "meta.json") in msg and key in msg and shown in msg, msg


def test_bad_meta_json_at_the_command_line(tmp_path, capsys):
    ds = tiny_dataset(tmp_path / "ds")
    edit_meta(ds, re_tau=-1.0)
    assert main(["flow", "info", str(ds)]) == 2
    line = one_error_line(capsys)
    assert "re_tau = -1.0" in line and "positive" in line
    # a run on it is stopped by the dataset, not blamed on run.domain
    assert main(["run", LOGLAW, "--quiet", "--out", str(tmp_path / "run"), "--set", "flow.source=les",
                 "--set", f"flow.dataset={ds}", *TINY]) == 2
    line = one_error_line(capsys)
    assert "meta.json" in line and "re_tau" in line and "run.domain" not in line


# --------------------------------------------------------------------------- Ctrl-C


def ctrl_c(*a, **k):
    raise KeyboardInterrupt


def main_no_escape(argv) -> int:
    """main(), with a KeyboardInterrupt that escapes it a test failure (not pytest's own stop)."""
    try:
        return main(argv)
    except KeyboardInterrupt:
        pytest.fail("KeyboardInterrupt escaped saltation.cli.main")


@pytest.mark.parametrize("command, target, words", [
    (["run", LOGLAW, "--quiet", "--out", "OUT"], "saltation.engine.simulation.run",
     ["nothing to resume", "start again with: saltation run"]),
    (["sweep", str(ROOT / "cases" / "concentration_sweep_reduced.toml"), "--out", "OUT"], "saltation.studies.sweep.run_sweep",
     ["sweep interrupted", "run the same command again"]),
    (["validate", "nino-garcia", "--no-ablation", "--out", "OUT"], "saltation.studies.validate.run_validation",
     ["validate interrupted"]),
    (["analyze", ".", "--out", "OUT"], "saltation.analysis.report.analyze", ["analyze interrupted"]),
    (["flow", "info"], "flowfields.open_dataset", ["flow info interrupted"]),
    (["flow", "check", "--out", "OUT"], "flowfields.open_dataset", ["flow check interrupted"]),
])
def test_ctrl_c_anywhere_is_one_line_and_130(tmp_path, capsys, monkeypatch, command, target, words):
    monkeypatch.setattr(target, ctrl_c)
    assert main_no_escape([str(tmp_path / "out") if a == "OUT" else a for a in command]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("saltation: ")
    for w in words:
        assert w in err, err


def test_ctrl_c_before_stepping_with_a_checkpoint_names_the_resume(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"

    def interrupted_while_loading(case, out=None, **kw):  # --resume into a run with a checkpoint
        (Path(out) / CHECKPOINT_NAME).write_bytes(b"")
        raise KeyboardInterrupt

    out.mkdir()
    monkeypatch.setattr(saltation.engine.simulation, "run", interrupted_while_loading)
    assert main_no_escape(["run", LOGLAW, "--quiet", "--resume", "--out", str(out), "--set", "run.seed=4"]) == 130
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert f"--resume --out {out} --set run.seed=4" in err and str(out / CHECKPOINT_NAME) in err


def cli_command(*argv) -> list[str]:
    """`python -m saltation.cli ARGV`, with Ctrl-C raising KeyboardInterrupt from the first line
    (where the tests run as a background job, SIGINT is inherited as ignored)."""
    code = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            f"sys.argv = ['saltation', *{list(argv)!r}]; runpy.run_module('saltation.cli', run_name='__main__')")
    return [sys.executable, "-c", code]


def test_sigint_while_loading_and_compiling_a_real_run(tmp_path):
    """SIGINT to the console command as soon as its run directory appears (the flow is being
    opened, the kernels loaded/compiled): exit 130, a line or two, no traceback."""
    out = tmp_path / "run"
    cmd = cli_command("run", LOGLAW, "--out", str(out), "--quiet", "--set", "run.duration=2.0",
                      "--set", "run.n_particles=10")
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not out.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.002)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and 1 <= len(err.strip().splitlines()) <= 2, err
    assert "interrupted" in err


def children(pid: int) -> list[str]:
    """Child processes of pid, started by any of its threads (Linux /proc)."""
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found += (task / "children").read_text().split()
        except OSError:  # a thread that just ended
            pass
    return found


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to see the cluster's worker start")
def test_sigint_while_a_sweep_starts_its_cluster(tmp_path):
    """SIGINT as soon as the sweep folder is written (Dask imported, the LocalCluster
    starting): exit 130, no traceback (distributed's own exit-time close of a half-started
    cluster printed one)."""
    sweep = tmp_path / "s.toml"
    sweep.write_text('[particle]\ndiameter = 0.69e-3\n[flow]\nsource = "loglaw"\ntau_ratio = 1.79\n'
                     '[run]\nn_particles = 4\nduration = 5.0\n[output]\nvtk = false\n[sweep]\n"run.seed" = [0, 1]\n')
    out = tmp_path / "out"
    cmd = cli_command("sweep", str(sweep), "--out", str(out), "--workers", "1")
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not children(proc.pid) and proc.poll() is None and time.time() < deadline:
        time.sleep(0.002)  # the first worker (or its resource tracker) is being spawned
    time.sleep(0.3)  # the cluster is still waiting for its worker
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert "saltation: sweep interrupted; finished cases are kept in" in err
