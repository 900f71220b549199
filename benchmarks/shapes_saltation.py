"""Saltation of a natural mixture of bonded-sphere grains vs spheres of the same nominal
diameter on the shipped LES (issue 6 item 5; seed 000 §4.4).

For each flow intensity τ*/τ*c: one run of N composite grains (Smith 2003 class
fractions, nominal diameter Dn = 0.69 mm, shape = "mixture") and one run of N spheres of
d = Dn, same case otherwise (shipped LES channel395, its box at the run's u*, virtual
bed — or ``--bed packed``, the hexagonal layer — with Schmeeckle et al. 2001
coefficients, all forces on, grain–grain contacts off,
same seed: same start positions, velocities and spins). Both go through
``saltation.run`` — the mixture by ``particle.shape = "mixture"``.

Table (CSV + printed), one row per run and, for the mixture, per Zingg class:
H/d, L/d, U/u* (mean ± std over counted jumps, each grain's first 10 dropped), mean
spanwise angular velocity Ω_z and mean |Ω| (u*/d), q* (analysis/transport.py: volume
flux per unit width over the bed area, /√(R g d³); per class: that class's grains'
share), the Ackers–White (1993) capacity q*_AW for the same flow and the ratio. The
transport and spin are averaged over t ≥ the same t_from for both runs of a τ*/τ*c (the
later of the two runs' median start of the first counted jump).

q* scales with the number of grains per bed area: it is compared between runs with the
same N (and box), and its ratio to Ackers–White says how far the run's load is from the
capacity load, not how good the model is.

    python benchmarks/shapes_saltation.py --out runs/shapes_saltation [--n 200] [--duration 4] [--bed packed]
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from saltation.analysis.transport import einstein_number, transport_rate
from saltation.engine.composites import CLASS_IDS, spin_statistics
from saltation.engine.simulation import run
from saltation.grains.shapes import CLASSES

DN = 0.69e-3  # m, nominal diameter (seed 003's validation grain)


def case(n, duration, tau_ratio, seed, threads, bed="virtual"):
    return {
        "particle": {"diameter": DN, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1.0e-6},
        "flow": {"source": "les", "tau_ratio": tau_ratio, "tau_c": 0.032},
        "bed": {"model": bed, "coefficients": "schmeeckle-2001"},
        "collisions": {"model": "off"},
        "run": {"n_particles": n, "duration": duration, "dt_particle": 0.01, "seed": seed, "threads": threads},
        "output": {"vtk": False, "variance": False},
    }


def _t_from(jumps, discarded=10):
    first = jumps[jumps["jump"] == discarded]
    return float(first["t_start"].median()) if len(first) else float("inf")


def _jump_row(j):
    j = j[j["jump"] >= 10]
    # share of counted "jumps" lower than 0.1 d: rocking/rattling contacts of a grain on the
    # virtual bed, each counted as a jump (impact to impact) — they pull the means of H, L down
    out = {"jumps": len(j), "low_jump_frac": float((j["height"] < 0.1).mean()) if len(j) else np.nan}
    for key, col in (("H", "height"), ("L", "length"), ("U", "velocity")):
        out[f"{key}_mean"] = float(j[col].mean()) if len(j) else np.nan
        out[f"{key}_std"] = float(j[col].std(ddof=1)) if len(j) > 1 else np.nan
    return out


def rows_for(label, res, volumes, class_of, t_from, tau_star, aw_qstar):
    """Table rows of one run: all grains, then per class (class_of None: spheres)."""
    jumps, tracks = res.jumps, res.tracks
    s = res.summary
    lx, lz = (x / DN for x in s["domain_m"][:2])
    groups = [("all", np.arange(s["n_particles"]))]
    if class_of is not None:
        groups += [(c, np.nonzero(class_of == CLASS_IDS[c])[0]) for c in CLASSES]
    rows = []
    for name, grains in groups:
        if len(grains) == 0:
            continue
        tr = tracks[np.isin(tracks["particle"].to_numpy(), grains)]
        q = transport_rate(tr, volumes, lx * lz, t_from=t_from)
        sp = spin_statistics(tr, t_from)
        qs = einstein_number(q["q_particle"], tau_star)
        rows.append({"tau_ratio": s["tau_ratio"], "run": label, "group": name, "grains": len(grains),
                     **_jump_row(jumps[np.isin(jumps["particle"].to_numpy(), grains)]),
                     "omega_z": sp["omega_z_mean"], "omega_abs": sp["omega_abs_mean"],
                     "u_volume_mean": q["u_volume_mean"], "volume_mean_d3": float(volumes[grains].mean()),
                     "q_star": qs, "q_star_AW": aw_qstar, "ratio_AW": qs / aw_qstar if aw_qstar else np.nan,
                     "t_from": t_from})
    return rows


def figure(table: pd.DataFrame, path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = ["sphere", "mixture"] + list(CLASSES)
    panels = [("H_mean", "H_std", "H / d"), ("L_mean", "L_std", "L / d"), ("U_mean", "U_std", "U / u*"),
              ("q_star", None, "q*")]
    taus = sorted(table["tau_ratio"].unique())
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.8))
    width = 0.8 / len(taus)
    for ax, (col, err, label) in zip(axes, panels):
        for k, tau in enumerate(taus):
            sub = table[table["tau_ratio"] == tau]
            vals, errs = [], []
            for g in groups:
                r = sub[(sub["run"] == "sphere") & (sub["group"] == "all")] if g == "sphere" else \
                    sub[(sub["run"] == "mixture") & (sub["group"] == ("all" if g == "mixture" else g))]
                vals.append(float(r[col].iloc[0]) if len(r) else np.nan)
                errs.append(float(r[err].iloc[0]) if (err and len(r)) else 0.0)
            x = np.arange(len(groups)) + (k - (len(taus) - 1) / 2) * width
            ax.bar(x, vals, width, yerr=errs if err else None, capsize=2, label=f"τ*/τ*c = {tau:g}")
        ax.set_xticks(np.arange(len(groups)))
        ax.set_xticklabels(groups, rotation=35)
        ax.set_ylabel(label)
    axes[3].set_title("class rows: that class's share", fontsize=8)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Bonded-sphere mixture (Smith 2003) vs spheres, Dn = {DN * 1e3:g} mm, shipped LES "
                 f"(mean ± std over counted jumps)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="runs/shapes_saltation")
    ap.add_argument("--n", type=int, default=200, help="grains per run (both runs)")
    ap.add_argument("--duration", type=float, default=4.0, help="simulated time per run (s)")
    ap.add_argument("--tau-ratios", type=float, nargs="+", default=[1.79, 2.43])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--bed", choices=("virtual", "packed"), default="virtual", help="bed.model of both runs")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, meta = [], []
    for tau in args.tau_ratios:
        base = case(args.n, args.duration, tau, args.seed, args.threads, args.bed)
        t0 = time.perf_counter()
        sph = run(base, out=out / f"sphere_{tau:g}", progress=False)
        t1 = time.perf_counter()
        mix = run(base, out=out / f"mixture_{tau:g}", progress=False, **{"particle.shape": "mixture"})
        t2 = time.perf_counter()
        grains = pd.read_parquet(out / f"mixture_{tau:g}" / "particles.parquet")
        t_from = max(_t_from(sph.jumps), _t_from(mix.jumps))
        aw = mix.summary["transport"]["ackers_white"]
        tau_star = mix.summary["tau_star"]
        rows += rows_for("sphere", sph, np.full(args.n, math.pi / 6.0), None, t_from, tau_star, aw["q_star"])
        rows += rows_for("mixture", mix, grains["volume"].to_numpy(), grains["class_id"].to_numpy(), t_from,
                         tau_star, aw["q_star"])
        meta.append({"tau_ratio": tau, "tau_star": tau_star, "wall_s_sphere": t1 - t0, "wall_s_mixture": t2 - t1,
                     "steps": mix.summary["steps"], "duration_particle": mix.summary["simulated_time_particle"],
                     "domain_d": [x / DN for x in mix.summary["domain_m"]], "t_from": t_from,
                     "ackers_white": aw, "mixture_shape": mix.summary["shape"]})
        print(f"τ*/τ*c = {tau:g}: spheres {t1 - t0:.0f} s, mixture {t2 - t1:.0f} s wall "
              f"({mix.summary['steps']} steps, {mix.summary['shape']['component_spheres']} component spheres)")
    table = pd.DataFrame(rows)
    table.to_csv(out / "shapes_saltation.csv", index=False)
    (out / "shapes_saltation.json").write_text(json.dumps({"runs": meta, "n": args.n, "duration_s": args.duration,
                                                           "seed": args.seed, "bed": args.bed}, indent=1, default=str))
    figure(table, out / "shapes_saltation.png")
    cols = ["tau_ratio", "run", "group", "grains", "jumps", "low_jump_frac", "H_mean", "H_std", "L_mean", "L_std", "U_mean",
            "U_std", "omega_z", "omega_abs", "volume_mean_d3", "u_volume_mean", "q_star", "q_star_AW", "ratio_AW"]
    with pd.option_context("display.width", 220, "display.max_columns", 30, "display.float_format", "{:.4g}".format):
        print(table[cols].to_string(index=False))
    print(f"wrote {out / 'shapes_saltation.csv'}, {out / 'shapes_saltation.png'}, {out / 'shapes_saltation.json'}")


if __name__ == "__main__":
    main()
