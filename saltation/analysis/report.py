"""``saltation analyze PATH``: tables, figures and one self-contained HTML report.

A **run directory** (summary.json, jumps.parquet, variance.parquet and/or tracks.parquet)
gives: the jump statistics table, the jump length / height / velocity distributions, the
variance curves with the fitted slopes (paper Fig. 8), the collision and cost figures of
summary.json.

A **sweep directory** (``OUT/cases/NAME/`` run directories; OUT/results.parquet is not
needed) gives, per τ*/τ*c: jump statistics vs concentration (Fig. 5), jump-velocity box
plots and grain-velocity distributions (Fig. 6), collisions and cost vs N (Fig. 7, with
Table 3 side by side with the paper's CPU times), variance curves (Fig. 8), γ vs
concentration for both ranges and directions (Fig. 9, with Tables 4–7 side by side with
the paper's values and the differences). Single-grain validation results
(``saltation validate nino-garcia`` output: validation.csv, validation.png, ablation.csv)
are included when a validation directory is given or found (DIR/validation,
DIR/../validation).

A **tracks file** (CSV or Parquet: particle, t in d/u*, x and z unwrapped in d, y
optional — e.g. grains tracked in a flume, or another model's output;
``diffusion.read_tracks_file`` explains the columns and the unit options) gives the
diffusion part: the exponents table, the crossover of the variance curves, the variance
figure with the fitted ranges and the two-segment fit, in ``<stem>_analysis/`` next to the
file (or ``--out``). ``--origins 1`` takes the statistics from one time origin (a tracer
release at the first origin) instead of 8 spread over the record.

Where the variance curve bends a second time beyond the intermediate range
(``diffusion.global_bend``), the **global** range is fitted too and shown beside the others:
its rows in the tables, its window and fitted line in the variance figure with the
three-segment fit and t_g, the fit itself in ``global_bend.csv``; otherwise the report
says why no global range is seen.

Everything lands in ``DIR/analysis`` (or ``--out``): CSV tables, PNG figures, report.html
(figures embedded as base64, no external files). A range that cannot be fitted appears
with the reason, never as a bare NaN.
"""
from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from . import reference as ref
from .diffusion import ALL_RANGES, DISCARDED_JUMPS, RANGE_NAMES, TRACK_COLUMNS, exponents, read_tracks_file
from .variance import N_ORIGINS, AnalysisError

JUMP_QUANTITIES = (("length", "L", "d"), ("height", "H", "d"), ("duration", "T", "d/u*"), ("velocity", "U", "u*"))


# --------------------------------------------------------------------------- reading
def is_run_dir(path: Path) -> bool:
    return (path / "summary.json").exists()


def find_runs(sweep: Path) -> list[Path]:
    """Run directories of a sweep: OUT/cases/NAME/ (or OUT/NAME/) holding summary.json."""
    base = sweep / "cases" if (sweep / "cases").is_dir() else sweep
    return sorted(p for p in base.iterdir() if p.is_dir() and is_run_dir(p))


def read_summary(run_dir: Path) -> dict:
    return json.loads((run_dir / "summary.json").read_text())


def counted_jumps(run_dir: Path) -> pd.DataFrame:
    path = run_dir / "jumps.parquet"
    if not path.exists():
        return pd.DataFrame(columns=["particle", "jump", "t_start", "length", "height", "duration", "velocity"])
    j = pd.read_parquet(path)
    return j[j["jump"] >= DISCARDED_JUMPS]


def collisions_model(run_dir: Path) -> str | None:
    """[collisions] model of the run's config.toml ("soft" | "hard" | "off"), None if unknown."""
    import tomllib

    try:
        return tomllib.loads((run_dir / "config.toml").read_text()).get("collisions", {}).get("model")
    except (OSError, tomllib.TOMLDecodeError):
        return None


def jump_table(jumps: pd.DataFrame) -> pd.DataFrame:
    """Mean, std, median, 10/90 % quantiles of L, H, T, U over the counted jumps."""
    rows = []
    for col, sym, unit in JUMP_QUANTITIES:
        v = jumps[col].to_numpy() if len(jumps) else np.zeros(0)
        if len(v) == 0:
            rows.append({"quantity": sym, "unit": unit, "n": 0, "note": "no counted jumps (each grain's first "
                         f"{DISCARDED_JUMPS} are dropped): run longer"})
            continue
        rows.append({"quantity": sym, "unit": unit, "n": len(v), "mean": v.mean(), "std": v.std(ddof=1) if len(v) > 1 else 0.0,
                     "median": np.median(v), "p10": np.quantile(v, 0.1), "p90": np.quantile(v, 0.9), "note": ""})
    return pd.DataFrame(rows)


def diffusion_of(run_dir: Path):
    """exponents() of a run, never raising: (result or None, problems dict)."""
    try:
        res = exponents(run_dir, strict=False)
        return res, dict(res.problems)
    except AnalysisError as exc:
        return None, {"all": str(exc)}


def case_row(run_dir: Path) -> dict:
    """One sweep-table row: the case, its jump, collision, cost and γ numbers."""
    s = read_summary(run_dir)
    j, col, tim = s.get("jumps", {}), s.get("collisions", {}), s.get("timing", {})
    row = {
        "case": run_dir.name, "status": s.get("status"), "n_particles": s.get("n_particles"),
        "collisions_model": collisions_model(run_dir),
        "concentration_pct": 100 * s["concentration"] if s.get("concentration") is not None else None,
        "tau_ratio": s.get("tau_ratio"), "simulated_time_s": s.get("simulated_time_s"),
        "simulated_time_particle": s.get("simulated_time_particle"),
        "jumps": j.get("count"), "H_mean": j.get("H_mean"), "H_std": j.get("H_std"), "L_mean": j.get("L_mean"),
        "L_std": j.get("L_std"), "U_mean": j.get("U_mean"), "U_std": j.get("U_std"),
        "collisions_pp": col.get("particle_particle"), "collisions_bed": col.get("bed"),
        "collisions_pp_per_particle": (col.get("particle_particle") or 0) / s["n_particles"] if s.get("n_particles") else None,
        "wall_s": tim.get("wall_s"), "free_flight_s": tim.get("free_flight_s"), "bed_s": tim.get("bed_s"),
        "particle_collisions_s": tim.get("particle_collisions_s"), "threads": tim.get("threads"),
        "particle_steps_per_s": s.get("particle_steps_per_s"),
    }
    dur = row["simulated_time_particle"]
    if row["collisions_pp"] is not None and dur:
        row["collisions_pp_per_particle_per_time"] = row["collisions_pp"] / s["n_particles"] / dur
    res, problems = diffusion_of(run_dir)
    row["jump_duration"] = res["jump_duration"] if res is not None else None
    cr = res["crossover"] if res is not None else None
    row["t_c"] = cr["t_c"] if cr and cr["found"] else None
    row["t_c_ci"] = f"{cr['ci'][0]:.3g}–{cr['ci'][1]:.3g}" if cr and cr["found"] and np.isfinite(cr["ci"][0]) else None
    row["windows_from"] = "; ".join(f"{k}: {v}" for k, v in res["windows_from"].items()) if res is not None else None
    gb = res["global_bend"] if res is not None else None
    row["t_g"] = gb["t_g"] if gb and gb["found"] else None
    row["t_g_ci"] = f"{gb['ci'][0]:.3g}–{gb['ci'][1]:.3g}" if gb and gb["found"] and np.isfinite(gb["ci"][0]) else None
    row["global_range"] = ("seen" if gb["found"] else f"not seen: {gb['reason']}") if gb else None
    for name in ALL_RANGES:
        for d in ("x", "z"):
            e = res.get(name) if res is not None else None
            row[f"gamma_{name}_{d}"] = e[f"gamma_{d}"] if e else None
            row[f"ci_{name}_{d}"] = f"{e[f'ci_{d}'][0]:.3f}–{e[f'ci_{d}'][1]:.3f}" if e else None
        e = res.get(name) if res is not None else None
        row[f"window_{name}"] = f"{e['t_min']:.3g}–{e['t_max']:.3g}" if e else None
    row["diffusion_problems"] = "; ".join(f"{k}: {v}" for k, v in problems.items())
    return row


# --------------------------------------------------------------------------- figures
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path


def fig_jump_distributions(jumps: pd.DataFrame, path: Path, title=""):
    plt = _plt()
    fig, axes = plt.subplots(1, 4, figsize=(13, 3.2))
    for ax, (col, sym, unit) in zip(axes, JUMP_QUANTITIES):
        v = jumps[col].to_numpy()
        if len(v):
            top = np.quantile(v, 0.995)  # the range of 99.5 % of the jumps; the rest is counted in the table
            ax.hist(v, bins=40, range=(min(v.min(), 0.0), top), density=True, color="#4477aa", alpha=0.85)
            ax.axvline(v.mean(), color="k", lw=1, ls="--", label=f"mean {v.mean():.2f}")
            ax.legend(fontsize=8)
        ax.set_xlabel(f"{sym} ({unit})")
    axes[0].set_ylabel("probability density")
    fig.suptitle(title or f"jump statistics ({len(jumps)} counted jumps)", fontsize=10)
    return _save(fig, path)


def fig_variance(res, path: Path, title=""):
    """Fig. 8: ⟨X′²⟩, ⟨Z′²⟩ against t on log–log axes with the fitted power laws."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    c = res.curves
    for ax, d, label in ((axes[0], "x", "⟨X′²⟩"), (axes[1], "z", "⟨Z′²⟩")):
        ax.loglog(c["t"], c[f"var_{d}"], "o", ms=3, color="#555555", label=label)
        for name, color in (("local", "#cc3311"), ("intermediate", "#0077bb"), ("global", "#009944")):
            e = res.get(name)
            if not e:
                continue
            tt = np.geomspace(e["t_min"], e["t_max"], 20)
            g, a = e[f"gamma_{d}"], e[f"alpha_{d}"]
            lo, hi = e[f"ci_{d}"]
            ax.loglog(tt, a * tt ** (2 * g), "-", lw=2, color=color,
                      label=f"{name}: γ{d} = {g:.2f} [{lo:.2f}, {hi:.2f}]")
        cr = res.get("crossover" if d == "x" else "crossover_z")
        gb = res.get("global_bend") if d == "x" else None
        if gb and gb.get("found"):
            _draw_three_segments(ax, gb, "crossover" in res.get("windows_from", {}).values())
        elif cr and cr.get("found"):
            tc, (lo, hi) = cr["t_c"], cr["ci"]
            for a0, a1, g in ((cr["fit_range"][0], tc, cr["gamma_before"]), (tc, cr["fit_range"][1], cr["gamma_after"])):
                tt = np.geomspace(a0, a1, 20)
                ax.loglog(tt, cr["var_c"] * (tt / tc) ** (2 * g), "--", lw=1, color="k", zorder=3,
                          label="two-segment fit" if a0 < tc else None)
            if np.isfinite(lo):
                ax.axvspan(lo, hi, color="#999999", alpha=0.25, lw=0)
            sets = d == "x" and "crossover" in res.get("windows_from", {}).values()
            ci = f" [{lo:.2f}, {hi:.2f}]" if np.isfinite(lo) else ""
            ax.axvline(tc, color="k", ls="-", lw=0.8,
                       label=f"t_c = {tc:.2f}{ci} d/u*" + (" (sets the ranges)" if sets else " (not used)"))
        if res.get("jump_duration"):
            src = res.get("jump_duration_from")
            ax.axvline(res["jump_duration"], color="k", ls=":", lw=1,
                       label=f"T_J = {res['jump_duration']:.2f} d/u*" + (f" ({src})" if src else ""))
        ax.set_xlabel("t (d/u*)")
        ax.set_ylabel(f"{label} (d²)")
        ax.legend(fontsize=8)
    fig.suptitle(title or "displacement variances (Nikora et al. 2002)", fontsize=10)
    return _save(fig, path)


def _draw_three_segments(ax, gb: dict, sets: bool):
    """The three-segment fit of ⟨X′²⟩ (dashed), t_c and t_g with their 95 % intervals."""
    tc, tg = gb["t_c"], gb["t_g"]
    g1, g2, g3 = gb["gammas"]
    for a0, a1, g, ref_t, ref_v in ((gb["fit_range"][0], tc, g1, tc, gb["var_c"]), (tc, tg, g2, tc, gb["var_c"]),
                                    (tg, gb["fit_range"][1], g3, tg, gb["var_g"])):
        tt = np.geomspace(a0, a1, 20)
        ax.loglog(tt, ref_v * (tt / ref_t) ** (2 * g), "--", lw=1, color="k", zorder=3,
                  label="three-segment fit" if a0 < tc else None)
    for t0, (lo, hi), name, ls in ((tc, gb["t_c_ci"], "t_c", "-"), (tg, gb["ci"], "t_g", "-.")):
        if np.isfinite(lo):
            ax.axvspan(lo, hi, color="#999999", alpha=0.25, lw=0)
        ci = f" [{lo:.3g}, {hi:.3g}]" if np.isfinite(lo) else ""
        what = " (sets the ranges)" if sets or name == "t_g" else " (not used)"
        ax.axvline(t0, color="k", ls=ls, lw=0.8, label=f"{name} = {t0:.3g}{ci} d/u*{what}")


def fig_run_costs(summary: dict, path: Path):
    plt = _plt()
    t = summary.get("timing", {})
    col = summary.get("collisions", {})
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    parts = {"free flight": t.get("free_flight_s"), "bed": t.get("bed_s"), "grain contacts": t.get("particle_collisions_s"),
             "compile": t.get("compile_s")}
    parts = {k: v for k, v in parts.items() if v}
    axes[0].bar(list(parts), list(parts.values()), color="#4477aa")
    axes[0].set_ylabel("wall time (s)")
    axes[0].set_title(f"cost (wall {t.get('wall_s', 0):.1f} s)", fontsize=9)
    cc = {"grain–grain": col.get("particle_particle") or 0, "bed": col.get("bed") or 0}
    axes[1].bar(list(cc), list(cc.values()), color="#ee7733")
    axes[1].set_ylabel("collisions in the run (total)")
    n = summary.get("n_particles") or 0
    bed_pp = col.get("bed_per_particle", (col.get("bed") or 0) / n if n else 0.0)
    axes[1].set_title(f"per grain: {col.get('per_particle') or 0:.1f} grain–grain, {bed_pp or 0:.1f} bed collisions",
                      fontsize=9)
    return _save(fig, path)


def _by_tau(df):
    yield from df.sort_values("concentration_pct").groupby("tau_ratio")


def fig_jumps_vs_concentration(df: pd.DataFrame, path: Path):
    """Fig. 5: mean ± std of H, L, U against C."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, (q, unit) in zip(axes, (("H", "d"), ("L", "d"), ("U", "u*"))):
        for tau, g in _by_tau(df):
            ax.errorbar(g["concentration_pct"], g[f"{q}_mean"], yerr=g[f"{q}_std"], marker="o", capsize=3,
                        label=f"τ*/τ*c = {tau:.2f}")
        ax.set_xscale("log")
        ax.set_xlabel("C (%)")
        ax.set_ylabel(f"{q} ({unit})")
        ax.legend(fontsize=8)
    fig.suptitle("jump height, length and velocity vs concentration (cf. paper Fig. 5)", fontsize=10)
    return _save(fig, path)


def fig_velocity_boxes(runs: list[Path], df: pd.DataFrame, path: Path):
    """Fig. 6: jump-velocity box plots per case, and the grains' streamwise velocity
    distribution from the tracks (where written)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4))
    data, labels = [], []
    order = df.sort_values(["tau_ratio", "concentration_pct"])["case"].tolist()
    by_name = {r.name: r for r in runs}
    no_tracks = []
    for name in order:
        j = counted_jumps(by_name[name])
        row = df.set_index("case").loc[name]
        data.append(j["velocity"].to_numpy())
        labels.append(f"{row['concentration_pct']:.2g}%\n{row['tau_ratio']:.2f}")
        tracks = by_name[name] / "tracks.parquet"
        if not tracks.exists():
            no_tracks.append(name)
        else:
            u = pd.read_parquet(tracks, columns=["u", "y"])
            u = u[u["y"] > 0.55]["u"].to_numpy()  # grains in flight (centre above the resting height 0.5 d)
            if len(u):
                axes[1].hist(u, bins=60, density=True, histtype="step", lw=1.3, label=labels[-1].replace("\n", ", τ*/τ*c "))
    axes[0].boxplot(data, showfliers=False)
    axes[0].set_xticks(range(1, len(labels) + 1), labels, fontsize=7)
    axes[0].set_ylabel("jump velocity U = L/T (u*)")
    axes[0].set_xlabel("C, τ*/τ*c")
    axes[1].set_xlabel("grain streamwise velocity u (u*), grains in flight")
    axes[1].set_ylabel("probability density")
    if axes[1].get_legend_handles_labels()[0]:
        axes[1].legend(fontsize=7)
    if no_tracks:
        why = (f"no tracks.parquet in {len(no_tracks)} of {len(order)} case(s)"
               + (f" ({', '.join(no_tracks[:4])}{', …' if len(no_tracks) > 4 else ''})" if len(no_tracks) < len(order) else "")
               + ":\nthe grain-velocity distribution needs the tracks;\nrun with output.tracks = true")
        empty = not axes[1].get_legend_handles_labels()[0]
        axes[1].text(0.5, 0.5 if empty else 0.97, why, transform=axes[1].transAxes, ha="center",
                     va="center" if empty else "top", fontsize=9 if empty else 7, color="#a33")
        if empty:
            axes[1].set_yticks([])
    fig.suptitle("velocity distributions (cf. paper Fig. 6)", fontsize=10)
    return _save(fig, path)


def fig_collisions_cost(df: pd.DataFrame, path: Path):
    """Fig. 7: collisions per grain, total, per grain per unit time, and cost vs N."""
    plt = _plt()
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.6))
    for tau, g in _by_tau(df):
        n = g["n_particles"]
        lab = f"τ*/τ*c = {tau:.2f}"
        axes[0].plot(n, g["collisions_pp_per_particle"], "o-", label=lab)
        axes[1].plot(n, g["collisions_pp"], "o-", label=lab)
        axes[2].plot(n, g.get("collisions_pp_per_particle_per_time", np.nan * n), "o-", label=lab)
        scaled = g["wall_s"] / g["simulated_time_s"] * ref.SIMULATED_S
        axes[3].plot(n, scaled, "o-", label=f"ours scaled to 200 s simulated, {lab}")
    pn = np.array(ref.N_PARTICLES)
    axes[3].plot(pn, [ref.CPU_TIME_S[k] for k in pn], "ks--", label="paper (200 s simulated)")
    for ax, yl in zip(axes, ("grain–grain collisions per grain", "total grain–grain collisions",
                             "collisions per grain per d/u*", "wall time for 200 s simulated (s)")):
        ax.set_xlabel("N")
        ax.set_ylabel(yl)
        ax.set_xscale("log")
        ax.legend(fontsize=7)
    axes[3].set_yscale("log")
    fig.suptitle("collisions and cost vs number of grains (cf. paper Fig. 7)", fontsize=10)
    return _save(fig, path)


def _why(df: pd.DataFrame, cases: list) -> str:
    """The diffusion problem of the first of ``cases``, wrapped for a figure."""
    import textwrap

    probs = df.set_index("case")["diffusion_problems"] if "diffusion_problems" in df else {}
    why = str(probs.get(cases[0], "") or "no diffusion data").removeprefix("all: ")
    return textwrap.fill(why if len(why) <= 200 else why[:197] + "…", 60)


def fig_variance_sweep(results: dict, df: pd.DataFrame, path: Path):
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name in df.sort_values(["tau_ratio", "concentration_pct"])["case"]:
        res = results.get(name)
        if res is None:
            continue
        row = df.set_index("case").loc[name]
        for ax, d in zip(axes, ("x", "z")):
            ax.loglog(res.curves["t"], res.curves[f"var_{d}"], "-", lw=1.2,
                      label=f"C = {row['concentration_pct']:.2g} %, τ*/τ*c = {row['tau_ratio']:.2f}")
    missing = [n for n in df["case"] if results.get(n) is None]
    for ax, d in zip(axes, ("X", "Z")):
        ax.set_xlabel("t (d/u*)")
        ax.set_ylabel(f"⟨{d}′²⟩ (d²)")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        if missing:
            empty = len(missing) == len(df)
            ax.text(0.5, 0.5 if empty else 0.03, f"no variance curves for {len(missing)} of {len(df)} case(s)"
                    + ("" if empty else f" ({', '.join(missing[:4])}{', …' if len(missing) > 4 else ''})")
                    + ":\n" + _why(df, missing),
                    transform=ax.transAxes, ha="center", va="center" if empty else "bottom",
                    fontsize=9 if empty else 7, color="#a33")
    fig.suptitle("displacement variances of every case (cf. paper Fig. 8)", fontsize=10)
    return _save(fig, path)


def fig_gamma(df: pd.DataFrame, path: Path):
    """Fig. 9: γ vs C, both ranges and directions, ours (95 % bootstrap bars) and the paper's."""
    plt = _plt()
    paper = ref.gamma_table()
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    colors = {1.79: "#0077bb", 2.43: "#cc3311", 2.67: "#009988"}
    for i, name in enumerate(RANGE_NAMES):
        for k, d in enumerate(("x", "z")):
            ax = axes[k, i]
            for tau, g in _by_tau(df):
                col = colors.get(min(colors, key=lambda t: abs(t - tau)), "k")
                y = pd.to_numeric(g[f"gamma_{name}_{d}"], errors="coerce")
                ok = y.notna()
                if ok.any():
                    lo = g.loc[ok, f"ci_{name}_{d}"].str.split("–").str[0].astype(float)
                    hi = g.loc[ok, f"ci_{name}_{d}"].str.split("–").str[1].astype(float)
                    ax.errorbar(g.loc[ok, "concentration_pct"], y[ok], yerr=[y[ok] - lo, hi - y[ok]], marker="o",
                                capsize=3, color=col, label=f"ours τ*/τ*c = {tau:.2f}")
            for tau, p in paper[(paper["range"] == name) & (paper["direction"] == d)].groupby("tau_ratio"):
                ax.plot(p["concentration_pct"], p["gamma"], "--", marker="s", ms=3, color=colors[tau], alpha=0.6,
                        label=f"paper {tau:.2f}")
            ax.axhline(0.5 if name == "intermediate" else 1.0, color="grey", lw=0.8)
            ax.set_xscale("log")
            ax.set_title(f"{name} γ{d} (paper Table {ref.TABLE_NUMBER[(name, d)]})", fontsize=9)
            ax.set_xlabel("C (%)")
            ax.set_ylabel(f"γ{d}")
            ax.legend(fontsize=6)
    fig.suptitle("diffusion exponents vs concentration (cf. paper Fig. 9)", fontsize=10)
    return _save(fig, path)


# --------------------------------------------------------------------------- tables
def gamma_vs_paper(df: pd.DataFrame) -> pd.DataFrame:
    """Tables 4–7 side by side: our γ (and 95 % interval) next to the paper's, with the difference."""
    paper = ref.gamma_table().set_index(["range", "direction", "tau_ratio", "concentration_pct"])["gamma"]
    rows = []
    for _, r in df.iterrows():
        ptau, pc, why = ref.match_case(r["tau_ratio"], r["concentration_pct"])
        for name in RANGE_NAMES:
            for d in ("x", "z"):
                ours = r.get(f"gamma_{name}_{d}")
                row = {"table": ref.TABLE_NUMBER[(name, d)], "range": name, "direction": d, "case": r["case"],
                       "tau_ratio": r["tau_ratio"], "concentration_pct": r["concentration_pct"],
                       "n_particles": r["n_particles"], "gamma_ours": ours, "ci95_ours": r.get(f"ci_{name}_{d}"),
                       "window_d_u*": r.get(f"window_{name}"), "paper_tau_ratio": ptau, "paper_concentration_pct": pc,
                       "gamma_paper": None, "difference": None, "note": why}
                if pc is not None:
                    row["gamma_paper"] = float(paper[(name, d, ptau, pc)])
                    if ours is not None and not pd.isna(ours):
                        row["difference"] = ours - row["gamma_paper"]
                if ours is None or pd.isna(ours):
                    row["note"] = (row["note"] + "; " if row["note"] else "") + "not fitted: " + (
                        r.get("diffusion_problems") or "no diffusion data")
                rows.append(row)
    return pd.DataFrame(rows).sort_values(["table", "tau_ratio", "concentration_pct"]).reset_index(drop=True)


def cost_vs_paper(df: pd.DataFrame) -> pd.DataFrame:
    """Table 3 side by side: our wall time, and scaled to the paper's 200 s simulated,
    next to the paper's CPU time at the nearest N (within 25 %) and at the paper case of
    the same concentration (the paper's domain holds more grains at a given C)."""
    rows = []
    for _, r in df.sort_values("n_particles").iterrows():
        n = r["n_particles"]
        near = min(ref.N_PARTICLES, key=lambda k: abs(math.log(k / n)))
        match = abs(near / n - 1) <= 0.25
        sim = r["simulated_time_s"]
        _, pc, _ = ref.match_case(r["tau_ratio"], r["concentration_pct"])
        n_at_c = ref.N_PARTICLES[ref.CONCENTRATIONS_PCT.index(pc)] if pc is not None else None
        rows.append({"case": r["case"], "n_particles": n, "tau_ratio": r["tau_ratio"],
                     "concentration_pct": r["concentration_pct"], "simulated_s": sim,
                     "wall_s": r["wall_s"], "threads": r["threads"],
                     "wall_s_per_simulated_s": r["wall_s"] / sim if sim else None,
                     "wall_s_scaled_to_200s": r["wall_s"] / sim * ref.SIMULATED_S if sim else None,
                     "paper_N": near if match else None, "paper_cpu_s_200s": ref.CPU_TIME_S[near] if match else None,
                     "paper_N_same_C": n_at_c, "paper_cpu_s_200s_same_C": ref.CPU_TIME_S[n_at_c] if n_at_c else None,
                     "particle_steps_per_s": r["particle_steps_per_s"],
                     "note": "" if match else f"no paper N within 25 % (nearest {near})"})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- HTML
def _img(path: Path) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode()
    return f'<img alt="{html.escape(path.name)}" src="data:image/png;base64,{data}" style="max-width:100%">'


def _table(df: pd.DataFrame) -> str:
    return df.to_html(index=False, float_format=lambda v: f"{v:.4g}", na_rep="—", border=0, classes="t")


CSS = """body{font-family:sans-serif;max-width:1300px;margin:2em auto;color:#222}
table.t{border-collapse:collapse;font-size:12px;margin:0.5em 0 1.5em}table.t td,table.t th{border:1px solid #ccc;padding:2px 6px}
table.t th{background:#eef}h2{border-bottom:1px solid #aaa}.note{color:#a33}"""


def _html(title: str, sections: list[tuple[str, list[str]]]) -> str:
    body = [f"<h1>{html.escape(title)}</h1>"]
    for head, parts in sections:
        body.append(f"<h2>{html.escape(head)}</h2>")
        body.extend(parts)
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>")


def _p(text: str, cls="") -> str:
    return f"<p class='{cls}'>{html.escape(text)}</p>"


def _validation_dir(root: Path, given) -> Path | None:
    if given:
        p = Path(given)
        if not (p / "validation.csv").exists():
            raise AnalysisError(f"validation directory {p} has no validation.csv (write one with "
                                f"`saltation validate nino-garcia --out {p}`)")
        return p
    for p in (root / "validation", root.parent / "validation"):
        if (p / "validation.csv").exists():
            return p
    return None


def _validation_section(vdir: Path | None) -> list[str]:
    if vdir is None:
        return [_p("No single-grain validation directory given or found (DIR/validation, DIR/../validation); "
                   "write one with `saltation validate nino-garcia --out DIR/validation`.", "note")]
    parts = [_p(f"from {vdir}"), _table(pd.read_csv(vdir / "validation.csv"))]
    if (vdir / "validation.png").exists():
        parts.append(_img(vdir / "validation.png"))
    if (vdir / "ablation.csv").exists():
        parts += [_p("force ablation (change vs all forces on)"), _table(pd.read_csv(vdir / "ablation.csv"))]
    return parts


# --------------------------------------------------------------------------- entry points
TRACK_SUFFIXES = (".csv", ".parquet", ".pq")


def analyze(path, out=None, validation=None, *, diameter: float = 1.0, time_scale: float = 1.0,
            n_origins: int = N_ORIGINS) -> dict:
    """Analyse a run directory, a sweep directory or a tracks file (CSV/Parquet);
    returns {"kind" ("run" | "sweep" | "tracks"), "out", "report", "tables": {...}, …}.
    ``diameter``, ``time_scale``: units of a tracks file (:func:`read_tracks_file`); ``n_origins``: its
    time origins (a run directory's variance.parquet has its own)."""
    path = Path(path)
    if path.is_file():
        if path.suffix.lower() not in TRACK_SUFFIXES:
            raise AnalysisError(f"{path} is a file but not a tracks file (.csv or .parquet with columns "
                                f"{', '.join(f'{k} ({v})' for k, v in TRACK_COLUMNS.items())})")
        return analyze_tracks_file(path, Path(out) if out else None, diameter=diameter, time_scale=time_scale,
                                   n_origins=n_origins)
    if not path.is_dir():
        raise AnalysisError(f"{path} is not a directory nor a file: give a run directory (with summary.json), a sweep "
                            f"directory (with cases/NAME/summary.json) or a tracks file (.csv or .parquet with columns "
                            f"particle, t, x, z)")
    if (diameter, time_scale) != (1.0, 1.0):
        raise AnalysisError("diameter / time_scale convert a tracks file's units; a run directory is already in d and d/u*")
    if n_origins != N_ORIGINS:
        raise AnalysisError("--origins applies to a tracks file; a run directory's variance.parquet has its own origins")
    out = Path(out) if out else path / "analysis"
    out.mkdir(parents=True, exist_ok=True)
    vdir = _validation_dir(path, validation)
    if is_run_dir(path):
        return analyze_run(path, out, vdir)
    runs = find_runs(path)
    if not runs:
        raise AnalysisError(f"{path} holds neither summary.json (a run directory) nor run directories under "
                            f"{path / 'cases'} (a sweep): nothing to analyse")
    return analyze_sweep(path, runs, out, vdir)


def analyze_run(run_dir: Path, out: Path, vdir=None) -> dict:
    s = read_summary(run_dir)
    jumps = counted_jumps(run_dir)
    jt = jump_table(jumps)
    jt.to_csv(out / "jump_stats.csv", index=False)
    sections = []
    head = (f"{s.get('n_particles')} grains, C = {100 * (s.get('concentration') or 0):.3g} %, τ*/τ*c = "
            f"{s.get('tau_ratio', 0):.3g}, {s.get('simulated_time_s', 0):.3g} s = {s.get('simulated_time_particle', 0):.1f} d/u* "
            f"simulated, status {s.get('status')}")
    parts = [_p(head), _table(jt)]
    if len(jumps):
        parts.append(_img(fig_jump_distributions(jumps, out / "jump_distributions.png")))
    sections.append((f"Jump statistics (first {DISCARDED_JUMPS} jumps of each grain dropped)", parts))

    res, problems = diffusion_of(run_dir)
    parts = _diffusion_parts(res, problems, out)
    sections.append(("Diffusion (cf. paper Fig. 8)", parts))

    flat = pd.json_normalize({k: s[k] for k in ("collisions", "timing") if k in s}, sep=".").T.reset_index()
    flat.columns = ["quantity", "value"]
    flat.to_csv(out / "collisions_cost.csv", index=False)
    sections.append(("Collisions and cost", [_table(flat), _img(fig_run_costs(s, out / "collisions_cost.png"))]))
    sections.append(("Single-grain validation", _validation_section(vdir)))
    report = out / "report.html"
    report.write_text(_html(f"saltation run {run_dir.name}", sections))
    return {"kind": "run", "out": out, "report": report, "diffusion": res, "problems": problems,
            "tables": {"jump_stats": jt}}


def crossover_table(res) -> pd.DataFrame:
    """The two-segment fits of ⟨X′²⟩ and ⟨Z′²⟩: breakpoint t_c (d/u*), its 95 % bootstrap
    interval, the γ of each segment, the span fitted, and whether t_c set the ranges."""
    rows = []
    used = "crossover" in res["windows_from"].values()
    for key in ("crossover", "crossover_z"):
        c = res[key]
        rows.append({"direction": c["direction"], "t_c": c["t_c"] if c["found"] else None, "ci_low": c["ci"][0],
                     "ci_high": c["ci"][1], "gamma_before": c["gamma_before"], "gamma_after": c["gamma_after"],
                     "fit_t_min": c["fit_range"][0] if c["fit_range"] else None,
                     "fit_t_max": c["fit_range"][1] if c["fit_range"] else None, "n_boot": c["n_boot"],
                     "sets_ranges": bool(used and key == "crossover"), "note": c["reason"]})
    return pd.DataFrame(rows)


def global_bend_table(res) -> pd.DataFrame:
    """The three-segment fit of ⟨X′²⟩ (``diffusion.global_bend``): whether a global range is
    seen, t_c and t_g (d/u*) with their 95 % bootstrap intervals, the γ of the three
    segments, the grid points beyond t_g, and why not where none is seen."""
    b = res["global_bend"]
    g = b["gammas"] or (None, None, None)
    return pd.DataFrame([{"direction": b["direction"], "found": bool(b["found"]), "t_c": b["t_c"],
                          "t_c_low": b["t_c_ci"][0], "t_c_high": b["t_c_ci"][1], "t_g": b["t_g"], "t_g_low": b["ci"][0],
                          "t_g_high": b["ci"][1], "gamma_1": g[0], "gamma_2": g[1], "gamma_3": g[2],
                          "n_beyond": b["n_beyond"], "n_boot": b["n_boot"], "note": b["reason"]}])


def windows_text(res) -> str:
    """One line: what set the ranges, t_c, and T_J as the cross-check."""
    c = res["crossover"]
    if c["found"]:
        lo, hi = c["ci"]
        tc = f"crossover of ⟨X′²⟩ t_c = {c['t_c']:.3g}" + (f" [{lo:.3g}, {hi:.3g}]" if np.isfinite(lo) else "") + " d/u*"
    else:
        tc = f"no crossover found in ⟨X′²⟩ ({c['reason']})"
    tj = (f"T_J = {res['jump_duration']:.3g} d/u* ({res['jump_duration_from']})" if res["jump_duration"]
          else "T_J not known (no jumps.parquet, no bed contacts)")
    frm = "; ".join(f"{k} from {v}" for k, v in res["windows_from"].items())
    gb = res.get("global_bend")
    if gb and gb["found"]:
        lo, hi = gb["ci"]
        glob = (f"second bend (three-segment fit) t_c = {gb['t_c']:.3g}, t_g = {gb['t_g']:.3g}"
                + (f" [{lo:.3g}, {hi:.3g}]" if np.isfinite(lo) else "") + " d/u*: global range from t_g")
    else:
        glob = f"no global range seen ({gb['reason']})" if gb else "no global range fitted"
    return f"ranges: {frm}. {tc}; {glob}; {tj}"


def _diffusion_parts(res, problems: dict, out: Path) -> list[str]:
    parts = []
    if res is not None:
        res.table.to_csv(out / "diffusion.csv", index=False)
        res.curves.to_csv(out / "variance_curves.csv", index=False)
        ct = crossover_table(res)
        ct.to_csv(out / "crossover.csv", index=False)
        gt = global_bend_table(res)
        gt.to_csv(out / "global_bend.csv", index=False)
        parts += [_p(f"source {res['source']}, {res['n_particles']} grains; samples every {res['sample_interval']:.3g} "
                     "d/u*; γ from least squares on log–log axes, 95 % bootstrap intervals over grains. The local range "
                     "ends at ½ t_c, the intermediate starts at 3 t_c, t_c being the breakpoint of a two-segment fit of "
                     "log⟨X′²⟩ against log t (unless ranges or T_J are given; T_J is shown as a cross-check). Where a "
                     "three-segment fit finds a second bend t_g beyond the intermediate range, the intermediate range "
                     "ends at t_g (t_c then from the same fit) and the global range runs from t_g to the longest lag."),
                  _p(windows_text(res)), _table(res.table), _p("two-segment fits (breakpoint t_c, d/u*)"), _table(ct),
                  _p("three-segment fit of ⟨X′²⟩ (second breakpoint t_g, d/u*: the global range)"), _table(gt)]
        parts.append(_img(fig_variance(res, out / "variance.png")))
    for k, v in problems.items():
        parts.append(_p(f"{k}: {v}", "note"))
    return parts


def analyze_tracks_file(path: Path, out: Path | None = None, *, diameter: float = 1.0, time_scale: float = 1.0,
                        n_origins: int = N_ORIGINS) -> dict:
    """Diffusion of a CSV/Parquet tracks file (no jumps, no summary): exponents, crossover,
    variance figure and report in ``out`` (default ``<stem>_analysis/`` next to the file).
    ``n_origins``: time origins of the statistics (1: a release at the first origin)."""
    frame = read_tracks_file(path, diameter=diameter, time_scale=time_scale)
    res = exponents(frame, strict=False, n_origins=n_origins)  # bad tracks raise; ranges that cannot be fitted are listed
    problems = dict(res.problems)
    out = out if out is not None else path.parent / f"{path.stem}_analysis"
    out.mkdir(parents=True, exist_ok=True)
    units = ("x, y, z in d and t in d/u* as read" if (diameter, time_scale) == (1.0, 1.0) else
             f"x, y, z divided by d = {diameter:g} and t by d/u* = {time_scale:g} (file units)")
    n_t = frame["t"].nunique()
    head = (f"{res['n_particles']} grains × {n_t} samples every {res['sample_interval']:.3g} d/u* "
            f"({(n_t - 1) * res['sample_interval']:.4g} d/u*); {units}")
    parts = [_p(head)] + _diffusion_parts(res, problems, out)
    report = out / "report.html"
    report.write_text(_html(f"saltation tracks {path.name}", [("Diffusion (cf. paper Fig. 8)", parts)]))
    return {"kind": "tracks", "out": out, "report": report, "diffusion": res, "problems": problems,
            "tables": {"diffusion": res.table, "crossover": crossover_table(res), "global_bend": global_bend_table(res)}}


def analyze_sweep(sweep: Path, runs: list[Path], out: Path, vdir=None) -> dict:
    rows, results = [], {}
    for r in runs:
        row = case_row(r)
        rows.append(row)
        res, _ = diffusion_of(r)
        results[r.name] = res
    df = pd.DataFrame(rows)
    df.to_csv(out / "cases.csv", index=False)
    gv = gamma_vs_paper(df)
    gv.to_csv(out / "gamma_vs_paper.csv", index=False)
    cv = cost_vs_paper(df)
    cv.to_csv(out / "cost_vs_paper.csv", index=False)

    sections = []
    overview = df[["case", "status", "n_particles", "concentration_pct", "tau_ratio", "simulated_time_s", "jumps",
                   "H_mean", "H_std", "L_mean", "L_std", "U_mean", "U_std"]]
    sections.append(("Jump statistics vs concentration (cf. paper Fig. 5)",
                     [_table(overview), _img(fig_jumps_vs_concentration(df, out / "fig5_jumps_vs_concentration.png"))]))
    sections.append(("Velocity distributions (cf. paper Fig. 6)",
                     [_img(fig_velocity_boxes(runs, df, out / "fig6_velocity.png"))]))
    coll = df[["case", "n_particles", "collisions_model", "collisions_pp", "collisions_pp_per_particle", "collisions_bed",
               "wall_s", "free_flight_s", "bed_s", "particle_collisions_s", "particle_steps_per_s"]]
    notes = []
    off = df[df["collisions_model"] == "off"]["case"].tolist()
    if off:
        notes.append(_p(f"grain–grain collisions were off (collisions.model = \"off\") in {len(off)} of {len(df)} "
                        f"case(s): {', '.join(off)} — their grains do not interact, so concentration changes only the "
                        "ensemble size there.", "note"))
    sections.append(("Collisions and cost vs N (cf. paper Fig. 7, Table 3)",
                     [*notes, _table(coll), _img(fig_collisions_cost(df, out / "fig7_collisions_cost.png")),
                      _p("Table 3 side by side: the paper's CPU time is for 200 s simulated on one OpenMP server; ours "
                         "is the wall time of the run, also scaled linearly to 200 s simulated."), _table(cv)]))
    sections.append(("Variance curves (cf. paper Fig. 8)", [_img(fig_variance_sweep(results, df, out / "fig8_variance.png"))]))
    g_parts = [_img(fig_gamma(df, out / "fig9_gamma.png"))]
    for (name, d), num in ref.TABLE_NUMBER.items():
        sub = gv[gv["table"] == num].drop(columns=["table", "range", "direction"])
        g_parts += [f"<h3>Table {num}: {name} γ{d} — ours vs paper</h3>", _table(sub)]
    probs = df[df["diffusion_problems"].astype(bool)][["case", "diffusion_problems"]]
    for _, p in probs.iterrows():
        g_parts.append(_p(f"{p['case']}: {p['diffusion_problems']}", "note"))
    sections.append(("Diffusion exponents vs concentration (cf. paper Fig. 9, Tables 4–7)", g_parts))
    sections.append(("Single-grain validation", _validation_section(vdir)))
    report = out / "report.html"
    report.write_text(_html(f"saltation sweep {sweep.name}: {len(runs)} cases", sections))
    return {"kind": "sweep", "out": out, "report": report, "tables": {"cases": df, "gamma_vs_paper": gv, "cost_vs_paper": cv}}
