"""Sweeps (issue 4 item 5): grid expansion, clear errors, runs on a Dask LocalCluster on
loopback, finished cases skipped on restart, interrupted cases resumed, one results table."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from saltation.case.schema import load_case, resolve_domain
from saltation.cli import main
from saltation.engine.simulation import CHECKPOINT, RunInterrupted, Simulation, open_flow
from saltation.studies.sweep import SweepError, case_name, load_sweep, plan_workers, run_sweep, sweep_key

ROOT = Path(__file__).resolve().parents[1]

TINY = """
[particle]
diameter = 0.69e-3
[flow]
source = "loglaw"
tau_ratio = 1.79
[run]
n_particles = 8
duration = 2.5          # s: 92 d/u*, 4580 steps: 10-30 jumps per grain
dt_particle = 0.02
[output]
vtk = false
[sweep]
tau_ratio = [1.79, 2.43]
"run.seed" = [0, 1]
"""


def write(tmp_path, text, name="tiny_sweep.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_grid_expands_to_named_cases(tmp_path):
    sw = load_sweep(write(tmp_path, TINY + 'concentration = [0.0004, 0.0394]\n'))
    assert list(sw.grid) == ["flow.tau_ratio", "run.seed", "run.concentration"]
    assert len(sw.cases) == 8
    names = [c.name for c in sw.cases]
    assert names[0] == "t1.79_s0_c0.04" and names[-1] == "t2.43_s1_c3.94"
    assert sw.cases[1].values == {"flow.tau_ratio": 1.79, "run.seed": 0, "run.concentration": 0.0394}
    assert case_name({"run.concentration": 0.0012, "flow.tau_ratio": 2.67, "run.seed": 3}) == "c0.12_t2.67_s3"
    # concentration replaces the base's n_particles in each case
    c = load_case(sw.cases[1].tables, sw.cases[1].values)
    assert c.run.concentration == 0.0394 and c.run.n_particles is None


def test_base_file_and_dotted_keys(tmp_path):
    text = f'base = "{ROOT / "cases" / "loglaw.toml"}"\n[run]\nduration = 0.2\n[sweep]\nrun.seed = [4, 5]\n'
    sw = load_sweep(write(tmp_path, text))
    assert [c.name for c in sw.cases] == ["s4", "s5"]
    assert sw.base["run"]["duration"] == 0.2 and sw.base["run"]["n_particles"] == 300
    assert sw.base["flow"]["source"] == "loglaw"


def test_bad_sweep_keys_name_the_key_and_what_is_allowed(tmp_path):
    with pytest.raises(SweepError, match=r"unknown sweep key 'concentraton' \(did you mean 'concentration'\?\)\. Allowed: .*run\.seed"):
        sweep_key("concentraton")
    with pytest.raises(SweepError, match=r"'restitution' is ambiguous: write one of bed\.restitution, collisions\.restitution"):
        sweep_key("restitution")
    with pytest.raises(SweepError, match="must be a non-empty list"):
        load_sweep(write(tmp_path, TINY.replace("tau_ratio = [1.79, 2.43]", "tau_ratio = 1.79")))
    with pytest.raises(SweepError, match=r"sweep case t1.79_s0_c6 .*: run\.concentration = 0\.06 is out of range"):
        load_sweep(write(tmp_path, TINY + "concentration = [0.06]\n"))
    with pytest.raises(SweepError, match=r"needs a \[sweep\] table"):
        load_sweep(write(tmp_path, TINY.split("[sweep]")[0]))
    assert main(["sweep", str(write(tmp_path, TINY + "nonsense = [1]\n"))]) == 2


def test_worker_plan_fills_the_cores():
    assert plan_workers(24, None, None, cores=2) == (2, 1)
    assert plan_workers(1, None, None, cores=2) == (1, 2)
    assert plan_workers(24, None, 2, cores=2) == (1, 2)
    assert plan_workers(24, 4, None, cores=16) == (4, 4)


def test_sweep_runs_skips_finished_cases_and_resumes_interrupted_ones(tmp_path):
    path = write(tmp_path, TINY)
    out = tmp_path / "out"
    log: list[str] = []
    df = run_sweep(path, out=out, processes=False, echo=log.append)
    assert list(df["case"]) == ["t1.79_s0", "t1.79_s1", "t2.43_s0", "t2.43_s1"]
    assert (df["status"] == "completed").all()
    assert any("[4/4]" in line for line in log)
    table = pd.read_parquet(out / "results.parquet")
    pd.testing.assert_frame_equal(table, df)
    for _, row in table.iterrows():
        s = json.loads((out / "cases" / row["case"] / "summary.json").read_text())
        assert row["tau_ratio"] == row["flow.tau_ratio"] == s["tau_ratio"]
        assert row["run.seed"] == int(row["case"][-1])
        assert row["n_particles"] == 8 and row["jumps"] == s["jumps"]["count"] > 0
        assert row["H_mean"] == s["jumps"]["H_mean"]
        assert row["bed_impacts_per_particle_per_s"] == pytest.approx(s["collisions"]["bed"] / 8 / s["simulated_time_s"])
        assert row["collisions_pp_per_particle"] == s["collisions"]["per_particle"]
    # the stronger flow throws the grains further
    assert table.groupby("flow.tau_ratio")["L_mean"].mean().is_monotonic_increasing

    # restart: three cases finished, one interrupted mid-run (as a killed sweep leaves it)
    victim = out / "cases" / "t2.43_s1"
    stamps = {c: (out / "cases" / c / "summary.json").stat().st_mtime_ns for c in df["case"] if c != "t2.43_s1"}
    sw = load_sweep(path)
    c = next(x for x in sw.cases if x.name == "t2.43_s1")
    case = load_case(c.tables, {**c.values, "run.name": c.name, "run.threads": 1})
    ds = open_flow(case)
    with pytest.raises(RunInterrupted):
        Simulation(resolve_domain(case), ds, victim, progress=False, stop_after_steps=2000).run()
    assert (victim / CHECKPOINT).exists()
    log.clear()
    df2 = run_sweep(path, out=out, processes=False, echo=log.append)
    assert "3 already finished, 1 to run" in log[0]
    assert {c: (out / "cases" / c / "summary.json").stat().st_mtime_ns for c in stamps} == stamps
    s = json.loads((victim / "summary.json").read_text())
    assert s["status"] == "completed" and s["resumed_from_step"] == 2000
    # resumed = uninterrupted: the same numbers as the first sweep's run of this case
    cols = ["H_mean", "H_std", "L_mean", "L_std", "U_mean", "U_std", "jumps", "collisions_bed"]
    pd.testing.assert_frame_equal(df2[cols], df[cols])

    log.clear()
    run_sweep(path, out=out, processes=False, echo=log.append)
    assert "4 already finished, 0 to run" in log[0]

    # the sweep file changed under a finished case: that case is not finished any more
    path.write_text(TINY.replace("n_particles = 8", "n_particles = 9").replace("tau_ratio = [1.79, 2.43]", "tau_ratio = [1.79]"))
    log.clear()
    df3 = run_sweep(path, out=out, processes=False, echo=log.append)
    assert "0 already finished, 2 to run" in log[0]
    assert "t1.79_s0: completed, but with another case definition: running it again" in log
    assert (df3["n_particles"] == 9).all()


def test_cli_sweep_on_a_two_process_local_cluster(tmp_path, capsys):
    path = write(tmp_path, TINY.replace('"run.seed" = [0, 1]', '"run.seed" = [7]'))
    out = tmp_path / "cli"
    assert main(["sweep", str(path), "--out", str(out), "--workers", "2", "--threads-per-worker", "1"]) == 0
    text = capsys.readouterr().out
    assert "LocalCluster on 127.0.0.1: 2 worker(s) x 1 Numba thread(s)" in text
    assert "[2/2]" in text and "t2.43_s7" in text
    df = pd.read_parquet(out / "results.parquet")
    assert len(df) == 2 and (df["status"] == "completed").all() and (df["threads"] == 1).all()


def test_sweep_on_an_existing_scheduler(tmp_path):
    from dask.distributed import LocalCluster

    path = write(tmp_path, TINY.replace('tau_ratio = [1.79, 2.43]', 'tau_ratio = [2.0]').replace('"run.seed" = [0, 1]', '"run.seed" = [2]'))
    log: list[str] = []
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        df = run_sweep(path, out=tmp_path / "remote", scheduler=cluster.scheduler_address, echo=log.append)
    assert any(line.startswith(f"scheduler {cluster.scheduler_address}: 1 worker(s), 1 case(s) at a time") for line in log)
    assert list(df["case"]) == ["t2_s2"] and df["status"].iloc[0] == "completed"
