"""Published saltation regressions (saltation/analysis/regressions.py, docs/references.md).

Expected numbers were computed by hand (awk, independently of the module) from the
printed equations at the first Niño & García stage: d = 0.69 mm quartz in water,
R = 1.65, g = 9.81, ν = 1e-6, τ*c = 0.032, τ*/τ*c = 1.79.
"""
import math
import re

import numpy as np
import pandas as pd
import pytest

from saltation.analysis import regressions as reg

D, R, G, NU, TC = 0.69e-3, 1.65, 9.81, 1.0e-6, 0.032
TS = 1.79 * TC
US = math.sqrt(TS * R * G * D)  # u* [m/s]
USC = math.sqrt(TC * R * G * D)  # u*c [m/s]


def test_condition_matches_the_spec():
    assert reg.dimensionless_grain_size(D, R, G, NU) == pytest.approx(17.454205, rel=1e-6)
    # SPEC: u* ≈ 0.025–0.031 m/s over the four stages
    u = [reg.shear_velocity(s * TC, D, R, G) for s in reg.NINO_GARCIA_STAGES]
    assert u[0] == pytest.approx(0.025293, rel=1e-4) and u[-1] == pytest.approx(0.030891, rel=1e-4)


# --- each formula against a value computed by hand from the printed equation ------------

def test_van_rijn_hand_values():
    out = reg.van_rijn_1984(D, R, G, NU, TS, TC)
    assert out["H"] == pytest.approx(1.973626, rel=1e-5)   # 0.3 D*^0.7 T^0.5
    assert out["L"] == pytest.approx(13.493533, rel=1e-5)  # 3 D*^0.6 T^0.9
    assert out["U"] == pytest.approx(5.440841, rel=1e-5)   # 1.5 T^0.6 √(Rgd) / u*


def test_fernandez_luque_van_beek_hand_value():
    out = reg.fernandez_luque_van_beek_1976(TS, TC)
    assert out["U"] == pytest.approx(5.483148, rel=1e-5)  # 11.5 (u* − 0.7 u*c) / u*
    assert math.isnan(out["H"]) and math.isnan(out["L"])


def test_sekine_kikkawa_hand_value_with_given_settling_velocity():
    out = reg.sekine_kikkawa_1992(D, R, G, NU, TS, TC, ws=0.09)
    assert out["U"] == pytest.approx(4.721011, rel=1e-5)  # 8 √(gdR) (u*/ws) (1 − u*c/u*)^½ / u*


def test_bridge_dominic_hand_value_and_needs_friction():
    # tan μd = 0.6 is a test input only: the module ships no value for it
    out = reg.bridge_dominic_1984(D, R, G, NU, TS, TC, tan_mu_d=0.6, ws=0.09)
    assert out["U"] == pytest.approx(0.931355, rel=1e-5)  # √tanμd ws/u*c (u* − u*c) / u*
    assert math.isnan(reg.bridge_dominic_1984(D, R, G, NU, TS, TC)["U"])


def test_wiberg_rubin_hand_value_uses_centimetres():
    out = reg.wiberg_rubin_1989(D, TS, TC)
    assert out["H"] == pytest.approx(0.948970, rel=1e-5)  # 0.68 T*/(1 + a2 T*), a2(d = 0.069 cm)
    # the metre reading of a2 (one code's variant) gives a clearly different number
    ln_m = math.log(D)
    a2_m = 0.0204 * ln_m**2 + 0.0220 * ln_m + 0.0709
    assert abs(out["H"] - 0.68 * 1.79 / (1 + a2_m * 1.79)) > 0.1


def test_lamb_hand_values():
    out = reg.lamb_2008(R, G, D, TS, TC)
    assert out["H"] == pytest.approx(1.279900, rel=1e-5)  # 1.44 (τ*/τ*c − 1)^0.5
    assert out["U"] == pytest.approx(5.712080, rel=1e-5)  # 1.56 √(Rgd) (τ*/τ*c − 1)^0.56 / u*
    assert math.isnan(out["L"])


# --- unit consistency: dimensional formulas divided by u* ---------------------------------

@pytest.mark.parametrize("stage", reg.NINO_GARCIA_STAGES)
def test_velocities_in_ustar_units_equal_dimensional_formulas(stage):
    ts = stage * TC
    us = math.sqrt(ts * R * G * D)
    T = stage - 1.0
    ws = 0.085
    dimensional = {  # m/s, straight from the printed equations
        "van Rijn 1984": 1.5 * T**0.6 * math.sqrt(R * G * D),
        "Fernandez Luque & van Beek 1976": 11.5 * (us - 0.7 * USC),
        "Sekine & Kikkawa 1992": math.sqrt(G * D * R) * 8 * (us / ws) * math.sqrt(1 - USC / us),
        "Bridge & Dominic 1984": math.sqrt(0.5) * ws / USC * (us - USC),
        "Lamb et al. 2008": 1.56 * math.sqrt(R * G * D) * T**0.56,
    }
    table = reg.evaluate_all(D, R, G, NU, ts, TC, ws=ws, tan_mu_d=0.5)
    for name, u in dimensional.items():
        assert table.loc[name, "U_over_ustar"] * us == pytest.approx(u, rel=1e-9), name


def test_heights_scale_with_d_in_metres():
    # H/d from the module times d equals the dimensional height of the printed formula
    T = 0.79
    d_star = D * (R * G / NU**2) ** (1 / 3)
    assert reg.van_rijn_1984(D, R, G, NU, TS, TC)["H"] * D == pytest.approx(0.3 * D * d_star**0.7 * T**0.5)


def test_settling_laws_agree_roughly():
    wd = reg.settling_velocity_dietrich(D, R, G, NU)
    wf = reg.settling_velocity_ferguson_church(D, R, G, NU)
    assert 0.05 < wd < 0.15 and wd == pytest.approx(wf, rel=0.1)
    # spheres settle faster than natural grains (Dietrich shape/roundness factors)
    assert reg.settling_velocity_dietrich(D, R, G, NU, csf=1.0, ps=6.0) > wd


# --- behaviour with stage ----------------------------------------------------------------

def test_every_quantity_grows_with_stage():
    stages = np.linspace(1.05, 4.0, 30)
    tables = [reg.evaluate_all(D, R, G, NU, s * TC, TC, tan_mu_d=0.5) for s in stages]
    for name in reg.REGRESSIONS:
        for col in ("H_over_d", "L_over_d", "U_over_ustar"):
            v = np.array([t.loc[name, col] for t in tables])
            if np.all(np.isnan(v)):
                continue
            assert not np.any(np.isnan(v)), (name, col)
            assert np.all(np.diff(v) > 0), (name, col)


def test_below_threshold_is_nan_and_threshold_is_zero_where_excess_stage_is_used():
    low = reg.evaluate_all(D, R, G, NU, 0.9 * TC, TC, tan_mu_d=0.5)
    assert low[["H_over_d", "L_over_d", "U_over_ustar"]].isna().all().all()
    at = reg.evaluate_all(D, R, G, NU, TC, TC, tan_mu_d=0.5)
    assert at.loc["van Rijn 1984", "H_over_d"] == 0.0 and at.loc["Lamb et al. 2008", "U_over_ustar"] == 0.0
    assert at.loc["Wiberg & Rubin 1989", "H_over_d"] > 0  # written in τ*/τ*c, not the excess


def test_bad_input_raises():
    with pytest.raises(ValueError):
        reg.van_rijn_1984(D, R, G, NU, TS, 0.0)


# --- registry, table and envelope --------------------------------------------------------

def test_registry_metadata_is_complete():
    assert len(reg.REGRESSIONS) >= 5
    for name, r in reg.REGRESSIONS.items():
        assert r.citation and r.validity and r.verified_in and r.stage_variable, name
        assert set(r.quantities) <= {"H", "L", "U"} and r.quantities, name
        assert set(r.spec_only) <= set(r.quantities), name
        assert r.status in ("quoted", "spec-only"), name
        doc = r.func.__doc__
        assert doc and "Validity:" in doc and re.search(r"\((19|20)\d\d\)", doc), name  # range, year
        # the regression gives exactly the quantities it declares
        out = r(D, R, G, NU, TS, TC, tan_mu_d=0.5)
        assert {q for q in "HLU" if not math.isnan(out[q])} == set(r.quantities), name


def test_evaluate_all_shape_and_notes():
    t = reg.evaluate_all(D, R, G, NU, TS, TC)
    assert isinstance(t, pd.DataFrame)
    assert list(t.index) == list(reg.REGRESSIONS)
    assert {"H_over_d", "L_over_d", "U_over_ustar", "status", "notes"} <= set(t.columns)
    assert "tan_mu_d" in t.loc["Bridge & Dominic 1984", "notes"]
    assert "SPEC" in t.loc["van Rijn 1984", "notes"]
    blank = reg.evaluate_all(D, R, G, NU, TS, TC, include_spec_only=False)
    assert math.isnan(blank.loc["van Rijn 1984", "L_over_d"])
    assert blank.loc["van Rijn 1984", "H_over_d"] == t.loc["van Rijn 1984", "H_over_d"]


def test_validity_note_when_outside_quoted_range():
    t = reg.evaluate_all(D, R, G, NU, 0.15, TC)
    assert "0.1" in t.loc["Fernandez Luque & van Beek 1976", "notes"]
    t = reg.evaluate_all(D, R, G, NU, TS, TC)
    assert t.loc["Fernandez Luque & van Beek 1976", "notes"] == ""


@pytest.mark.parametrize("stage", reg.NINO_GARCIA_STAGES)
def test_envelope_is_min_and_max_over_regressions(stage):
    ts = stage * TC
    t = reg.evaluate_all(D, R, G, NU, ts, TC, tan_mu_d=0.5)
    env = reg.envelope(D, R, G, NU, ts, TC, tan_mu_d=0.5)
    for q, col in (("H", "H_over_d"), ("L", "L_over_d"), ("U", "U_over_ustar")):
        vals = t[col].dropna()
        assert env.loc[q, "min"] == vals.min() and env.loc[q, "max"] == vals.max()
        assert env.loc[q, "n"] == len(vals)
        assert t.loc[env.loc[q, "min_by"], col] == vals.min()
        assert t.loc[env.loc[q, "max_by"], col] == vals.max()
    assert env.loc["U", "min"] < env.loc["U", "max"]  # several velocity regressions, not one


def test_stage_table_covers_the_four_stages():
    t = reg.stage_table()
    assert sorted(t["tau_ratio"].unique()) == list(reg.NINO_GARCIA_STAGES)
    assert len(t) == 4 * len(reg.REGRESSIONS)
    row = t[(t["tau_ratio"] == 1.79) & (t["regression"] == "van Rijn 1984")].iloc[0]
    assert row["H_over_d"] == pytest.approx(1.973626, rel=1e-5)
    md = reg.format_stage_table(t)
    assert md.count("\n") == 1 + len(reg.REGRESSIONS) and "U/u* @ 2.67" in md
