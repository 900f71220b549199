"""Hydrodynamic time step from measurement: jump statistics against run.dt_particle.

Two sets, each at every dt in --dts (d/u*), τ*/τ*c = 1.79, the reduced paper domain
(cases/concentration_sweep_reduced.toml), one thread, the same seed for every dt:

* free flight: collisions.model = "off", --n-free grains (independent of each other; the
  number only buys jumps), --free-duration s, every jump counted after each grain's
  first 10;
* contacts on: soft contacts at C = --conc (default 2.07 %), the stiffness of --factor ×
  the current overlap rule's value (see study_stiffness.py; 1 = the default), statistics
  after --spinup s.

The reference is the smallest dt; beside it a first-order Richardson value 2 X(dt₁) −
X(2 dt₁) where the dts allow. For each dt: the relative deviation of H, L, U from the
reference, with the standard error of that *difference* from a bootstrap over grains
that resamples the same grains in both runs (same seed: a grain starts alike at every
dt and draws the same bed-normal random numbers, so the difference is much less noisy
than either value). The largest dt whose H, L, U are within 1 % of the reference (and,
separately, within 1 % allowing 2 SE of the difference) is printed.

    PYTHONPATH=. NUMBA_CACHE_DIR=/tmp/numba python benchmarks/study_dt.py \
        --out /tmp/saltation-studies/dt [--dts 0.005 0.01 0.02 0.04 0.05] [--sets free contacts]

Writes per-run JSON/NPZ (a rerun skips finished points), dt.csv, dt.json, dt.png under --out.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_stiffness import DISCARD, N_BOOT, base_tables, default_stiffness, point_overrides, save_point, simulate

QUANTS = ("H", "L", "U")


def _per_grain_sums(jumps, t_from, n):
    sel = (jumps[:, 2] >= t_from) & (jumps[:, 1] >= DISCARD)
    j = jumps[sel]
    g = j[:, 0].astype(np.int64)
    cnt = np.bincount(g, minlength=n).astype(float)
    vals = {"H": j[:, 4], "L": j[:, 3], "U": j[:, 3] / j[:, 5]}
    return cnt, {k: np.bincount(g, weights=v, minlength=n) for k, v in vals.items()}


def paired_differences(ref, other, t_from, n, seed=0):
    """Relative difference other/ref − 1 of H, L, U means and its SE (bootstrap over the
    same grains in both runs)."""
    c0, s0 = _per_grain_sums(ref, t_from, n)
    c1, s1 = _per_grain_sums(other, t_from, n)
    rng = np.random.default_rng(seed)
    W = rng.multinomial(n, np.full(n, 1.0 / n), size=N_BOOT).astype(float)
    out = {}
    for q in QUANTS:
        m0 = s0[q].sum() / c0.sum()
        m1 = s1[q].sum() / c1.sum()
        b0 = (W @ s0[q]) / (W @ c0)
        b1 = (W @ s1[q]) / (W @ c1)
        out[q] = {"rel": float(m1 / m0 - 1.0), "rel_se": float((b1 / b0 - 1.0).std(ddof=1))}
    return out


def run_set(name, tables, dts, overrides, spinup, out: Path, record=False):
    res = {}
    for dt in dts:
        path = out / f"{name}_dt{dt:.4f}.json"
        if path.exists():
            res[dt] = json.loads(path.read_text())
            res[dt]["_jumps"] = np.load(path.with_suffix(".npz"))["jumps"]
            continue
        tb = json.loads(json.dumps(tables))
        tb["run"]["dt_particle"] = dt
        t0 = time.perf_counter()
        r = simulate(tb, overrides, spinup, record=record, label=f"{name} dt={dt}")
        r["set"] = name
        jumps = r["_jumps"]
        save_point(path, r)
        r["_jumps"] = jumps
        js = r["jump_stats"]
        print(f"{name} dt={dt}: N={r['n_particles']} sub={r['contact_substeps']} jumps={js['count']} "
              f"H={js['H_mean']:.4f} L={js['L_mean']:.4f} U={js['U_mean']:.4f} wall={time.perf_counter() - t0:.0f}s",
              flush=True)
        res[dt] = r
    return res


def analyse(name, res, tol=0.01):
    dts = sorted(res)
    ref = res[dts[0]]
    n = ref["n_particles"]
    t_from = ref["spinup_particle"]
    lines = [f"\n### {name}: N = {n}, {ref['steps'] * ref['dt_particle']:.1f} d/u* simulated at the smallest dt, "
             f"statistics after {t_from:.1f} d/u*\n",
             "| dt (d/u*) | sub-steps | counted jumps | H/d | L/d | U/u* | ΔH | ΔL | ΔU (rel. to dt = "
             f"{dts[0]:g}, ± SE of the paired difference) | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    rows = []
    rich = None
    if len(dts) >= 2 and abs(dts[1] - 2 * dts[0]) < 1e-12:
        a, b = res[dts[0]]["jump_stats"], res[dts[1]]["jump_stats"]
        rich = {q: 2 * a[f"{q}_mean"] - b[f"{q}_mean"] for q in QUANTS}
    largest, largest_noise = dts[0], dts[0]
    passing, passing_noise = True, True
    for dt in dts:
        r = res[dt]
        js = r["jump_stats"]
        d = paired_differences(ref["_jumps"], r["_jumps"], t_from, n) if dt != dts[0] else \
            {q: {"rel": 0.0, "rel_se": 0.0} for q in QUANTS}
        within = all(abs(d[q]["rel"]) <= tol for q in QUANTS)
        within_noise = all(abs(d[q]["rel"]) - 2 * d[q]["rel_se"] <= tol for q in QUANTS)
        passing = passing and within
        passing_noise = passing_noise and within_noise
        if passing:
            largest = dt
        if passing_noise:
            largest_noise = dt
        row = {"set": name, "dt": dt, "substeps": r["contact_substeps"], "jumps": js["count"],
               "wall_s": r["wall_s"], "within_1pct": within}
        for q in QUANTS:
            row[f"{q}_mean"] = js[f"{q}_mean"]
            row[f"{q}_se"] = js[f"{q}_se"]
            row[f"{q}_rel"] = d[q]["rel"]
            row[f"{q}_rel_se"] = d[q]["rel_se"]
            if rich:
                row[f"{q}_rel_to_richardson"] = js[f"{q}_mean"] / rich[q] - 1.0
        rows.append(row)
        lines.append(
            f"| {dt:g} | {r['contact_substeps']} | {js['count']} | "
            + " | ".join(f"{js[q + '_mean']:.4f} ± {js[q + '_se']:.4f}" for q in QUANTS) + " | "
            + " | ".join(f"{100 * d[q]['rel']:+.2f} ± {100 * d[q]['rel_se']:.2f} %" for q in QUANTS)
            + f" | {r['wall_s']:.0f} |")
    if rich:
        lines.append("\nFirst-order Richardson values 2X(dt₁) − X(2dt₁): "
                     + ", ".join(f"{q} = {rich[q]:.4f}" for q in QUANTS)
                     + "; deviation of each dt from them: "
                     + "; ".join(f"dt={row['dt']:g}: " + ", ".join(f"{q} {100 * row[q + '_rel_to_richardson']:+.2f} %"
                                                                  for q in QUANTS) for row in rows))
    lines.append(f"\nLargest dt with H, L, U all within {100 * tol:g} % of dt = {dts[0]:g} (and every smaller dt too): "
                 f"**{largest:g}**; allowing 2 SE of the paired difference: {largest_noise:g}")
    return "\n".join(lines), rows, {"largest_within": largest, "largest_within_noise": largest_noise,
                                    "richardson": rich}


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(13, 4))
    for ax, q in zip(axs, QUANTS):
        for name in sorted({r["set"] for r in rows}):
            rs = [r for r in rows if r["set"] == name]
            ax.errorbar([r["dt"] for r in rs], [100 * r[f"{q}_rel"] for r in rs],
                        yerr=[200 * r[f"{q}_rel_se"] for r in rs], marker="o", capsize=3, label=name)
        ax.axhspan(-1, 1, color="0.9")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("dt (d/u*)")
        ax.set_ylabel(f"{q}: % from smallest dt")
        ax.grid(alpha=0.3)
    axs[0].legend()
    fig.suptitle("Jump statistics vs hydrodynamic step (±2 SE of the paired difference; band: ±1 %)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="/tmp/saltation-studies/dt")
    ap.add_argument("--dts", type=float, nargs="+", default=[0.005, 0.01, 0.02, 0.04, 0.05])
    ap.add_argument("--sets", nargs="+", default=["free", "contacts"])
    ap.add_argument("--n-free", type=int, default=800)
    ap.add_argument("--free-duration", type=float, default=1.5)
    ap.add_argument("--conc", type=float, default=0.0207)
    ap.add_argument("--factor", type=float, default=1.0, help="k_n / k_default for the contact set")
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--spinup", type=float, default=0.5)
    ap.add_argument("--shrink", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--bed", choices=("virtual", "packed"), default="virtual", help="bed.model of every run")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    dts = sorted(a.dts)
    text, rows, verdicts = [], [], {}
    if "free" in a.sets:
        tb = base_tables(a.shrink)
        ov = {"collisions.model": "off", "run.n_particles": a.n_free, "run.duration": a.free_duration,
              "run.seed": a.seed, "run.threads": 1, "bed.model": a.bed}
        res = run_set("free", tb, dts, ov, 0.0, out)
        t, r, v = analyse(f"free flight (contacts off, {a.bed} bed)", res)
        text.append(t), rows.extend(r)
        verdicts["free"] = v
    if "contacts" in a.sets:
        tb = base_tables(a.shrink)
        k_def = default_stiffness(tb)
        ov = {**point_overrides(k_def, a.factor, a.conc, a.seed, a.duration), "bed.model": a.bed}
        res = run_set("contacts", tb, dts, ov, a.spinup, out)
        t, r, v = analyse(f"soft contacts, C = {100 * a.conc:.2f} %, k_n = {a.factor:g} × k_default", res)
        text.append(t), rows.extend(r)
        verdicts["contacts"] = v
    header = f"τ*/τ*c = 1.79, seed {a.seed}, domain shrink {a.shrink}, {a.bed} bed"
    print(header)
    print("\n".join(text))
    (out / "dt.md").write_text(header + "\n" + "\n".join(text) + "\n")
    if rows:
        with open(out / "dt.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k)
                                                     if k in rows[0] else 99))
            w.writeheader()
            w.writerows(rows)
        plot(rows, out / "dt.png")
    (out / "dt.json").write_text(json.dumps({"args": vars(a), "rows": rows, "verdicts": verdicts}, indent=1,
                                            default=float))


if __name__ == "__main__":
    main()
