"""Physical check of a flow dataset: mean and r.m.s. profiles against the law of the wall.

Averages over x, z and all snapshots. Law of the wall (issue 2 / Pope 2000):
viscous sublayer u⁺ = y⁺ (y⁺ ≲ 5), log law u⁺ = 2.44 ln y⁺ + 5.2 (y⁺ ≳ 30).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from .analytic import reichardt

LOG_KAPPA_INV = 2.44
LOG_B = 5.2
CHECK_POINTS = (5.0, 10.0, 30.0, 100.0)


def log_law_check(y_plus):
    return LOG_KAPPA_INV * np.log(y_plus) + LOG_B


def profile_statistics(ds) -> pd.DataFrame:
    """u⁺(y⁺), r.m.s. of u, v, w and the Reynolds shear stress −u'v'⁺ over x, z and time."""
    ny = len(ds.y)
    s1 = np.zeros((ny, 3))
    s2 = np.zeros((ny, 3))
    suv = np.zeros(ny)
    n = 0
    for i in range(ds.n_snapshots):
        u = ds.snapshot(i)  # (nx, ny, nz, 3)
        s1 += u.sum(axis=(0, 2))
        s2 += (u * u).sum(axis=(0, 2))
        suv += (u[..., 0] * u[..., 1]).sum(axis=(0, 2))
        n += u.shape[0] * u.shape[2]
    mean = s1 / n
    var = np.maximum(s2 / n - mean**2, 0.0)
    uv = suv / n - mean[:, 0] * mean[:, 1]
    return pd.DataFrame(
        {
            "y_plus": np.asarray(ds.y, dtype=float),
            "u_plus": mean[:, 0],
            "v_plus": mean[:, 1],
            "w_plus": mean[:, 2],
            "u_rms": np.sqrt(var[:, 0]),
            "v_rms": np.sqrt(var[:, 1]),
            "w_rms": np.sqrt(var[:, 2]),
            "minus_uv": -uv,
        }
    )


def law_of_the_wall_table(profile: pd.DataFrame, points=CHECK_POINTS) -> pd.DataFrame:
    """u⁺ at chosen y⁺ against the applicable law (sublayer, log law, Reichardt in between)."""
    rows = []
    y, u = profile["y_plus"].to_numpy(), profile["u_plus"].to_numpy()
    for yp in points:
        if yp > y[-1]:
            continue
        u_les = float(np.interp(yp, np.concatenate([[0.0], y]), np.concatenate([[0.0], u])))
        if yp <= 5.0:
            law, ref = "u+ = y+", yp
        elif yp >= 30.0:
            law, ref = "u+ = 2.44 ln y+ + 5.2", float(log_law_check(yp))
        else:
            law, ref = "Reichardt (buffer layer)", float(reichardt(yp))
        rows.append({"y_plus": yp, "u_plus_les": u_les, "law": law, "u_plus_law": ref, "rel_diff": u_les / ref - 1.0})
    return pd.DataFrame(rows)


def summarize(ds, profile: pd.DataFrame) -> dict:
    y = profile["y_plus"].to_numpy()
    u = profile["u_plus"].to_numpy()
    log_region = (y >= 30.0) & (y <= min(0.3 * ds.re_tau, 200.0))
    peak = int(np.argmax(profile["u_rms"].to_numpy()))
    out = {
        "re_tau": ds.re_tau,
        "u_rms_peak": float(profile["u_rms"].iloc[peak]),
        "u_rms_peak_y_plus": float(y[peak]),
        "first_cell_y_plus": float(y[0]),
    }
    if log_region.any():
        rel = u[log_region] / log_law_check(y[log_region]) - 1.0
        out["log_region"] = [float(y[log_region][0]), float(y[log_region][-1])]
        out["log_region_max_abs_rel_diff"] = float(np.max(np.abs(rel)))
    return out


def write_profile_check(ds, out_dir) -> dict:
    """Write profile.csv, law_of_the_wall.csv, profile_check.json and profile.png; return the summary."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    prof = profile_statistics(ds)
    table = law_of_the_wall_table(prof)
    summary = summarize(ds, prof)
    summary["law_of_the_wall"] = table.to_dict(orient="records")
    prof.to_csv(out_dir / "profile.csv", index=False, float_format="%.5g")
    table.to_csv(out_dir / "law_of_the_wall.csv", index=False, float_format="%.4g")
    (out_dir / "profile_check.json").write_text(json.dumps(summary, indent=1))

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    y = prof["y_plus"]
    a1.semilogx(y, prof["u_plus"], "k-", lw=2, label="dataset")
    ys = np.geomspace(0.1, y.max(), 200)
    a1.semilogx(ys[ys <= 12], ys[ys <= 12], "b--", label="u⁺ = y⁺")
    a1.semilogx(ys[ys >= 10], log_law_check(ys[ys >= 10]), "r--", label="2.44 ln y⁺ + 5.2")
    a1.set_xlabel("y⁺")
    a1.set_ylabel("⟨u⟩⁺")
    a1.set_title(f"mean velocity, Re_τ = {ds.re_tau:.0f}")
    a1.legend()
    for c, name in (("u_rms", "u′"), ("v_rms", "v′"), ("w_rms", "w′")):
        a2.plot(y, prof[c], label=name)
    a2.plot(y, prof["minus_uv"], label="−u′v′")
    a2.axvspan(12, 15, color="0.9", label="expected u′ peak")
    a2.set_xlabel("y⁺")
    a2.set_ylabel("r.m.s.⁺")
    a2.set_xlim(0, min(y.max(), 200))
    a2.legend()
    a2.set_title(f"peak u′ = {summary['u_rms_peak']:.2f} at y⁺ = {summary['u_rms_peak_y_plus']:.1f}")
    fig.tight_layout()
    fig.savefig(out_dir / "profile.png", dpi=110)
    plt.close(fig)
    return summary
