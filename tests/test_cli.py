"""End-to-end: the console script on tiny cases, outputs read back."""
import json
import subprocess
import sys

import pandas as pd
import pytest

from saltation.cli import main


def test_run_writes_the_run_directory(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", "cases/loglaw.toml", "--out", str(out), "--quiet",
               "--set", "run.n_particles=20", "--set", "run.duration=0.3", "--set", "output.vtk=true"])
    assert rc == 0
    for name in ("config.toml", "summary.json", "jumps.parquet", "tracks.parquet", "particles.pvd"):
        assert (out / name).exists(), name
    s = json.loads((out / "summary.json").read_text())
    for key in ("n_particles", "concentration", "tau_star", "tau_ratio", "jumps", "collisions", "timing", "particle_steps_per_s"):
        assert key in s
    assert s["n_particles"] == 20
    assert set(s["jumps"]) >= {"count", "H_mean", "H_std", "L_mean", "L_std", "U_mean", "U_std"}
    assert set(s["timing"]) >= {"wall_s", "free_flight_s", "bed_s", "particle_collisions_s"}
    tr = pd.read_parquet(out / "tracks.parquet")
    assert list(tr.columns) == ["particle", "t", "x", "y", "z", "u", "v", "w", "spin_x", "spin_y", "spin_z"]
    assert tr["particle"].nunique() == 20
    # the config written back reloads and names the values used
    from saltation.case.schema import load_case

    c = load_case(out / "config.toml")
    assert c.run.n_particles == 20 and c.run.duration == pytest.approx(0.3)
    assert "jumps" in capsys.readouterr().out


def test_bad_key_is_a_clear_error(capsys):
    rc = main(["run", "cases/loglaw.toml", "--set", "bed.restitusion=0.5"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "bed.restitusion" in err and "restitution" in err


def test_console_script_is_installed():
    out = subprocess.run([sys.executable, "-m", "saltation.cli", "flow", "info", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "dataset" in out.stdout
