"""Single-grain validation against Niño & García (1998) conditions (paper §3.2, Fig. 4).

Runs the four shipped cases (d = 0.69 mm quartz, τ*c = 0.032, τ*/τ*c = 1.79, 1.87, 2.43,
2.67) and compares the mean jump height H/d, length L/d and grain velocity U/u* with

(a) an experimental data file, when the user has one (CSV, columns below). The
    measurements of Niño & García (1998) are not distributed with this project; nothing
    here invents them. Columns::

        source, tau_ratio, H_mean, H_std, L_mean, L_std, U_mean, U_std

    H and L in grain diameters, U in units of u*, std = one standard deviation; empty
    cells allowed. ``source`` is free text (paper, table, figure).

(b) the published regressions of van Rijn (1984, J. Hydraul. Eng. 110(10)), with
    D* = d (R g/ν²)^{1/3} and T = τ*/τ*c − 1:
    saltation height δ_b/d = 0.3 D*^0.7 T^0.5, grain velocity u_b = 1.5 T^0.6 √(R g d)
    (so U/u* = 1.5 T^0.6/√τ*), and saltation length λ_b/d = 3 D*^0.6 T^0.9.

The force ablation switches each of lift, Magnus, added mass, fluid acceleration and
Basset off in turn and reports the change of H, L and U against the all-forces run.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

CASES = {
    1.79: "nino_garcia_179.toml",
    1.87: "nino_garcia_187.toml",
    2.43: "nino_garcia_243.toml",
    2.67: "nino_garcia_267.toml",
}
ABLATION_FORCES = ("lift", "magnus", "added_mass", "fluid_acceleration", "basset")
EXPERIMENT_COLUMNS = ("source", "tau_ratio", "H_mean", "H_std", "L_mean", "L_std", "U_mean", "U_std")


def cases_dir() -> Path:
    here = Path(__file__).resolve().parent.parent / "cases"
    if here.exists():
        return here
    return Path.cwd() / "cases"


def van_rijn(case) -> dict:
    """van Rijn (1984) saltation height, length (in d) and grain velocity (in u*)."""
    g, d, nu, R = case.gravity, case.particle.diameter, case.fluid.viscosity, case.submerged_specific_gravity
    d_star = d * (R * g / nu**2) ** (1.0 / 3.0)
    T = case.tau_ratio - 1.0
    return {
        "H_vanrijn": 0.3 * d_star**0.7 * T**0.5,
        "L_vanrijn": 3.0 * d_star**0.6 * T**0.9,
        "U_vanrijn": 1.5 * T**0.6 / np.sqrt(case.shields_number),
        "D_star": d_star,
    }


def read_experiments(path) -> pd.DataFrame:
    """Read and check a user's experimental CSV (columns in the module docstring)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"experimental data file not found: {path}")
    df = pd.read_csv(path, comment="#")
    missing = [c for c in EXPERIMENT_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"{path}: missing column(s) {missing}; expected {list(EXPERIMENT_COLUMNS)}")
    return df


def _stats(result) -> dict:
    j = result.summary["jumps"]
    return {k: j[k] for k in ("count", "H_mean", "H_std", "L_mean", "L_std", "U_mean", "U_std")}


def run_validation(out, data=None, duration_scale=1.0, ablation=True, progress=True, threads=0) -> dict:
    """Run the four cases (and the ablation); write table, figure and JSON into ``out``."""
    from .config import load_case
    from .simulation import run

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for ratio, name in CASES.items():
        case_path = cases_dir() / name
        case = load_case(case_path)
        overrides = {"output.vtk": False, "run.threads": threads}
        if duration_scale != 1.0:
            overrides["run.duration"] = case.run.duration * duration_scale
        res = run(case_path, out=out / "runs" / name.removesuffix(".toml"), progress=progress, overwrite=True, **overrides)
        row = {"tau_ratio": ratio, "tau_star": res.summary["tau_star"], **_stats(res), **van_rijn(load_case(case_path))}
        rows.append(row)
        print(f"τ*/τ*c = {ratio}: {row['count']} jumps, H = {row['H_mean']:.2f} d, L = {row['L_mean']:.2f} d, U = {row['U_mean']:.2f} u*", flush=True)
    table = pd.DataFrame(rows)
    for q in ("H", "L", "U"):
        table[f"{q}_model_over_vanrijn"] = table[f"{q}_mean"] / table[f"{q}_vanrijn"]
    table.to_csv(out / "validation.csv", index=False, float_format="%.4g")
    experiments = read_experiments(data) if data else None
    _figure(table, experiments, out / "validation.png")
    result = {"validation": table.to_dict(orient="records")}
    if ablation:
        abl = run_ablation(out, duration_scale=duration_scale, progress=progress, threads=threads)
        abl.to_csv(out / "ablation.csv", index=False, float_format="%.4g")
        result["ablation"] = abl.to_dict(orient="records")
    (out / "validation.json").write_text(json.dumps(result, indent=1, default=float))
    return result


def run_ablation(out, ratio=1.79, duration_scale=1.0, progress=True, threads=0) -> pd.DataFrame:
    """Each force off in turn at one flow intensity; % change of H, L, U vs all forces on."""
    from .config import load_case
    from .simulation import run

    case_path = cases_dir() / CASES[ratio]
    case = load_case(case_path)
    base_over = {"output.vtk": False, "output.tracks": False, "run.threads": threads}
    if duration_scale != 1.0:
        base_over["run.duration"] = case.run.duration * duration_scale
    variants = [("all forces", {})] + [(f"no {f}", {f"forces.{f}": False}) for f in ABLATION_FORCES]
    rows = []
    for label, over in variants:
        res = run(case_path, out=Path(out) / "ablation" / label.replace(" ", "_"), progress=progress, overwrite=True, **base_over, **over)
        rows.append({"variant": label, **_stats(res)})
    df = pd.DataFrame(rows)
    for q in ("H", "L", "U"):
        df[f"{q}_change_pct"] = 100.0 * (df[f"{q}_mean"] / df[f"{q}_mean"].iloc[0] - 1.0)
    return df


def _figure(table: pd.DataFrame, experiments, path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    x = table["tau_ratio"].to_numpy()
    for ax, q, label in zip(axes, ("H", "L", "U"), ("H/d", "L/d", "U/u*")):
        ax.errorbar(x, table[f"{q}_mean"], yerr=2 * table[f"{q}_std"], fmt="ko", capsize=4, label="model (mean ± 2σ)")
        ax.plot(x, table[f"{q}_vanrijn"], "r--s", label="van Rijn (1984)")
        if experiments is not None and f"{q}_mean" in experiments:
            e = experiments.dropna(subset=[f"{q}_mean"])
            ax.errorbar(e["tau_ratio"], e[f"{q}_mean"], yerr=2 * e[f"{q}_std"].fillna(0), fmt="b^", capsize=4, label="experiment (± 2σ)")
        ax.set_xlabel("τ*/τ*c")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Single-grain saltation, d = 0.69 mm quartz in water (Niño & García 1998 conditions)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
