"""Checkpoint and restart (issue 4 item 6): an interrupted and resumed run is the
uninterrupted run, bit for bit — jumps.parquet, tracks.parquet, the jump statistics and
the ParaView frames — whether it was stopped by a signal (SIGINT to the CLI), by the
in-process test hook, or killed after a periodic checkpoint."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from saltation.case.schema import load_case
from saltation.engine.simulation import (
    CHECKPOINT,
    PARTS,
    RunInterrupted,
    Simulation,
    SimulationError,
    _les_box_m,
    open_flow,
    resolve_domain,
    run,
)

ROOT = Path(__file__).resolve().parents[1]


def tiny_case(n=24, duration=0.8, **extra):
    """Loglaw source, quartz d = 0.69 mm at τ*/τ*c = 1.79: 0.8 s = 29 d/u* = 1465 steps."""
    case = {
        "particle": {"diameter": 0.69e-3},
        "flow": {"source": "loglaw", "tau_ratio": 1.79},
        "run": {"n_particles": n, "duration": duration, "dt_particle": 0.02, "seed": 3, "threads": 1, "name": "tiny"},
        "output": {"tracks": True, "vtk": True, "vtk_interval": 0.1},
    }
    for key, value in extra.items():
        table, name = key.split(".")
        case.setdefault(table, {})[name] = value
    return case


def simulation(case, out, **kw):
    c = load_case(case)
    ds = open_flow(c)
    c = resolve_domain(c, _les_box_m(ds, c) if c.flow.source == "les" else None)
    return Simulation(c, ds, Path(out), progress=False, **kw)


def assert_same_run(a: Path, b: Path):
    sa = json.loads((a / "summary.json").read_text())
    sb = json.loads((b / "summary.json").read_text())
    assert sa["status"] == sb["status"] == "completed"
    assert sa["steps"] == sb["steps"]
    assert sa["jumps"] == sb["jumps"]  # exact: same jumps collected in the same order
    assert sa["collisions"] == sb["collisions"]
    assert sa["steps_above_flow_top"] == sb["steps_above_flow_top"]
    for name in ("jumps.parquet", "tracks.parquet"):
        fa, fb = pd.read_parquet(a / name), pd.read_parquet(b / name)
        assert len(fa) > 0
        pd.testing.assert_frame_equal(fa, fb, check_exact=True)
    assert (a / "particles.pvd").read_text() == (b / "particles.pvd").read_text()
    pieces = sorted(p.name for p in (a / "vtk").iterdir())
    assert pieces == sorted(p.name for p in (b / "vtk").iterdir())
    assert not (b / CHECKPOINT).exists() and not (b / PARTS).exists()


def test_interrupted_and_resumed_run_is_the_uninterrupted_run(tmp_path):
    case = tiny_case()
    ref = run(case, out=tmp_path / "ref", progress=False)
    assert ref.summary["jumps"]["recorded"] > 0

    with pytest.raises(RunInterrupted) as stop:
        simulation(case, tmp_path / "b", stop_after_steps=610).run()
    s = stop.value.result.summary
    assert s["status"] == "interrupted"
    assert 610 <= s["steps"] < ref.summary["steps"]
    assert s["checkpoint"]["step"] == s["steps"]
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["status"] == "interrupted"
    # outputs flushed: the partial tables are readable and hold the start of the full ones
    part = pd.read_parquet(tmp_path / "b" / "tracks.parquet")
    full = ref.tracks
    pd.testing.assert_frame_equal(part, full.iloc[: len(part)].reset_index(drop=True), check_exact=True)
    assert len(part) < len(full)

    res = run(case, out=tmp_path / "b", progress=False, resume=True)
    assert res.summary["resumed_from_step"] == s["steps"]
    assert_same_run(tmp_path / "ref", tmp_path / "b")
    # the run does depend on its state: a different seed is a different run
    other = run(case, out=tmp_path / "c", progress=False, **{"run.seed": 4})
    assert other.summary["jumps"] != ref.summary["jumps"]


def test_resume_after_kill_discards_output_written_after_the_checkpoint(tmp_path):
    """A kill -9 leaves the last periodic checkpoint plus parts written after it (one of
    them unfinished): resuming drops those and still gives the uninterrupted run."""
    case = tiny_case(**{"output.checkpoint_steps": 300})
    run(case, out=tmp_path / "ref", progress=False)

    sim = simulation(case, tmp_path / "k", stop_after_steps=1000)
    with pytest.raises(RunInterrupted):
        sim.run()
    out = tmp_path / "k"
    # roll the checkpoint back to an earlier periodic one, as a kill would have left it:
    # take a fresh run that checkpoints at 300 steps and stops at once after that
    with pytest.raises(RunInterrupted):
        simulation(case, tmp_path / "early", stop_after_steps=300).run()
    (out / CHECKPOINT).unlink()  # what the checkpoint at step 300 wrote (variance sums inside)
    (tmp_path / "early" / CHECKPOINT).replace(out / CHECKPOINT)
    early_parts = {p.name for p in (tmp_path / "early" / PARTS).iterdir()}
    later = [p for p in (out / PARTS).iterdir() if p.name not in early_parts]
    assert later, "the longer run should have written parts after the 300-step checkpoint"
    (out / PARTS / "jumps-00099.parquet").write_bytes(b"PAR1 half-written")
    (out / "vtk" / "particles_00999.vtu").write_text("stale frame")
    res = run(case, out=out, progress=False, resume=True)
    assert res.summary["resumed_from_step"] == 300
    assert_same_run(tmp_path / "ref", out)


def test_resume_refuses_another_case_and_a_missing_checkpoint(tmp_path):
    case = tiny_case(duration=0.3)
    with pytest.raises(RunInterrupted):
        simulation(case, tmp_path / "a", stop_after_steps=200).run()
    with pytest.raises(SimulationError, match=r"run\.seed \(checkpoint 3, now 5\)"):
        run(case, out=tmp_path / "a", progress=False, resume=True, **{"run.seed": 5})
    # threads and checkpoint settings may change
    run(case, out=tmp_path / "a", progress=False, resume=True, **{"run.threads": 2, "output.checkpoint_every": 5.0})
    with pytest.raises(SimulationError, match="no checkpoint.*completed"):
        run(case, out=tmp_path / "a", progress=False, resume=True)


def test_sigint_to_the_cli_checkpoints_and_resume_completes(tmp_path):
    case_dict = tiny_case(n=150, duration=3.0, **{"output.checkpoint_steps": 200, "output.vtk": False})
    case_file = tmp_path / "case.toml"
    lines = []
    for table, keys in case_dict.items():
        lines.append(f"[{table}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in keys.items()]
    case_file.write_text("\n".join(lines) + "\n")
    out = tmp_path / "sig"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "saltation.cli", "run", str(case_file), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # a cold Numba cache compiles the run path first: minutes on a loaded 2-core machine
    # (more than 400 s seen with the test suite and benchmarks running beside it)
    deadline = time.time() + 1500
    while not (out / CHECKPOINT).exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGINT, err
    assert "--resume" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) <= 3, err  # a clean stop, no traceback
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["steps"] < 5000

    done = subprocess.run(cmd + ["--resume"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    run(case_file, out=tmp_path / "ref", progress=False)
    sa = json.loads((tmp_path / "ref" / "summary.json").read_text())
    sb = json.loads((out / "summary.json").read_text())
    assert sa["jumps"] == sb["jumps"] and sb["status"] == "completed"
    for name in ("jumps.parquet", "tracks.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "ref" / name), pd.read_parquet(out / name), check_exact=True)


@pytest.mark.parametrize("model, bed", [("soft", "virtual"), ("hard", "virtual"), ("soft", "packed")])
def test_resume_with_grain_contacts(tmp_path, model, bed):
    """Dense grains in contact: the contact list, tangential (shear) history, the bed
    springs of sub-stepped grains and the collision counters go into the checkpoint, so
    the resumed run is still the uninterrupted one (a checkpoint at step 200 missed the
    bed-contact slots before they were saved)."""
    case = tiny_case(n=None, duration=0.4, **{
        "collisions.model": model, "run.concentration": 0.0394, "run.domain": [0.012, 0.006, 0.028],
        "bed.model": bed, "output.vtk": False, "output.checkpoint_steps": 150})
    del case["run"]["n_particles"]
    ref = run(case, out=tmp_path / "ref", progress=False)
    assert ref.summary["collisions"]["particle_particle"] > 0
    with pytest.raises(RunInterrupted):
        simulation(case, tmp_path / "b", stop_after_steps=200).run()
    res = run(case, out=tmp_path / "b", progress=False, resume=True)
    assert res.summary["collisions"] == ref.summary["collisions"]
    assert res.summary["jumps"] == ref.summary["jumps"]
    for name in ("jumps.parquet", "tracks.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "ref" / name), pd.read_parquet(tmp_path / "b" / name),
                                      check_exact=True)


@pytest.mark.parametrize("bed", ["virtual", "packed"])
def test_composite_run_interrupted_and_resumed_is_the_uninterrupted_run(tmp_path, bed):
    """Bonded-sphere grains go through the same run loop (engine/composites.py is a grain
    family of engine/simulation.py): their state, work arrays, contact lists with their
    tangential springs and the packed bed's slots go into the checkpoint, and the resumed
    run is the uninterrupted one, bit for bit."""
    from saltation.engine.composites import ClusterSimulation

    # seed 5 over the LES, as the regression set (with seed 3 this packed, dense mixture
    # went non-finite while its bed contacts were hard — step 637 with the code of f9475d8:
    # the rebound and push-out moved grains into neighbours they were in contact with;
    # with soft bed contacts in the contact phase, issue 20, it runs 917 steps to the end)
    case = tiny_case(n=None, duration=0.25, **{
        "particle.shape": "mixture", "collisions.model": "soft", "run.concentration": 0.0207,
        "run.domain": [0.012, 0.006, 0.028], "bed.model": bed, "output.vtk": False, "flow.source": "les",
        "run.seed": 5})
    del case["run"]["n_particles"]
    ref = run(case, out=tmp_path / "ref", progress=False)
    assert ref.summary["collisions"]["particle_particle"] > 0 and ref.summary["jumps"]["recorded"] > 0
    c = load_case(case)
    ds = open_flow(c)
    c = resolve_domain(c, _les_box_m(ds, c))
    with pytest.raises(RunInterrupted) as stop:
        ClusterSimulation(c, ds, tmp_path / "b", progress=False, stop_after_steps=230).run()
    assert stop.value.result.summary["status"] == "interrupted"
    res = run(case, out=tmp_path / "b", progress=False, resume=True)
    assert res.summary["resumed_from_step"] == stop.value.result.summary["steps"] < ref.summary["steps"]
    assert res.summary["collisions"] == ref.summary["collisions"]
    assert res.summary["jumps"] == ref.summary["jumps"]
    for name in ("jumps.parquet", "tracks.parquet", "particles.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "ref" / name), pd.read_parquet(tmp_path / "b" / name),
                                      check_exact=True)


def test_resting_composites_interrupted_and_resumed_are_the_uninterrupted_run(tmp_path):
    """Bonded-sphere grains at rest on the packed bed (soft bed contacts in the contact
    phase, their springs and last-contact steps in the checkpoint) resume bit for bit."""
    from saltation.engine.composites import ClusterSimulation

    d = 0.69e-3
    case = tiny_case(n=10, duration=0.1, **{
        "particle.shape": "mixture", "collisions.model": "soft", "bed.model": "packed", "run.start": "rest",
        "run.domain": [6 * d, 7 * d, 50 * d], "run.dt_particle": 0.01, "flow.source": "les", "flow.tau_ratio": 1.0,
        "output.vtk": False})
    ref = run(case, out=tmp_path / "ref", progress=False)
    assert ref.summary["collisions"]["bed"] > 0
    c = load_case(case)
    ds = open_flow(c)
    c = resolve_domain(c, _les_box_m(ds, c))
    with pytest.raises(RunInterrupted) as stop:
        ClusterSimulation(c, ds, tmp_path / "b", progress=False, stop_after_steps=200).run()
    res = run(case, out=tmp_path / "b", progress=False, resume=True)
    assert res.summary["resumed_from_step"] == stop.value.result.summary["steps"] < ref.summary["steps"]
    assert res.summary["collisions"] == ref.summary["collisions"]
    for name in ("jumps.parquet", "tracks.parquet", "particles.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "ref" / name), pd.read_parquet(tmp_path / "b" / name),
                                      check_exact=True)
