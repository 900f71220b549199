"""Issue 16: results a user can trust, tested the way users call the product — the Python
API called several times in one process, results that do not depend on output switches
or checkpoint cadence, what a jump is, the run directory protected and locked, damaged
checkpoints named, Parquet files that describe themselves."""
from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

import saltation
from saltation.engine.simulation import (
    CHECKPOINT,
    CHECKPOINT_FRACTION,
    RunInterrupted,
    Simulation,
    SimulationError,
    run,
)
from saltation.io.run_directory import LOCK, RunDirectoryError

ROOT = Path(__file__).resolve().parents[1]


def case(n=24, duration=0.4, **extra):
    """Quartz d = 0.69 mm on the rough log law at τ*/τ*c = 1.79: 0.4 s = 14.7 d/u* = 733 steps."""
    c = {
        "particle": {"diameter": 0.69e-3},
        "flow": {"source": "loglaw", "tau_ratio": 1.79},
        "run": {"n_particles": n, "duration": duration, "dt_particle": 0.02, "seed": 5, "threads": 1},
        "output": {"tracks": True, "vtk": False},
    }
    for key, value in extra.items():
        table, name = key.split(".")
        c.setdefault(table, {})[name] = value
    return c


def simulation(c, out, **kw):
    from saltation.case.schema import load_case, resolve_domain
    from saltation.engine.simulation import open_flow

    cc = resolve_domain(load_case(c))
    return Simulation(cc, open_flow(cc), Path(out), progress=False, **kw)


# --------------------------------------------------------------------------- 1. the API
def test_saltation_run_can_be_called_again_and_again_in_one_process(tmp_path):
    results = [saltation.run(case(n=8, duration=0.1), out=tmp_path / f"r{k}", progress=False) for k in range(3)]
    assert callable(saltation.run)
    assert [r.summary["status"] for r in results] == ["completed"] * 3
    # the same case and seed three times: the same run
    for r in results[1:]:
        pd.testing.assert_frame_equal(r.tracks, results[0].tracks, check_exact=True)


def test_diffusion_is_reachable_after_a_plain_import():
    code = "import saltation; print(callable(saltation.analysis.diffusion.exponents), callable(saltation.run))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "True"]


# --------------------------------------------------------------------------- 2. what a jump is
def test_a_grain_resting_on_the_bed_makes_no_micro_jumps(tmp_path):
    """A grain released with its bottom on the virtual bed in still water chatters on the
    bed every few steps (weight in, rebound out): before bed/jumps.py each bounce was a
    "jump" (83 in 7 d/u*, 0.001–0.007 d high, 2–5 steps long). It is one bed-contact
    episode: no jump at all."""
    res = run(case(n=1, duration=0.2, **{"flow.source": "still", "run.release_height": 0.5,
                                         "collisions.model": "off"}), out=tmp_path / "rest", progress=False)
    particles = pd.read_parquet(tmp_path / "rest" / "particles.parquet")
    assert particles["bed_impacts"].iloc[0] > 50  # it does touch the bed, step after step
    assert res.summary["jumps"]["recorded"] == 0
    assert len(res.jumps) == 0


@pytest.mark.parametrize("bed, contacts", [("virtual", "off"), ("virtual", "soft"), ("packed", "soft")])
def test_no_recorded_jump_is_shorter_than_a_step_or_lower_than_a_steps_fall(tmp_path, bed, contacts):
    from saltation.case.schema import load_case
    from saltation.physics.forces import ALPHA, TAU_STAR, make_coefficients

    c = case(n=60, duration=0.8, **{"bed.model": bed, "collisions.model": contacts})
    res = run(c, out=tmp_path / "r", progress=False)
    j = res.jumps
    assert len(j) > 100
    lc = load_case(c)
    coef = make_coefficients(tau_star=lc.shields_number, R=lc.submerged_specific_gravity, re_star=lc.shear_reynolds)
    dt = lc.dt_particle
    assert j["duration"].min() >= dt
    assert j["height"].min() >= max(0.01, 0.5 * coef[ALPHA] / coef[TAU_STAR] * dt * dt)
    # U = L/T is bounded by the fastest grain: no 1e9 u* outliers in the statistics
    assert j["velocity"].abs().max() < 40.0
    s = res.summary["jumps"]
    assert s["T_shortest"] >= dt
    # the mean of L/T and the flight-weighted ΣL/ΣT agree within the spread
    assert abs(s["U_mean"] - s["U_flight_weighted"]) < s["U_std"]


# --------------------------------------------------------------------------- 3. output switches
SWITCHES = {"output.tracks": [True, False], "output.vtk": [True, False], "output.variance": [True, False]}


def _fingerprint(out: Path):
    s = json.loads((out / "summary.json").read_text())
    # the file as written: its rows are in (particle, jump) order whatever the chunking
    jumps = pd.read_parquet(out / "jumps.parquet")
    assert jumps.equals(jumps.sort_values(["particle", "jump"], ignore_index=True))
    return (s["steps"], s["jumps"], s["collisions"], s["steps_above_flow_top"], jumps,
            pd.read_parquet(out / "particles.parquet"))


def _assert_same(a, b):
    assert a[:4] == b[:4]
    pd.testing.assert_frame_equal(a[4], b[4], check_exact=True)
    pd.testing.assert_frame_equal(a[5], b[5], check_exact=True)


@pytest.mark.parametrize("bed, contacts", [("virtual", "soft"), ("packed", "soft"), ("virtual", "hard")])
def test_output_switches_and_checkpoint_cadence_do_not_change_the_physics(tmp_path, bed, contacts):
    """Every combination of the output switches, and checkpoints every 37 and 300 steps
    (chunk ends, hence kernel calls, in other places), give the same jumps and the same
    end state (positions, velocities, spins of particles.parquet) bit for bit."""
    base = case(n=40, duration=0.25, **{"bed.model": bed, "collisions.model": contacts,
                                        "output.tracks_interval": 0.3, "output.vtk_interval": 0.7})
    ref = None
    variants = [dict(zip(SWITCHES, v)) for v in itertools.product(*SWITCHES.values())]
    variants += [{"output.checkpoint_steps": 37}, {"output.checkpoint_steps": 300, "output.tracks": False},
                 {"output.tracks_interval": 0.02}]
    for k, over in enumerate(variants):
        c = json.loads(json.dumps(base))
        for key, value in over.items():
            table, name = key.split(".")
            c[table][name] = value
        run(c, out=tmp_path / f"v{k}", progress=False)
        got = _fingerprint(tmp_path / f"v{k}")
        if ref is None:
            ref = got
            assert ref[1]["recorded"] > 0 and len(ref[4]) > 0
        else:
            _assert_same(ref, got)


# --------------------------------------------------------------------------- 5. the run directory
def test_a_second_run_into_a_used_directory_is_refused_unless_resume_or_overwrite(tmp_path):
    c = case(n=6, duration=0.05)
    out = tmp_path / "r"
    first = run(c, out=out, progress=False)
    before = (out / "summary.json").read_text()
    with pytest.raises(RunDirectoryError, match=r"not empty \(summary.json says status \"completed\".*--overwrite"):
        run(c, out=out, progress=False)
    assert (out / "summary.json").read_text() == before  # nothing touched
    (out / "notes.txt").write_text("mine")
    again = run(c, out=out, progress=False, overwrite=True, **{"run.seed": 9})
    assert again.summary["status"] == "completed"
    assert (out / "notes.txt").read_text() == "mine"  # not the run's: left alone
    assert not (out / LOCK).exists()
    assert first.summary["jumps"] is not None
    with pytest.raises(RunDirectoryError, match="contradict"):
        run(c, out=out, progress=False, overwrite=True, resume=True)


def test_the_cli_refuses_a_used_directory_and_accepts_overwrite(tmp_path):
    out = tmp_path / "cli"
    args = [sys.executable, "-m", "saltation.cli", "run", str(ROOT / "cases" / "default.toml"), "--out", str(out),
            "--quiet", "--set", "run.duration=0.02", "--set", "run.n_particles=4", "--set", "output.vtk=false"]
    first = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert first.returncode == 0, first.stderr
    second = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert second.returncode == 2
    assert "not empty" in second.stderr and "--overwrite" in second.stderr and "Traceback" not in second.stderr
    third = subprocess.run(args + ["--overwrite"], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert third.returncode == 0, third.stderr


def test_two_runs_at_once_in_one_directory_the_second_is_refused(tmp_path):
    out = tmp_path / "shared"
    c = case(n=200, duration=8.0, **{"output.vtk": False})  # ~1 min of work: stopped long before its end
    (tmp_path / "case.json").write_text(json.dumps(c))
    code = ("import json, sys, saltation; "
            f"saltation.run(json.load(open({str(tmp_path / 'case.json')!r})), out={str(out)!r}, progress=False)")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 300
        while not (out / "config.toml").exists() and time.time() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, proc.stderr.read()
        for kw in ({}, {"overwrite": True}, {"resume": True}):  # not even --overwrite takes it
            with pytest.raises(RunDirectoryError, match=rf"in use by another run \(pid {proc.pid} "):
                run(case(n=4, duration=0.05), out=out, progress=False, **kw)
        while not (out / CHECKPOINT).exists() and time.time() < deadline and proc.poll() is None:
            time.sleep(0.05)  # stepping (signals caught) once the first 5 % checkpoint is there
    finally:
        proc.send_signal(signal.SIGINT)  # the first run checkpoints and stops
        proc.wait(timeout=300)
    s = json.loads((out / "summary.json").read_text())
    cfg = (out / "config.toml").read_text()
    assert s["n_particles"] == 200 and "n_particles = 200" in cfg  # one run's files only
    assert s["status"] == "interrupted" and (out / CHECKPOINT).exists()
    assert not (out / LOCK).exists()


# --------------------------------------------------------------------------- 6. faults
def test_checkpoints_are_taken_by_simulated_progress_as_well(tmp_path, monkeypatch):
    """With the default wall-time cadence (600 s) a short run would never checkpoint:
    every CHECKPOINT_FRACTION of its steps it does, so a kill -9 loses at most that."""
    steps = []
    original = Simulation._write_checkpoint

    def spy(self, st, ws, rows, step, *a):
        steps.append(int(step))
        return original(self, st, ws, rows, step, *a)

    monkeypatch.setattr(Simulation, "_write_checkpoint", spy)
    res = run(case(n=6, duration=0.4, **{"output.tracks": False}), out=tmp_path / "p", progress=False)
    n = res.summary["steps"]
    every = int(np.ceil(CHECKPOINT_FRACTION * n))
    assert steps == list(range(every, n, every))


def test_a_second_ctrl_c_during_the_checkpoint_write_waits_for_it(tmp_path, monkeypatch):
    c = case(n=12, duration=0.4)
    ref = run(c, out=tmp_path / "ref", progress=False)
    original = Simulation._write_checkpoint
    sent = []

    def interrupted_write(self, *a):
        if self._signal is not None and not sent:  # the final checkpoint after a first Ctrl-C
            sent.append(1)
            os.kill(os.getpid(), signal.SIGINT)  # the second Ctrl-C, in the middle of the write
            time.sleep(0.05)
        return original(self, *a)

    monkeypatch.setattr(Simulation, "_write_checkpoint", interrupted_write)
    sim = simulation(c, tmp_path / "b", stop_after_steps=300)
    with pytest.raises(KeyboardInterrupt):
        sim.run()
    assert sent
    assert (tmp_path / "b" / CHECKPOINT).exists() and not (tmp_path / "b" / (CHECKPOINT + ".tmp")).exists()
    monkeypatch.setattr(Simulation, "_write_checkpoint", original)
    res = run(c, out=tmp_path / "b", progress=False, resume=True)
    pd.testing.assert_frame_equal(res.jumps, ref.jumps, check_exact=True)
    pd.testing.assert_frame_equal(res.tracks, ref.tracks, check_exact=True)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_a_damaged_checkpoint_is_named_with_what_to_do(tmp_path, damage):
    c = case(n=6, duration=0.2)
    with pytest.raises(RunInterrupted):
        simulation(c, tmp_path / "a", stop_after_steps=200).run()
    path = tmp_path / "a" / CHECKPOINT
    data = path.read_bytes()
    path.write_bytes({"truncate": data[: len(data) // 2], "garbage": b"not a zip file" * 10, "empty": b""}[damage])
    with pytest.raises(SimulationError, match=rf"checkpoint {path} is damaged.*--overwrite"):
        run(c, out=tmp_path / "a", progress=False, resume=True)


def test_variance_sums_travel_inside_the_checkpoint(tmp_path):
    """No separate variance state to lose: a resumed run writes the uninterrupted run's
    variance.parquet; a checkpoint written with output.variance off cannot switch it on."""
    c = case(n=16, duration=0.4, **{"output.tracks": False})
    ref = run(c, out=tmp_path / "ref", progress=False)
    with pytest.raises(RunInterrupted):
        simulation(c, tmp_path / "b", stop_after_steps=300).run()
    assert sorted(p.name for p in (tmp_path / "b").iterdir() if p.suffix == ".npz") == [CHECKPOINT]
    run(c, out=tmp_path / "b", progress=False, resume=True)
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "ref" / "variance.parquet"),
                                  pd.read_parquet(tmp_path / "b" / "variance.parquet"), check_exact=True)
    assert ref.summary["status"] == "completed"
    off = case(n=16, duration=0.4, **{"output.tracks": False, "output.variance": False})
    with pytest.raises(RunInterrupted):
        simulation(off, tmp_path / "c", stop_after_steps=300).run()
    with pytest.raises(SimulationError, match="written without the displacement variances.*output.variance=false"):
        run(c, out=tmp_path / "c", progress=False, resume=True)
    done = run(off, out=tmp_path / "c", progress=False, resume=True)
    assert done.summary["status"] == "completed"


# --------------------------------------------------------------------------- 8. self-describing files
def test_parquet_files_carry_units_meanings_and_the_discarded_jumps(tmp_path):
    res = run(case(n=20, duration=0.8), out=tmp_path / "r", progress=False)
    tracks = pq.read_schema(tmp_path / "r" / "tracks.parquet")
    assert tracks.field("t").metadata[b"unit"] == b"d/u*"
    assert b"unwrapped" in tracks.field("x").metadata[b"description"]
    assert b"bed top" in tracks.field("y").metadata[b"description"]
    meta = json.loads(tracks.metadata[b"saltation"])
    assert meta["d_m"] == pytest.approx(0.69e-3) and meta["time_scale_s"] > 0
    jumps = pq.read_table(tmp_path / "r" / "jumps.parquet")
    assert jumps.schema.field("height").metadata[b"unit"] == b"d"
    j = jumps.to_pandas()
    assert (j["discarded"] == (j["jump"] < 10)).all() and j["discarded"].any() and (~j["discarded"]).any()
    assert res.summary["jumps"]["count"] == int((~j["discarded"]).sum())
    parts = pq.read_schema(tmp_path / "r" / "particles.parquet")
    assert parts.field("x").metadata[b"unit"] == b"d"


def test_a_run_too_short_for_any_jump_writes_an_empty_jumps_file_with_its_columns(tmp_path):
    """A few steps, no jump finished (no part file was ever written): jumps.parquet has
    no row but every column, with units."""
    res = run(case(n=4, duration=0.01), out=tmp_path / "r", progress=False)
    jumps = pq.read_table(tmp_path / "r" / "jumps.parquet")
    assert jumps.num_rows == 0 and res.summary["jumps"]["recorded"] == 0
    assert jumps.schema.field("height").metadata[b"unit"] == b"d"
    assert pd.read_parquet(tmp_path / "r" / "jumps.parquet").columns[:2].tolist() == ["particle", "jump"]
