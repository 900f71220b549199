"""Contact stiffness from measurement (SPEC §5): jump statistics, collision rates and the
overlap distribution against k_n, and the relative approach speed of real contacts.

For each concentration C and each k_n = k_default × factor (k_default: the overlap rule's
value of the case, Case.collision_stiffness with collisions.stiffness absent) one run on
the reduced paper domain (cases/concentration_sweep_reduced.toml, optionally shrunk
further in x and z by --shrink), τ*/τ*c = 1.79, soft contacts, one thread, the same
seed(s) for every k. ``collisions.stiffness`` is passed explicitly; the overlap rule
refuses a stiffness below its own value, so ``collisions.impact_speed`` is lowered by
√factor with it (k ∝ impact_speed², the rule's value then equals the given k).

Statistics are taken after a spin-up (--spinup s): jumps that *start* after it (and, as
in summary.json, not among a grain's first 10), collisions begun after it (per grain per
d/u*), overlaps after it (cl.max_overlap and the contact phase's sums are reset at the
end of the spin-up; they are statistics only, no force reads them). Standard errors are
by grain (cluster bootstrap over grains: a grain's successive jumps are correlated, two
grains of one run are treated as independent — the shared LES and collisions make that
optimistic; several seeds (--seeds) give the run-to-run scatter where affordable).

Approach speeds: the code does not record the normal speed at which a grain–grain
contact begins, so during the measurement window the run advances one step at a time
and this script reconstructs it (the kernels are not touched): the grains whose
``cl.collisions`` counter rose in the step are the ones that began a contact; for each
pair of them within reach at the start of the step the straight-line relative path
r(t) = r₀ + v_rel t (positions and velocities at the start of the step; gravity cancels
in v_rel) is intersected with |r| = d, and v_n = −r·v_rel/|r| there is the approach
speed. Pairs already overlapping at the step start, or whose straight path does not
reach d within the step, are counted as unmatched (the matched fraction is reported).

The run loop is engine/simulation.Simulation's own (its _new_state/_start/_advance, the
same compiled step); chunk ends do not change a run (engine/simulation.py "Checkpoints"),
so stepping one step at a time in the window gives the run saltation.run would give.

    PYTHONPATH=. NUMBA_CACHE_DIR=/tmp/numba python benchmarks/study_stiffness.py \
        --out /tmp/saltation-studies/stiffness [--conc 0.0052 0.0207 0.0394] \
        [--factors 0.0625 0.125 0.25 0.5 1] [--seeds 1] [--duration 1.0] [--spinup 0.5] \
        [--shrink 1.0]

Writes per-run JSON files (a rerun skips finished points), stiffness.csv, stiffness.json
and stiffness.png under --out, and prints the tables (markdown).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

from saltation.io.writers import drain_jumps

REPO = Path(__file__).resolve().parents[1]
REDUCED = REPO / "cases" / "concentration_sweep_reduced.toml"
TAU_RATIO = 1.79
DISCARD = 10  # first jumps of each grain dropped, as engine/statistics.DISCARDED_JUMPS
N_BOOT = 300


# --------------------------------------------------------------------------- one run

def base_tables(shrink: float = 1.0) -> dict:
    """The reduced sweep's case tables (less [sweep]) at τ*/τ*c = 1.79, x and z × shrink."""
    tables = tomllib.loads(REDUCED.read_text())
    tables.pop("sweep", None)
    tables["flow"]["tau_ratio"] = TAU_RATIO
    lx, lz, h = tables["run"]["domain"]
    tables["run"]["domain"] = [lx * shrink, lz * shrink, h]
    tables["output"] = {"tracks": False, "vtk": False, "variance": False}
    tables["run"]["threads"] = 1
    return tables


def _collect(st, rows):
    """Finished jumps (particle, jump, t_start, L, H, T) out of the kernels' buffers."""
    drained = drain_jumps(st)
    if drained is not None:
        part, jidx, data = drained
        rows.append(np.column_stack([part, jidx, data[:, 0], data[:, 1], data[:, 2], data[:, 3]]))


def _approach_speeds(pos0, vel0, dcoll, dt, box):
    """Approach speeds (u*) of the contacts begun in one step (module docstring); returns
    (speeds, contacts begun, contacts matched)."""
    from scipy.spatial import cKDTree

    begun = int(dcoll.sum()) // 2
    g = np.nonzero(dcoll > 0)[0]
    if len(g) < 2:
        return np.zeros(0), begun, 0
    lx, lz = box
    p = pos0[g].copy()
    p[:, 0] = np.mod(p[:, 0], lx)
    p[:, 2] = np.mod(p[:, 2], lz)
    p[:, 1] = p[:, 1] + 50.0  # y is not periodic: a large box
    v = vel0[g]
    vmax = float(np.max(np.linalg.norm(v, axis=1)))
    reach = 1.0 + 2.0 * vmax * dt * 1.05 + 1e-9
    tree = cKDTree(p, boxsize=[lx, 1e6, lz])
    pairs = tree.query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros(0), begun, 0
    i, j = pairs[:, 0], pairs[:, 1]
    r = p[i] - p[j]
    r[:, 0] -= lx * np.round(r[:, 0] / lx)
    r[:, 2] -= lz * np.round(r[:, 2] / lz)
    w = v[i] - v[j]
    # |r + w t| = 1: a t² + b t + c = 0
    a = (w * w).sum(1)
    b = 2.0 * (r * w).sum(1)
    c = (r * r).sum(1) - 1.0
    disc = b * b - 4 * a * c
    ok = (c > 0) & (b < 0) & (disc >= 0) & (a > 0)
    t = np.full(len(r), np.inf)
    t[ok] = (-b[ok] - np.sqrt(disc[ok])) / (2 * a[ok])
    hit = ok & (t <= dt * 1.0001)
    rh = r[hit] + w[hit] * t[hit, None]
    vn = -(rh * w[hit]).sum(1) / np.linalg.norm(rh, axis=1)
    return vn, begun, int(hit.sum())


def simulate(tables, overrides: dict, spinup_s: float, record: bool = True, chunk: int = 200,
             label: str = "") -> dict:
    """One run (module docstring); returns a dict of statistics and the raw arrays."""
    import numba

    from saltation.case.schema import load_case, resolve_domain
    from saltation.engine.simulation import Simulation, _les_box_m, open_flow
    from saltation.flight.spheres import NOT_FINITE

    case = load_case(tables, overrides)
    ds = open_flow(case)
    case = resolve_domain(case, _les_box_m(ds, case) if case.flow.source == "les" else None)
    sim = Simulation(case, ds, Path("/nonexistent-not-written"), progress=False)
    numba.set_num_threads(1)
    st, ws = sim._new_state()
    sim._start(st, resumed=False)
    f = ds.arrays
    t_c0 = time.perf_counter()
    sim._advance(f, st, ws, 0.0, 0, 0)
    compile_s = time.perf_counter() - t_c0
    dt = sim.dt
    n_steps = case.n_steps
    spin_steps = min(n_steps, int(round(spinup_s / case.time_scale / dt)))
    soft = case.collisions.model == "soft"
    rows, speeds = [], []
    begun = matched = 0
    coll_spin = None
    wall0 = time.perf_counter()
    kernel_spin = 0.0
    step = 0
    while step < n_steps:
        in_window = step >= spin_steps
        if step == spin_steps and soft:
            stp = sim.stepper
            coll_spin = stp.cl.collisions.copy()
            stp.cl.max_overlap[:] = 0.0
            stp.ph.overlap_sum[:] = 0.0
            stp.ph.contact_substeps[:] = 0
            stp.ph.bed_overlap_max[:] = 0.0
            kernel_spin = time.perf_counter() - wall0
            timers_spin = stp.timers.copy()
        if step == spin_steps and not soft:
            kernel_spin = time.perf_counter() - wall0
        if in_window and record and soft:
            pos0, vel0 = st.pos.copy(), st.vel.copy()
            c0 = sim.stepper.cl.collisions.copy()
            done = sim._advance(f, st, ws, step * dt, 1, step)
            vn, nb, nm = _approach_speeds(pos0, vel0, sim.stepper.cl.collisions - c0, dt, sim.domain_d)
            speeds.append(vn)
            begun += nb
            matched += nm
        else:
            want = min(chunk, n_steps - step, (spin_steps - step) if step < spin_steps else n_steps)
            done = sim._advance(f, st, ws, step * dt, want, step)
        _collect(st, rows)
        if np.any(st.status == NOT_FINITE):
            raise RuntimeError(f"{label}: a grain became non-finite near step {step + done}")
        step += done
    wall = time.perf_counter() - wall0
    jumps = np.concatenate(rows) if rows else np.zeros((0, 6))
    t_spin_p = spin_steps * dt
    window_p = (n_steps - spin_steps) * dt
    out = {
        "label": label,
        "overrides": {k: v for k, v in overrides.items()},
        "n_particles": int(case.n_particles),
        "concentration": case.concentration,
        "domain_m": list(case.domain),
        "domain_d": list(sim.domain_d),
        "time_scale_s": case.time_scale,
        "dt_particle": dt,
        "steps": n_steps,
        "spinup_particle": t_spin_p,
        "window_particle": window_p,
        "stiffness_N_m": case.collision_stiffness if soft else None,
        "contact_substeps": case.contact_substeps,
        "wall_s": wall,
        "wall_window_s": wall - kernel_spin,
        "compile_s": compile_s,
        "timers": sim.stepper.timing(),
    }
    out["jump_stats"] = jump_stats(jumps, t_spin_p, case.n_particles)
    if soft:
        stp = sim.stepper
        dcoll = stp.cl.collisions - (coll_spin if coll_spin is not None else 0)
        rate = dcoll / window_p  # per grain per d/u* (a collision counts for both grains)
        sub = int(stp.ph.contact_substeps.sum())
        mo = stp.cl.max_overlap
        out["collisions"] = {
            "rate_per_grain": float(rate.mean()),
            "rate_se": float(rate.std(ddof=1) / math.sqrt(len(rate))),
            "begun_in_window": int(dcoll.sum()) // 2,
        }
        out["overlap"] = {
            "time_mean_over_d": float(stp.ph.overlap_sum.sum() / sub) if sub else None,
            "grain_max_p50": float(np.percentile(mo[mo > 0], 50)) if np.any(mo > 0) else 0.0,
            "grain_max_p99": float(np.percentile(mo[mo > 0], 99)) if np.any(mo > 0) else 0.0,
            "max_over_d": float(mo.max(initial=0.0)),
            "bed_max_over_d": float(stp.ph.bed_overlap_max.max(initial=0.0)),
            "contact_duration_substeps_mean": sub / int(dcoll.sum()) if dcoll.sum() else None,
            "is": "grain_max_*: percentiles over grains (that touched one) of each grain's largest "
                  "overlap in the window; time_mean: mean overlap over sub-steps in contact",
        }
        c = stp.ph.counters
        out["substepped_grain_substeps_per_step"] = float(c[3]) / n_steps
        tm = stp.timers - timers_spin if coll_spin is not None else stp.timers
        out["timers_window"] = {"free_flight_s": float(tm[0]), "particle_collisions_s": float(tm[1]),
                                "bed_s": float(tm[2])}
        if record:
            v = np.concatenate(speeds) if speeds else np.zeros(0)
            out["approach"] = {
                "matched": matched, "begun": begun,
                "matched_fraction": matched / begun if begun else None,
                "p50": float(np.percentile(v, 50)) if len(v) else None,
                "p90": float(np.percentile(v, 90)) if len(v) else None,
                "p99": float(np.percentile(v, 99)) if len(v) else None,
                "p999": float(np.percentile(v, 99.9)) if len(v) else None,
                "max": float(v.max()) if len(v) else None,
                "mean": float(v.mean()) if len(v) else None,
            }
            out["_approach_speeds"] = v
    out["_jumps"] = jumps
    return out


def jump_stats(jumps, t_from, n_grains, rng_seed=0) -> dict:
    """H, L, U, T mean and std of the counted jumps (started at t ≥ t_from and not among a
    grain's first DISCARD), with standard errors from a bootstrap over grains."""
    sel = (jumps[:, 2] >= t_from) & (jumps[:, 1] >= DISCARD)
    j = jumps[sel]
    out = {"count": int(len(j)), "grains_with_jumps": int(len(np.unique(j[:, 0]))) if len(j) else 0}
    if len(j) < 3:
        return out
    grains, inv = np.unique(j[:, 0].astype(np.int64), return_inverse=True)
    G = len(grains)
    cnt = np.bincount(inv, minlength=G).astype(float)
    rng = np.random.default_rng(rng_seed)
    W = rng.multinomial(G, np.full(G, 1.0 / G), size=N_BOOT).astype(float)  # (B, G)
    T = j[:, 5]
    L = j[:, 3]
    cols = {"H": j[:, 4], "L": L, "U": L / T, "T": T}
    for key, x in cols.items():
        s1 = np.bincount(inv, weights=x, minlength=G)
        s2 = np.bincount(inv, weights=x * x, minlength=G)
        mean = x.mean()
        std = x.std(ddof=1)
        n_b = W @ cnt
        m_b = (W @ s1) / n_b
        v_b = (W @ s2) / n_b - m_b ** 2
        out[f"{key}_mean"] = float(mean)
        out[f"{key}_std"] = float(std)
        out[f"{key}_se"] = float(m_b.std(ddof=1))
        out[f"{key}_std_se"] = float(np.sqrt(np.maximum(v_b, 0)).std(ddof=1))
        out[f"{key}_se_iid"] = float(std / math.sqrt(len(x)))
    # flight-weighted velocity ΣL/ΣT
    sL = np.bincount(inv, weights=L, minlength=G)
    sT = np.bincount(inv, weights=T, minlength=G)
    out["U_flight_weighted"] = float(L.sum() / T.sum())
    out["U_flight_weighted_se"] = float(((W @ sL) / (W @ sT)).std(ddof=1))
    return out


# --------------------------------------------------------------------------- the study

def default_stiffness(tables) -> float:
    from saltation.case.schema import load_case

    return load_case(tables, {"run.duration": 1.0}).collision_stiffness


def point_overrides(k_default, factor, conc, seed, duration, impact_speed_default=10.0):
    return {
        "run.concentration": conc,
        "run.seed": seed,
        "run.duration": duration,
        "run.threads": 1,
        "collisions.model": "soft",
        "collisions.stiffness": k_default * factor,
        # the overlap rule's floor k ∝ impact_speed²: lowered with k (module docstring)
        "collisions.impact_speed": impact_speed_default * math.sqrt(factor) * (1 - 1e-9),
    }


def save_point(path: Path, res: dict):
    np.savez_compressed(path.with_suffix(".npz"), jumps=res.pop("_jumps"),
                        approach=res.pop("_approach_speeds", np.zeros(0)))
    path.write_text(json.dumps(res, indent=1, default=float))


QUANTS = [("H", "H/d"), ("L", "L/d"), ("U", "U/u*")]


def within_noise(a, b, key, se_key, nsig):
    if key not in a or key not in b:
        return False
    return abs(a[key] - b[key]) <= nsig * math.hypot(a[se_key], b[se_key])


def analyse(points, factors, concs, nsig=2.0):
    """Tables, and the softest factor whose H, L, U, collision rate are within nsig
    combined standard errors of every stiffer factor's at every concentration."""
    lines = []
    table_rows = []
    verdict = {}
    for conc in concs:
        lines.append(f"\n### C = {100 * conc:.2f} %\n")
        first = next((points[(conc, f)] for f in factors if (conc, f) in points), None)
        if first is None:
            continue
        lines.append(f"N = {first['n_particles']}, domain {first['domain_d'][0]:.1f} × {first['domain_d'][1]:.1f} d, "
                     f"spin-up {first['spinup_particle']:.1f} d/u*, window {first['window_particle']:.1f} d/u*\n")
        lines.append("| k_n/k_def | k_n (N/m) | sub-steps | counted jumps | H/d | σ_H | L/d | σ_L | U/u* | σ_U | "
                     "coll./grain/(d/u*) | overlap mean/p99/max (d) | wall (s) |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for fct in factors:
            p = points.get((conc, fct))
            if p is None:
                continue
            js, co, ov = p["jump_stats"], p["collisions"], p["overlap"]
            row = {"concentration": conc, "factor": fct, "stiffness_N_m": p["stiffness_N_m"],
                   "substeps": p["contact_substeps"], "n_particles": p["n_particles"], "jumps": js["count"],
                   "coll_rate": co["rate_per_grain"], "coll_rate_se": co["rate_se"],
                   "overlap_mean": ov["time_mean_over_d"], "overlap_p99": ov["grain_max_p99"],
                   "overlap_max": ov["max_over_d"], "wall_s": p["wall_s"], "wall_window_s": p["wall_window_s"],
                   "grain_substeps_per_step": p["substepped_grain_substeps_per_step"],
                   "seeds": p.get("seeds", 1)}
            for q, _ in QUANTS:
                for s in ("mean", "se", "std", "std_se"):
                    row[f"{q}_{s}"] = js.get(f"{q}_{s}")
            ap = p.get("approach") or {}
            for s in ("p50", "p90", "p99", "max", "matched_fraction"):
                row[f"approach_{s}"] = ap.get(s)
            table_rows.append(row)
            def fm(q, js=js):
                return f"{js.get(q + '_mean', math.nan):.3f} ± {js.get(q + '_se', math.nan):.3f}"

            def fs(q, js=js):
                return f"{js.get(q + '_std', math.nan):.2f} ± {js.get(q + '_std_se', math.nan):.2f}"

            om = ov["time_mean_over_d"]
            lines.append(
                f"| {fct:g} | {p['stiffness_N_m']:.3g} | {p['contact_substeps']} | {js['count']} | {fm('H')} | {fs('H')} | "
                f"{fm('L')} | {fs('L')} | {fm('U')} | {fs('U')} | {co['rate_per_grain']:.3f} ± {co['rate_se']:.3f} | "
                f"{(om or 0):.4f} / {ov['grain_max_p99']:.4f} / {ov['max_over_d']:.4f} | {p['wall_s']:.0f} |")
        lines.append("")
        lines.append("| k_n/k_def | contacts begun | matched | v_n p50 | p90 | p99 | p99.9 | max (u*) |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for fct in factors:
            p = points.get((conc, fct))
            if p is None or not p.get("approach"):
                continue
            ap = p["approach"]
            if ap["p50"] is None:
                continue
            lines.append(f"| {fct:g} | {ap['begun']} | {100 * (ap['matched_fraction'] or 0):.0f} % | {ap['p50']:.2f} | "
                         f"{ap['p90']:.2f} | {ap['p99']:.2f} | {ap['p999']:.2f} | {ap['max']:.2f} |")
    # verdict: factor passes when it and every stiffer factor agree pairwise
    ok = {}
    for fct in factors:
        fails = []
        for conc in concs:
            p = points.get((conc, fct))
            if p is None:  # not run at this C: not a candidate, but no test fails
                continue
            for stiffer in [g for g in factors if g > fct]:
                s = points.get((conc, stiffer))
                if s is None:
                    continue
                for q, _ in QUANTS:
                    if not within_noise(p["jump_stats"], s["jump_stats"], f"{q}_mean", f"{q}_se", nsig):
                        fails.append(f"C={100 * conc:.2f}% {q} vs ×{stiffer:g}")
                if not within_noise(p["collisions"], s["collisions"], "rate_per_grain", "rate_se", nsig):
                    fails.append(f"C={100 * conc:.2f}% collision rate vs ×{stiffer:g}")
        ok[fct] = fails
    complete = {f for f in factors if all((c, f) in points for c in concs)}
    chosen = None
    for fct in sorted(factors, reverse=True):
        if ok[fct]:
            break
        if fct in complete:
            chosen = fct
    verdict = {"nsig": nsig, "fails": ok, "chosen_factor": chosen,
               "run_at_every_C": sorted(complete)}
    lines.append(f"\nWithin {nsig:g} combined standard errors of every stiffer k (H, L, U, collision rate, all C):")
    for fct in factors:
        lines.append(f"* ×{fct:g}: " + ("pass" if not ok[fct] else "FAIL — " + "; ".join(ok[fct])))
    lines.append(f"\nSoftest k run at every C that passes, with every stiffer k passing too: k_n = k_default × {chosen}"
                 f" (k values run at only some C count as references only)")
    return "\n".join(lines), table_rows, verdict


def plot(table_rows, concs, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [("H", "H: % from k_default"), ("L", "L: % from k_default"), ("U", "U: % from k_default"),
            ("coll_rate", "collision rate: % from k_default"),
            ("overlap_p99", "p99 of grain max overlap (d)"),
            ("grain_substeps_per_step", "grain-sub-steps per step (cost)")]
    fig, axs = plt.subplots(2, 3, figsize=(13, 7))
    for ax, (k, lab) in zip(axs.flat, keys):
        for conc in concs:
            rs = sorted([r for r in table_rows if r["concentration"] == conc and r.get("H_mean") is not None],
                        key=lambda r: r["factor"])
            ref = next((r for r in rs if r["factor"] == 1.0), None)
            if not rs or ref is None:
                continue
            x = [r["factor"] for r in rs]
            if k in ("H", "L", "U", "coll_rate"):
                m, se = (f"{k}_mean", f"{k}_se") if k != "coll_rate" else ("coll_rate", "coll_rate_se")
                y = [100 * (r[m] / ref[m] - 1) for r in rs]
                e = [200 * r[se] / ref[m] for r in rs]
                ax.axhline(0, color="0.6", lw=0.8)
            else:
                y = [r[k] for r in rs]
                e = None
            ax.errorbar(x, y, yerr=e, marker="o", capsize=3, label=f"C = {100 * conc:.2f} %")
        ax.set_xscale("log", base=2)
        if k == "grain_substeps_per_step":
            ax.set_yscale("log")
        ax.set_xlabel("k_n / k_default")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axs.flat[0].legend(fontsize=8)
    fig.suptitle("Soft-contact stiffness sensitivity (error bars: ±2 SE, by grain × run-to-run inflation)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="/tmp/saltation-studies/stiffness")
    ap.add_argument("--conc", type=float, nargs="+", default=[0.0052, 0.0207, 0.0394])
    ap.add_argument("--factors", type=float, nargs="+", default=[1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--duration", type=float, default=1.0, help="s simulated per run")
    ap.add_argument("--spinup", type=float, default=0.5, help="s before statistics are taken")
    ap.add_argument("--shrink", type=float, default=1.0, help="x and z of the reduced domain × this")
    ap.add_argument("--dt", type=float, default=0.02, help="run.dt_particle (d/u*)")
    ap.add_argument("--nsig", type=float, default=2.0)
    ap.add_argument("--no-record", action="store_true", help="skip the approach-speed recorder")
    ap.add_argument("--analyse-only", action="store_true")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    tables = base_tables(a.shrink)
    tables["run"]["dt_particle"] = a.dt
    k_def = default_stiffness(tables)
    print(f"k_default = {k_def:.6g} N/m (overlap rule: max_overlap 0.01 d at impact_speed 10 u*)", flush=True)
    if not a.analyse_only:
        # cheapest first: dilute before dense, soft before stiff
        for seed in a.seeds:
            for conc in a.conc:
                for fct in a.factors:
                    path = out / f"C{conc:.4f}_k{fct:.4f}_s{seed}.json"
                    if path.exists():
                        continue
                    label = path.stem
                    ov = point_overrides(k_def, fct, conc, seed, a.duration)
                    t0 = time.perf_counter()
                    res = simulate(tables, ov, a.spinup, record=not a.no_record, label=label)
                    res["factor"], res["seed"], res["shrink"] = fct, seed, a.shrink
                    save_point(path, res)
                    js = res["jump_stats"]
                    print(f"{label}: N={res['n_particles']} sub={res['contact_substeps']} jumps={js['count']} "
                          f"H={js.get('H_mean', float('nan')):.3f} L={js.get('L_mean', float('nan')):.3f} "
                          f"U={js.get('U_mean', float('nan')):.3f} coll={res['collisions']['rate_per_grain']:.3f} "
                          f"approach p99={res.get('approach', {}).get('p99')} "
                          f"wall={time.perf_counter() - t0:.0f}s", flush=True)
    points = {}
    for conc in a.conc:
        for fct in a.factors:
            found = [json.loads((out / f"C{conc:.4f}_k{fct:.4f}_s{s}.json").read_text()) for s in a.seeds
                     if (out / f"C{conc:.4f}_k{fct:.4f}_s{s}.json").exists()]
            if found:
                points[(conc, fct)] = merge_seeds(found, out, conc, fct, a.seeds)
    inflation = seed_inflation(out, a.conc, a.factors, a.seeds)
    for (conc, _fct), p in points.items():
        r = inflation.get(conc, {}).get("factor", 1.0)
        for q, _ in QUANTS:
            if f"{q}_se" in p["jump_stats"]:
                p["jump_stats"][f"{q}_se_grains"] = p["jump_stats"][f"{q}_se"]
                p["jump_stats"][f"{q}_se"] *= r
        p["collisions"]["rate_se_grains"] = p["collisions"]["rate_se"]
        p["collisions"]["rate_se"] *= r
    text, rows, verdict = analyse(points, a.factors, a.conc, a.nsig)
    verdict["seed_inflation"] = inflation
    header = (f"k_default = {k_def:.6g} N/m; τ*/τ*c = {TAU_RATIO}; dt = {a.dt} d/u*; seeds {a.seeds}; "
              f"duration {a.duration} s, spin-up {a.spinup} s; domain shrink {a.shrink}\n"
              "Standard errors: bootstrap over grains × the run-to-run inflation factor r of each C "
              "(r² = mean over repeated (k, seed) pairs and H, L, U, collision rate of d²/(SE₁² + SE₂²), "
              "at least 1): " + ", ".join(f"C = {100 * c:.2f} %: r = {v['factor']:.2f} from {v['pairs']} pairs"
                                          for c, v in inflation.items()))
    print(header)
    print(text)
    (out / "stiffness.md").write_text(header + "\n" + text + "\n")
    import csv

    if rows:
        with open(out / "stiffness.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        plot(rows, a.conc, out / "stiffness.png")
    (out / "stiffness.json").write_text(json.dumps({"k_default_N_m": k_def, "args": vars(a), "rows": rows,
                                                    "verdict": verdict}, indent=1, default=float))
    return verdict


def seed_inflation(out, concs, factors, seeds):
    """Run-to-run scatter against the by-grain bootstrap SE: for each C, r² = mean of
    (x_s1 − x_s2)² / (SE_s1² + SE_s2²) over every k run with two or more seeds (consecutive
    seed pairs) and over H, L, U and the collision rate; r = max(1, √r²). Grains of one
    run share the flow and collide, so the bootstrap over grains can understate the noise."""
    res = {}
    for conc in concs:
        ratios = []
        for fct in factors:
            found = [json.loads((out / f"C{conc:.4f}_k{fct:.4f}_s{s}.json").read_text()) for s in seeds
                     if (out / f"C{conc:.4f}_k{fct:.4f}_s{s}.json").exists()]
            for x, y in zip(found[:-1], found[1:]):
                for q, _ in QUANTS:
                    a, b = x["jump_stats"], y["jump_stats"]
                    ratios.append((a[f"{q}_mean"] - b[f"{q}_mean"]) ** 2 / (a[f"{q}_se"] ** 2 + b[f"{q}_se"] ** 2))
                a, b = x["collisions"], y["collisions"]
                ratios.append((a["rate_per_grain"] - b["rate_per_grain"]) ** 2 / (a["rate_se"] ** 2 + b["rate_se"] ** 2))
        if ratios:
            res[conc] = {"factor": max(1.0, math.sqrt(float(np.mean(ratios)))), "pairs": len(ratios) // 4,
                         "raw": math.sqrt(float(np.mean(ratios)))}
        else:
            res[conc] = {"factor": 1.0, "pairs": 0, "raw": None}
    return res


def merge_seeds(found, out, conc, fct, seeds):
    """One point from one or more seeds: jumps and approach speeds pooled (grains of
    different seeds are different clusters), collision rates averaged."""
    if len(found) == 1:
        return found[0]
    p = dict(found[0])
    jumps, speeds = [], []
    n0 = 0
    for s, f in zip([s for s in seeds if (out / f"C{conc:.4f}_k{fct:.4f}_s{s}.json").exists()], found):
        z = np.load(out / f"C{conc:.4f}_k{fct:.4f}_s{s}.npz")
        j = z["jumps"].copy()
        j[:, 0] += n0
        n0 += f["n_particles"]
        jumps.append(j)
        speeds.append(z["approach"])
    p["jump_stats"] = jump_stats(np.concatenate(jumps), found[0]["spinup_particle"], n0)
    rates = [f["collisions"]["rate_per_grain"] for f in found]
    ses = [f["collisions"]["rate_se"] for f in found]
    p["collisions"] = {"rate_per_grain": float(np.mean(rates)),
                       "rate_se": float(math.sqrt(sum(s * s for s in ses)) / len(ses)),
                       "seed_values": rates}
    p["wall_s"] = float(np.mean([f["wall_s"] for f in found]))
    p["wall_window_s"] = float(np.mean([f["wall_window_s"] for f in found]))
    v = np.concatenate(speeds)
    if len(v):
        ap = dict(found[0]["approach"])
        ap.update(p50=float(np.percentile(v, 50)), p90=float(np.percentile(v, 90)), p99=float(np.percentile(v, 99)),
                  p999=float(np.percentile(v, 99.9)), max=float(v.max()),
                  begun=sum(f["approach"]["begun"] for f in found), matched=sum(f["approach"]["matched"] for f in found))
        ap["matched_fraction"] = ap["matched"] / ap["begun"] if ap["begun"] else None
        p["approach"] = ap
    p["seeds"] = len(found)
    return p


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
