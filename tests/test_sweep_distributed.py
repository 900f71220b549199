"""Sweeps on a real Dask cluster (issue 19 item 5): `saltation sweep --scheduler` against a
`dask scheduler` and two `dask worker` processes on loopback, started here as a user would
start them. One worker is SIGKILLed while its case runs (after that case wrote a
checkpoint): Dask resubmits the case to the surviving worker, the case resumes from its
checkpoint, and its outputs are bit for bit those of the same case run uninterrupted.

The worker processes import this checkout (PYTHONPATH) and share this session's Numba
cache (NUMBA_CACHE_DIR, inherited): the reference run below compiles or loads the kernels
first, so the workers only load them."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from saltation.engine.simulation import CHECKPOINT, PARTS
from saltation.studies.sweep import _failure, load_sweep, run_case

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[1]

# two cases of 300 grains on the log law, soft contacts: 2.0 s = 73 d/u* = 3666 steps, a
# checkpoint every 400 steps (and at every 5 %); 5-10 s each on one core
SWEEP = """
[particle]
diameter = 0.69e-3
[flow]
source = "loglaw"
tau_ratio = 1.79
[collisions]
model = "soft"
[run]
n_particles = 300
duration = 2.0
dt_particle = 0.02
[output]
tracks = true
vtk = false
variance = true
checkpoint_every = 0.0
checkpoint_steps = 400
[sweep]
"run.seed" = [3, 4]
"""
VICTIM = "s3"  # the case whose worker is killed ...
KILL_AFTER = 800  # ... once it has a checkpoint at this step or later
PHYSICS = ("status", "n_particles", "steps", "simulated_time_s", "jumps", "collisions", "steps_above_flow_top",
           "variance")
OUTPUTS = ("jumps.parquet", "tracks.parquet", "particles.parquet", "variance.parquet")


def _env() -> dict:
    """This process's environment (NUMBA_CACHE_DIR included), importing this checkout."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.pop("DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES", None)  # the default (3) is what is tested
    return env


def _wait_for(predicate, timeout: float, what: str, logs=()):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    tails = "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in logs if p.exists())
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}\n{tails}")


@pytest.fixture
def dask_cluster(tmp_path, request):
    """A `dask scheduler` and two `dask worker --nthreads 1 --no-nanny` processes on
    127.0.0.1 (no dashboards): (address, {pid: Popen of each worker}, log files).
    Parametrized indirectly: the scheduler's allowed-failures (default: Dask's, 3)."""
    env = _env()
    allowed = getattr(request, "param", None)
    folder = tmp_path / "cluster"
    folder.mkdir()
    sched_file = folder / "scheduler.json"
    procs, logs = [], []

    def start(name, args):
        log = folder / f"{name}.log"
        logs.append(log)
        with open(log, "wb") as fh:
            p = subprocess.Popen([sys.executable, "-m", "dask", *args], env=env, cwd=folder, stdout=fh,
                                 stderr=subprocess.STDOUT, start_new_session=True)
        procs.append(p)
        return p

    try:
        if allowed is not None:
            env = dict(env, DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES=str(allowed))
        start("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                            "--scheduler-file", str(sched_file)])
        _wait_for(lambda: sched_file.exists() and sched_file.stat().st_size > 0, 60, "the scheduler file", logs)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        env = _env()
        workers = {}
        for i in range(2):
            p = start(f"worker{i}", ["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                     "--host", "127.0.0.1", "--death-timeout", "60", "--name", f"w{i}"])
            workers[p.pid] = p
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=90)
        yield address, workers, logs
    finally:
        # the workers first, then the scheduler: a worker told to stop while its scheduler
        # closes can hang in Dask's shutdown (then it is killed)
        for group in (procs[1:], procs[:1]):
            for p in group:
                if p.poll() is None:
                    p.terminate()
            for p in group:
                try:
                    p.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


def _checkpoint_step(path: Path) -> int:
    """The step of a run's checkpoint (0: none yet)."""
    try:
        with np.load(path) as z:
            return json.loads(bytes(z["meta"]).decode())["step"]
    except FileNotFoundError:
        return 0


def _lock_pid(directory: Path) -> int | None:
    """The pid that a run directory's lock file names (None: no run holds it)."""
    try:
        return json.loads((directory / ".lock").read_text() or "{}").get("pid")
    except (FileNotFoundError, ValueError):
        return None


def _start_sweep(path: Path, out: Path, address: str, log: Path, *more: str) -> subprocess.Popen:
    """`saltation sweep PATH --out OUT --scheduler ADDRESS`, as a user runs it."""
    with open(log, "wb") as fh:
        return subprocess.Popen(
            [sys.executable, "-m", "saltation.cli", "sweep", str(path), "--out", str(out), "--scheduler", address,
             *more],
            env=_env(), cwd=path.parent, stdout=fh, stderr=subprocess.STDOUT)


def _kill_the_worker_running(case: str, address: str, workers: dict, out: Path, sweep_proc, logs):
    """Once ``case`` has a checkpoint at KILL_AFTER or later: SIGKILL the worker process that
    runs it. Returns (pid, worker name, the step of the checkpoint it leaves)."""
    from distributed import Client

    victim = out / "cases" / case
    _wait_for(lambda: _checkpoint_step(victim / CHECKPOINT) >= KILL_AFTER or sweep_proc.poll() is not None,
              240, f"a checkpoint of {case} at step {KILL_AFTER} or later", logs)
    assert sweep_proc.poll() is None, f"the sweep ended before {case} checkpointed:\n{logs[0].read_text()}"
    key = f"saltation-{Path(sweep_proc.args[4]).stem}-{case}-"  # + a hash of the sweep folder
    with Client(address, timeout=30) as client:
        def running_it():
            return next((a for a, keys in client.processing().items()
                         if any(str(k).startswith(key) for k in keys)), None)

        holder = _wait_for(running_it, 30, f"the worker running {key}", logs)
        pid = client.run(os.getpid, workers=[holder])[holder]
        name = client.scheduler_info(n_workers=-1)["workers"][holder]["name"]
    assert pid in workers and workers[pid].args[-1] == name  # --no-nanny: the very process started above
    # the run directory's lock names the process that runs the case
    assert _lock_pid(victim) == pid
    os.kill(pid, signal.SIGSTOP)  # frozen: the checkpoint read now is the one it leaves
    try:
        assert (victim / CHECKPOINT).exists() and not (victim / "summary.json").exists(), \
            f"{case} finished before its worker could be killed: make the case longer"
        killed_at = _checkpoint_step(victim / CHECKPOINT)
    finally:
        os.kill(pid, signal.SIGKILL)
    workers[pid].wait(timeout=30)
    return pid, name, killed_at


def test_sweep_on_a_real_cluster_survives_a_killed_worker(tmp_path, dask_cluster):
    address, workers, logs = dask_cluster
    path = tmp_path / "fault.toml"
    path.write_text(SWEEP)
    sweep = load_sweep(path)
    case = next(c for c in sweep.cases if c.name == VICTIM)

    # the victim case uninterrupted, in its own directory (this also compiles or loads the
    # kernels into the shared Numba cache before the workers need them)
    ref = tmp_path / "reference"
    run_case(case.tables, case.values, case.name, str(ref), 1)

    out = tmp_path / "out"
    victim = out / "cases" / VICTIM
    cli_log = tmp_path / "sweep.log"
    sweep_proc = _start_sweep(path, out, address, cli_log)
    logs = [cli_log, *logs]
    try:
        pid, name, killed_at = _kill_the_worker_running(VICTIM, address, workers, out, sweep_proc, logs)
        survivor = next(p for p in workers if p != pid)
        assert workers[survivor].poll() is None
        # Dask resubmits the case to the surviving worker (the lock names the process that runs it)
        # (the killed one's lock file stays until then, naming it: the kernel dropped the lock itself)
        resumed_by = _wait_for(lambda: _lock_pid(victim) not in (None, pid) and _lock_pid(victim)
                               or sweep_proc.poll() is not None, 240, f"{VICTIM} to start again", logs)
        assert resumed_by == survivor, (resumed_by, survivor, pid)

        rc = sweep_proc.wait(timeout=600)
    finally:
        if sweep_proc.poll() is None:
            sweep_proc.kill()
            sweep_proc.wait()
    text = cli_log.read_text()
    assert rc == 0, text
    assert f"scheduler {address}: 2 worker(s)" in text
    assert "[1/2]" in text and "[2/2]" in text and "[3/2]" not in text  # each case counted once
    df = pd.read_parquet(out / "results.parquet")
    assert sorted(df["case"]) == ["s3", "s4"] and (df["status"] == "completed").all(), text

    # the killed case went on from its checkpoint, on the surviving worker ...
    s = json.loads((victim / "summary.json").read_text())
    assert 0 < killed_at < s["steps"]
    assert s.get("resumed_from_step") == killed_at, (killed_at, s.get("resumed_from_step"))
    assert not (victim / CHECKPOINT).exists() and not (victim / PARTS).exists()
    # ... and ended where the uninterrupted run ends, bit for bit
    r = json.loads((ref / "summary.json").read_text())
    assert "resumed_from_step" not in r and r["jumps"]["count"] > 0
    for k in PHYSICS:
        assert s.get(k) == r.get(k), k
    for file in OUTPUTS:
        a, b = pd.read_parquet(ref / file), pd.read_parquet(victim / file)
        assert len(a) > 0
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    print(f"killed worker {name} (pid {pid}) running {VICTIM} after its checkpoint at step {killed_at} of "
          f"{s['steps']}; resumed from step {s['resumed_from_step']}; outputs identical to the uninterrupted run")
    # the other case ran once, uninterrupted
    assert "resumed_from_step" not in json.loads((out / "cases" / "s4" / "summary.json").read_text())


@pytest.mark.parametrize("dask_cluster", [0], indirect=True)  # the scheduler gives a case up at once
def test_a_case_given_up_by_the_scheduler_is_reported_and_resumed_next_time(tmp_path, dask_cluster):
    address, workers, logs = dask_cluster
    path = tmp_path / "fault.toml"
    path.write_text(SWEEP)
    out = tmp_path / "out"
    cli_log = tmp_path / "sweep.log"
    sweep_proc = _start_sweep(path, out, address, cli_log)
    logs = [cli_log, *logs]
    try:
        pid, name, killed_at = _kill_the_worker_running(VICTIM, address, workers, out, sweep_proc, logs)
        rc = sweep_proc.wait(timeout=600)
    finally:
        if sweep_proc.poll() is None:
            sweep_proc.kill()
            sweep_proc.wait()
    text = cli_log.read_text()
    assert rc == 1, text
    line = next(x for x in text.splitlines() if f"{VICTIM}: FAILED" in x)
    assert f"{VICTIM}: FAILED KilledWorker: the worker process running this case died, on 1 worker(s) in turn" \
        in line, line
    assert f"allowed-failures + 1 = 1 lost worker(s); its checkpoint at step {killed_at} is kept: run the same " \
           "command again to resume it" in line
    assert "s4: completed" in text and "[2/2]" in text and "[3/2]" not in text
    assert f"1 case(s) not completed: {VICTIM}" in text
    df = pd.read_parquet(out / "results.parquet").set_index("case")
    assert df.loc[VICTIM, "status"] == "failed" and df.loc["s4", "status"] == "completed"
    assert df.loc[VICTIM, "error"].startswith("KilledWorker: ")

    # the same command again, on the surviving worker: the given-up case resumes (one Numba
    # thread, not the default two of a lone worker on two cores: the test suite has the other)
    again = tmp_path / "again.log"
    proc = _start_sweep(path, out, address, again, "--threads-per-worker", "1")
    assert proc.wait(timeout=600) == 0, again.read_text()
    text = again.read_text()
    assert "2 cases, 1 already finished, 1 to run" in text
    assert f"[2/2] {VICTIM}: completed (resumed from step {killed_at})" in text
    s = json.loads((out / "cases" / VICTIM / "summary.json").read_text())
    assert s["status"] == "completed" and s["resumed_from_step"] == killed_at


def test_killed_worker_message_names_the_cause_and_the_checkpoint(tmp_path):
    from types import SimpleNamespace

    from distributed.scheduler import KilledWorker

    err = KilledWorker("saltation-x-s3-0", SimpleNamespace(address="tcp://127.0.0.1:1234"), 3)
    msg = _failure(err, tmp_path)
    assert msg.startswith("KilledWorker: the worker process running this case died, on 4 worker(s) in turn")
    assert "the last was tcp://127.0.0.1:1234" in msg and "it left no checkpoint" in msg
    meta = np.frombuffer(json.dumps({"step": 1234}).encode(), dtype=np.uint8)
    np.savez(tmp_path / CHECKPOINT, meta=meta)
    assert "its checkpoint at step 1234 is kept: run the same command again to resume it" in _failure(err, tmp_path)
    assert _failure(ValueError("boom"), tmp_path) == "ValueError: boom"


def test_the_full_size_paper_case_file():
    """cases/paper_full_c0.52.toml: one case, the paper's domain at C = 0.52 %, as its comment says."""
    from saltation.case.schema import load_case, resolve_domain

    sw = load_sweep(ROOT / "cases" / "paper_full_c0.52.toml")
    assert [c.name for c in sw.cases] == ["c0.52_t1.79"]
    case = resolve_domain(load_case(sw.cases[0].tables, sw.cases[0].values))
    assert tuple(case.run.domain) == (0.176, 0.088, 0.028)
    assert case.n_particles == 13110 and case.n_steps == 9165
