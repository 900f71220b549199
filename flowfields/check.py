"""Physical check of a flow dataset: mean and r.m.s. profiles against the law of the wall.

Averages over x, z and all snapshots. Law of the wall (issue 2 / Pope 2000):
viscous sublayer u⁺ = y⁺ (y⁺ ≲ 5), log law u⁺ = 2.44 ln y⁺ + 5.2 (y⁺ ≳ 30).

A rough-bed dataset (meta.json "bed", flowfields.rough_bed) is checked against the rough
log law instead: the mean profile above the bed top is fitted with a virtual origin and a
roughness function ΔU⁺ (``rough_bed.roughness_fit``), and ΔU⁺ is compared with
Colebrook's and Nikuradse's at k_s = 1, 2 and 2.5 d; u⁺ at heights above the bed top is
tabulated against the fitted law; u* is the dataset's own (the momentum balance at the
bed top, recorded by the generator).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from . import rough_bed as rb
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


ROUGH_CHECK_HEIGHTS_D = (0.25, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0)


def rough_bed_summary(ds, profile: pd.DataFrame) -> dict:
    """Roughness fit of a rough-bed dataset's mean profile and u⁺ at heights above the
    bed top (in d) against the fitted law."""
    d_plus = float(ds.bed["d_plus"])
    y, u = profile["y_plus"].to_numpy(), profile["u_plus"].to_numpy()
    try:
        fit = rb.roughness_fit(y, u, d_plus, re_tau=ds.re_tau)
    except ValueError as exc:  # no log region (a low-Re_tau or very shallow channel)
        return {"d_plus": d_plus, "floor_plus": float(ds.bed["floor_plus"]), "fit_error": str(exc), "table": [],
                "u_at_bed_top": float(np.interp(0.0, y, u)),
                "u_rms_peak": float(profile["u_rms"].max()),
                "u_rms_peak_y_plus": float(y[int(np.argmax(profile["u_rms"].to_numpy()))]),
                "u_rms_peak_y_d": float(y[int(np.argmax(profile["u_rms"].to_numpy()))]) / d_plus}
    rows = []
    for yd in ROUGH_CHECK_HEIGHTS_D:
        yp = yd * d_plus
        if yp > y[-1]:
            continue
        u_les = float(np.interp(yp, y, u))
        law = float(rb.rough_law(yp, fit))
        rows.append({"y_d": yd, "y_plus": yp, "u_plus_les": u_les, "u_plus_fitted_law": law,
                     "u_plus_smooth_log_law": float(log_law_check(yp)),
                     "rel_diff": u_les / law - 1.0,
                     "in_fit_range": bool(fit["log_range_plus"][0] <= yp <= fit["log_range_plus"][1])})
    above = y >= 0
    peak = int(np.argmax(np.where(above, profile["u_rms"].to_numpy(), -1.0)))
    ks_ref = {k: float(rb.colebrook_delta_u(float(k) * d_plus)) for k in (1.0, 2.0, 2.5)}
    return {
        "d_plus": d_plus, "floor_plus": float(ds.bed["floor_plus"]),
        "u_tau_source": (ds.meta.get("provenance", {}).get("bed") or {}).get("u_tau_source", "given at import"),
        **fit,
        "colebrook_delta_u_plus": ks_ref,
        "nikuradse_delta_u_plus": {k: float(rb.nikuradse_delta_u(float(k) * d_plus)) for k in (1.0, 2.0, 2.5)},
        "delta_u_minus_colebrook_at_ks_d": {f"{k:g}": fit["delta_u_plus"] - v for k, v in ks_ref.items()},
        "u_at_bed_top": float(np.interp(0.0, y, u)),
        "u_rms_peak": float(profile["u_rms"].iloc[peak]), "u_rms_peak_y_plus": float(y[peak]),
        "u_rms_peak_y_d": float(y[peak]) / d_plus,
        "table": rows,
    }


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
    rough = rough_bed_summary(ds, prof) if getattr(ds, "bed", None) else None
    if rough:
        summary["rough_bed"] = rough
        # the smooth-wall numbers do not apply over a bed: keep the rough ones only
        summary.pop("log_region", None)
        summary.pop("log_region_max_abs_rel_diff", None)
        summary["law_of_the_wall"] = []
        summary["u_rms_peak"], summary["u_rms_peak_y_plus"] = rough["u_rms_peak"], rough["u_rms_peak_y_plus"]
        pd.DataFrame(rough["table"]).to_csv(out_dir / "rough_bed.csv", index=False, float_format="%.4g")
    prof.to_csv(out_dir / "profile.csv", index=False, float_format="%.5g")
    table.to_csv(out_dir / "law_of_the_wall.csv", index=False, float_format="%.4g")
    (out_dir / "profile_check.json").write_text(json.dumps(summary, indent=1))

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    y = prof["y_plus"]
    ys = np.geomspace(0.1, y.max(), 200)
    if rough and "fit_error" not in rough:
        yd0 = rough["virtual_origin_plus"]
        pos = y > 0
        a1.semilogx(y[pos] + yd0, prof["u_plus"][pos], "k-", lw=2, label="dataset (above the bed top)")
        a1.semilogx(ys[ys >= 10], log_law_check(ys[ys >= 10]), "r:", label="smooth wall 2.44 ln y⁺ + 5.2")
        a1.semilogx(ys[ys >= 5], rb.rough_law(ys[ys >= 5] - yd0, rough), "b--",
                    label=f"fit: ΔU⁺ = {rough['delta_u_plus']:.2f}, y_d = {rough['virtual_origin_d']:.2f} d")
        for k in rough["log_range_plus"]:
            a1.axvline(k + yd0, color="0.7", lw=0.8)
        a1.set_xlabel("y⁺ + y_d⁺ (from the virtual origin)")
    else:
        a1.semilogx(y, prof["u_plus"], "k-", lw=2, label="dataset")
        a1.semilogx(ys[ys <= 12], ys[ys <= 12], "b--", label="u⁺ = y⁺")
        a1.semilogx(ys[ys >= 10], log_law_check(ys[ys >= 10]), "r--", label="2.44 ln y⁺ + 5.2")
        a1.set_xlabel("y⁺")
    a1.set_ylabel("⟨u⟩⁺")
    a1.set_title(f"mean velocity, Re_τ = {ds.re_tau:.0f}")
    a1.legend()
    for c, name in (("u_rms", "u′"), ("v_rms", "v′"), ("w_rms", "w′")):
        a2.plot(y, prof[c], label=name)
    a2.plot(y, prof["minus_uv"], label="−u′v′")
    if rough:
        a2.axvline(0.0, color="0.5", lw=1, label="bed top")
        a2.set_xlim(float(y[0]), min(y.max(), 200))
    else:
        a2.axvspan(12, 15, color="0.9", label="expected u′ peak")
    a2.set_xlabel("y⁺")
    a2.set_ylabel("r.m.s.⁺")
    if not rough:
        a2.set_xlim(0, min(y.max(), 200))
    a2.legend()
    a2.set_title(f"peak u′ = {summary['u_rms_peak']:.2f} at y⁺ = {summary['u_rms_peak_y_plus']:.1f}")
    fig.tight_layout()
    fig.savefig(out_dir / "profile.png", dpi=110)
    plt.close(fig)
    return summary
