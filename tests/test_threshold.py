"""Incipient motion and bed-load transport (saltation/studies/threshold.py; issue 20)."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from saltation.cli import main
from saltation.studies.threshold import (
    crossing,
    d_star,
    displacement_rate,
    formula_q_star,
    motion_statistics,
    shields_soulsby,
    tail_shape,
)


def test_shields_curve_and_formulas():
    ds = d_star(0.69e-3, 1.65, 1e-6)
    assert abs(ds - 17.46) < 0.05
    # Soulsby & Whitehouse (1997) at D* = 17.5: 0.30/22 + 0.055 (1 − e^−0.35) = 0.0298
    assert abs(shields_soulsby(ds) - 0.0298) < 5e-4
    assert shields_soulsby(2.0) > shields_soulsby(15.0) < shields_soulsby(60.0)  # the dip of the curve
    assert formula_q_star(0.04, 8.0, 0.047) == 0.0
    assert abs(formula_q_star(0.147, 8.0, 0.047) - 8.0 * 0.1**1.5) < 1e-12


def test_crossing_interpolates_in_log_log():
    tau = [0.01, 0.02, 0.04]
    q = [1e-6, 1e-5, 1e-3]  # 1e-4 between the last two: halfway in log q
    tc, why = crossing(tau, q)
    assert why is None and abs(tc - math.sqrt(0.02 * 0.04)) < 1e-12
    assert crossing(tau, [1e-3, 1e-2, 1e-1])[0] is None
    assert "lower the series" in crossing(tau, [1e-3, 1e-2, 1e-1])[1]
    assert "raise the series" in crossing(tau, [0.0, 1e-6, 1e-5])[1]


def test_motion_statistics_of_a_stop_and_go_track():
    # one grain: rest 0–2, move at 1 u* for 3, rest 5–9 (4 long), move 9–10, rest to 12;
    # a resting grain's reported velocity is not zero (it is not used)
    t = np.arange(0.0, 12.5, 0.5)
    u = np.where(((t > 2) & (t <= 5)) | ((t > 9) & (t <= 10)), 1.0, 0.0)
    x = np.concatenate([[0.0], np.cumsum(u[1:] * 0.5)])
    tr = pd.DataFrame({"particle": 0, "t": t, "x": x, "y": 0.3, "z": 1.0, "u": u + 0.05, "v": 0.0, "w": 0.0})
    ms = motion_statistics(tr)
    assert ms["fraction_moving"] == pytest.approx(8 / 24)
    assert list(ms["rest_times"]) == [4.0]  # the first and last rests are cut by the record
    np.testing.assert_allclose(ms["step_lengths"], [3.0, 1.0])
    assert displacement_rate(tr, 2.0) == pytest.approx(math.pi / 6 * 4.0 / (2.0 * 12.0))


def test_tail_shape_tells_exponential_from_power_law():
    rng = np.random.default_rng(1)
    expo = tail_shape(rng.exponential(2.0, 4000))
    pareto = tail_shape(rng.pareto(1.5, 4000) + 1.0)
    assert abs(expo["cv"] - 1.0) < 0.1
    assert pareto["hill_tail_exponent"] < 2.0 < expo["hill_tail_exponent"]


SMALL_CASE = """
[particle]
diameter = 0.69e-3
density = 2650.0
[fluid]
density = 1000.0
viscosity = 1.0e-6
[flow]
source = "les"
tau_ratio = 1.0
tau_c = 0.032
[bed]
model = "packed"
[collisions]
model = "soft"
[run]
start = "rest"
n_particles = 10
domain = [0.0042, 0.0048, 0.0345]
duration = 0.1
dt_particle = 0.01
"""


def test_threshold_command_on_a_small_bed(tmp_path, capsys):
    """The user path: a case file, two Shields numbers, threshold.json read back."""
    case = tmp_path / "rest.toml"
    case.write_text(SMALL_CASE)
    rc = main(["threshold", str(case), "--out", str(tmp_path / "th"), "--tau-stars", "0.002,0.06",
               "--width", "6,7", "--duration", "15", "--quiet"])
    assert rc == 0
    res = json.loads((tmp_path / "th" / "threshold.json").read_text())
    rows = res["table"]
    assert [r["tau_star"] for r in rows] == [0.002, 0.06]
    # grains barely rock at a tenth of the Shields value and are carried at twice it
    assert rows[0]["q_star"] < 1e-4 < rows[1]["q_star"]
    assert rows[0]["fraction_moving"] < rows[1]["fraction_moving"]
    assert 0.002 < res["tau_star_c"] < 0.06
    assert (tmp_path / "th" / "threshold.png").stat().st_size > 0
    assert "tau*_c (q* = 1e-4)" in capsys.readouterr().out
    # rerun: the finished runs are reused, the same answer
    assert main(["threshold", str(case), "--out", str(tmp_path / "th"), "--tau-stars", "0.002,0.06",
                 "--width", "6,7", "--duration", "15", "--quiet"]) == 0
    assert json.loads((tmp_path / "th" / "threshold.json").read_text())["tau_star_c"] == res["tau_star_c"]


def test_threshold_command_for_bonded_sphere_grains(tmp_path):
    """The natural mixture rests on the bed too: placed, settled (the first
    SETTLE_COMPOSITES d/u* not measured), re-entrained at twice the Shields value."""
    case = tmp_path / "rest.toml"
    case.write_text(SMALL_CASE)
    assert main(["threshold", str(case), "--out", str(tmp_path / "th"), "--tau-stars", "0.002,0.06",
                 "--width", "6,7", "--duration", "15", "--set", "particle.shape=mixture", "--quiet"]) == 0
    res = json.loads((tmp_path / "th" / "threshold.json").read_text())
    assert res["shape"] == "mixture" and res["settle_d_u"] == 10.0
    rows = res["table"]
    assert rows[0]["q_star"] < 1e-4 < rows[1]["q_star"]
    assert rows[0]["fraction_moving"] < 0.05 < rows[1]["fraction_moving"]
    tracks = pd.read_parquet(next((tmp_path / "th").glob("tau_0.00200/tracks.parquet")))
    assert tracks["t"].max() >= 24.9  # settle + measured window


def test_displacement_rate_weighs_each_grain_by_its_volume():
    tracks = pd.DataFrame({"particle": [0, 0, 1, 1], "t": [0.0, 2.0, 0.0, 2.0], "x": [0.0, 1.0, 0.0, 3.0]})
    assert displacement_rate(tracks, 4.0) == pytest.approx(math.pi / 6 * 4.0 / 8.0)
    vol = pd.Series([0.5, 0.25], index=[0, 1])
    assert displacement_rate(tracks, 4.0, vol) == pytest.approx((0.5 * 1.0 + 0.25 * 3.0) / 8.0)


def test_threshold_command_rejects_bad_input(tmp_path, capsys):
    assert main(["threshold", "cases/threshold.toml", "--tau-stars", "0.01,x", "--out", str(tmp_path / "a")]) == 2
    assert "--tau-stars" in capsys.readouterr().err
    assert main(["threshold", "cases/threshold.toml", "--width", "6", "--out", str(tmp_path / "b")]) == 2
    assert "--width" in capsys.readouterr().err
