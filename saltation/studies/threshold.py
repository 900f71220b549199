"""Incipient motion and bed-load transport (SPEC §7; seed 000 §4.3–4.4): grains that
start at rest in the hollows of the packed bed (``run.start = "rest"``) under the LES flow
at a series of Shields numbers τ*.

Per τ* one run of the case (its grain, fluid, flow and bed; τ* set through
``flow.tau_ratio`` = τ*/``flow.tau_c``) on a bed of ``width_d`` = (Lx, Lz) in d holding
``coverage`` × (bed spheres) grains at rest, for ``duration_d`` d/u* (the same number of
grain time scales at every τ*). From its tracks:

* the transport rate q* = q/√(R g d³), q = Σ V (x(T) − x(0))/(Lx Lz T) from each grain's
  unwrapped displacement (the same mean as ⟨Σ V u⟩/(Lx Lz) of analysis/transport.py, but
  free of the instantaneous velocity of a grain in a lasting contact, which carries an
  offset of about half a sub-step's weight, ~g'Δt/(2 n_sub): at q* ~ 10⁻⁴ that offset
  would be the signal); since
  the bed offers the same number of grains per area at every τ* and every diameter, q*
  compares across them; it depends on that areal density (here ``coverage`` grains per
  bed sphere, bed spheres at 1/(d² √3/2)), as it would in a flume on how much loose
  sediment lies on the bed;
* the fraction of grains moving: of the track intervals, those in which a grain moved
  faster than ``MOVING_SPEED`` u* on average;
* rest times (from a grain's stop to its next start, complete rests only) and step lengths
  (streamwise travel from a start to the next stop), from the track samples.

The threshold τ*c is where q* crosses ``Q_STAR_THRESHOLD`` = 10⁻⁴ (seed 000's definition,
after Smith & Cheung 2004), interpolated linearly in log q* – log τ* between the two runs
that bracket it; none when the series does not bracket it (the reason is written).

References compared (all in threshold.json and the figure):
* the Shields curve as fitted by Soulsby & Whitehouse (1997):
  θcr = 0.30/(1 + 1.2 D*) + 0.055 (1 − exp(−0.020 D*)), D* = d (g R/ν²)^{1/3};
* bed-load formulas q* = a (τ* − τ*c)^{3/2}: Meyer-Peter & Müller (1948) a = 8,
  τ*c = 0.047; Wong & Parker (2006) a = 3.97, τ*c = 0.0495; Fernandez Luque & van Beek
  (1976) a = 5.7, τ*c = the Shields-curve value (their own measured 0.037–0.06 spans it);
  and the Ackers–White (1973/1993) capacity with the LES's depth and bulk velocity.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

Q_STAR_THRESHOLD = 1e-4  # seed 000 §4.3: incipient motion where q* reaches 10⁻⁴
MOVING_SPEED = 0.1  # u*: a grain faster than this over a track interval is moving
DEFAULT_RATIOS = (0.4, 0.55, 0.7, 0.85, 1.0, 1.2, 1.5)  # τ* / (Shields-curve θcr)
DEFAULT_WIDTH = (20.0, 12.0)  # bed Lx, Lz in d
DEFAULT_COVERAGE = 0.4  # grains at rest per bed sphere (random filling of the hollows holds ~0.45)
DEFAULT_DURATION = 200.0  # d/u* per τ*
# bonded-sphere grains are placed on the bed by a drop (grains/initial.composites_resting)
# and tip into a stable pose in their first d/u* or so: the first SETTLE_COMPOSITES d/u*
# of their runs are not measured (spheres start in equilibrium in their hollows: none)
SETTLE_COMPOSITES = 10.0
FORMULAS = {  # q* = a (τ* − τ*c)^1.5; τ*c None: the Shields curve's
    "Meyer-Peter & Müller 1948": (8.0, 0.047),
    "Wong & Parker 2006": (3.97, 0.0495),
    "Fernandez Luque & van Beek 1976": (5.7, None),
}


def d_star(d, R, nu, g=9.81):
    """Dimensionless grain diameter D* = d (g R/ν²)^{1/3}."""
    return d * (g * R / nu**2) ** (1.0 / 3.0)


def shields_soulsby(dstar):
    """Critical Shields number of Soulsby & Whitehouse (1997), eq. in Soulsby (1997) §9.3."""
    return 0.30 / (1.0 + 1.2 * dstar) + 0.055 * (1.0 - math.exp(-0.020 * dstar))


def formula_q_star(tau_star, a, tau_c):
    """q* = a (τ* − τ*c)^{3/2}, 0 below τ*c."""
    return a * max(tau_star - tau_c, 0.0) ** 1.5


def crossing(tau, q, level=Q_STAR_THRESHOLD):
    """τ* where q*(τ*) first crosses ``level`` upward (log–log interpolation between the
    bracketing runs): (τ*c, None) or (None, reason)."""
    tau = np.asarray(tau, float)
    q = np.asarray(q, float)
    order = np.argsort(tau)
    tau, q = tau[order], q[order]
    for k in range(len(tau) - 1):
        if q[k] < level <= q[k + 1]:
            if q[k] <= 0.0:
                return float(tau[k + 1]), "lower bracket has q* = 0: τ*c is at most the upper one"
            f = (math.log(level) - math.log(q[k])) / (math.log(q[k + 1]) - math.log(q[k]))
            return float(math.exp(math.log(tau[k]) + f * (math.log(tau[k + 1]) - math.log(tau[k])))), None
    if len(q) and q.min() >= level:
        return None, f"q* >= {level:g} at every τ* (lowest {tau[0]:.4g}): lower the series"
    return None, f"q* < {level:g} at every τ* (highest {tau[-1]:.4g}): raise the series"


def motion_statistics(tracks: pd.DataFrame, moving_speed=MOVING_SPEED) -> dict:
    """Fraction moving, rest times (d/u*) and step lengths (d) from track samples
    (module docstring). Returns arrays and summary numbers."""
    rests, steps = [], []
    moving_total = 0
    samples = 0
    for _, g in tracks.groupby("particle", sort=True):
        g = g.sort_values("t")
        t = g["t"].to_numpy()
        x = g["x"].to_numpy()
        if len(t) < 2:
            continue
        y = g["y"].to_numpy() if "y" in g else np.zeros(len(t))
        z = g["z"].to_numpy() if "z" in g else np.zeros(len(t))
        dist = np.sqrt(np.diff(x) ** 2 + np.diff(y) ** 2 + np.diff(z) ** 2)
        mov = dist > moving_speed * np.diff(t)  # interval k: samples k → k + 1
        moving_total += int(mov.sum())
        samples += len(mov)
        # run boundaries: indices where the state changes
        change = np.flatnonzero(np.diff(mov.astype(np.int8))) + 1
        edges = np.concatenate([[0], change, [len(mov)]])
        for a, b in zip(edges[:-1], edges[1:]):
            complete = a > 0 and b < len(mov)  # bounded by the other state on both sides
            if not complete:
                continue
            if mov[a]:
                steps.append(x[b] - x[a])  # intervals a..b-1 span samples a..b
            else:
                rests.append(t[b] - t[a])
    rests = np.asarray(rests, float)
    steps = np.asarray(steps, float)
    return {"fraction_moving": moving_total / samples if samples else float("nan"),
            "rest_times": rests, "step_lengths": steps,
            "rest_mean": float(rests.mean()) if len(rests) else None,
            "rest_cv": float(rests.std() / rests.mean()) if len(rests) > 1 else None,
            "step_mean": float(steps.mean()) if len(steps) else None,
            "step_cv": float(steps.std() / steps.mean()) if len(steps) > 1 and steps.mean() != 0 else None}


def displacement_rate(tracks: pd.DataFrame, area: float, volumes=None) -> float:
    """q in particle units (u* d): Σ_p V_p (x_p(T) − x_p(0)) / (area · T), x unwrapped,
    from each grain's first to last track sample (module docstring); V_p = π/6 (a
    sphere of d) or ``volumes`` (a Series indexed by particle, d³: bonded-sphere grains)."""
    g = tracks.sort_values("t").groupby("particle")
    first, last = g.first(), g.last()
    span = float((last["t"] - first["t"]).max())
    if not span > 0:
        raise ValueError("displacement_rate: the tracks span no time; run longer")
    dx = last["x"] - first["x"]
    if volumes is None:
        return float((math.pi / 6.0) * dx.sum() / (area * span))
    return float((volumes.reindex(dx.index).to_numpy() * dx.to_numpy()).sum() / (area * span))


def tail_shape(samples, minimum=30):
    """Exponential or heavy-tailed? The coefficient of variation (1 for an exponential)
    and the Hill estimate of the power-law tail exponent over the largest 20 % (a small
    value, ≲ 2–3, means a heavy tail). None below ``minimum`` samples."""
    s = np.sort(np.asarray(samples, float))
    s = s[s > 0]
    if len(s) < minimum:
        return None
    k = max(int(0.2 * len(s)), 5)
    top = s[-k:]
    hill = 1.0 / np.mean(np.log(top / s[-k - 1]))
    return {"n": int(len(s)), "mean": float(s.mean()), "median": float(np.median(s)),
            "cv": float(s.std() / s.mean()), "hill_tail_exponent": float(hill)}


def threshold_study(case, out, *, ratios=DEFAULT_RATIOS, tau_stars=None, width_d=DEFAULT_WIDTH,
                    coverage=DEFAULT_COVERAGE, duration_d=DEFAULT_DURATION, settle_d=None, overrides=None,
                    progress=True, echo=print) -> dict:
    """Run the series (module docstring) into ``out``/tau_<τ*>/ and write
    ``out``/threshold.json (and threshold.csv, threshold.png). Each run lasts
    ``settle_d`` + ``duration_d`` d/u*; only the last ``duration_d`` are measured
    (settle_d None: 0 for spheres, SETTLE_COMPOSITES for bonded-sphere grains). Finished
    runs in ``out`` are reused (a rerun continues where an interrupted study stopped)."""
    from ..analysis.transport import ackers_white, bulk_velocity_plus, einstein_number
    from ..bed.packed import hexagonal_layer
    from ..case.schema import GRAVITY, load_case
    from ..engine.simulation import open_flow, run

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    base = load_case(case, overrides or None)
    d = base.particle.diameter
    R = base.submerged_specific_gravity
    nu = base.fluid.viscosity
    dstar = d_star(d, R, nu)
    if settle_d is None:
        settle_d = 0.0 if base.particle.shape == "sphere" else SETTLE_COMPOSITES
    theta_cr = shields_soulsby(dstar)
    series = sorted(float(t) for t in (tau_stars if tau_stars is not None else [r * theta_cr for r in ratios]))
    lx, lz = (float(w) for w in width_d)
    n_bed = len(hexagonal_layer(lx, lz)[0])
    n = max(1, int(round(coverage * n_bed)))
    tau_c_key = base.flow.tau_c
    ds = open_flow(base)
    ub_plus = bulk_velocity_plus(ds) if base.flow.source == "les" else None
    rows, stats = [], {}
    for k, ts in enumerate(series):
        u_star = math.sqrt(ts * R * GRAVITY * d)
        time_scale = d / u_star
        sets = {"run.start": "rest", "run.n_particles": n,
                "run.domain": [lx * d, lz * d, 50 * d], "run.duration": (settle_d + duration_d) * time_scale,
                "run.name": f"tau_{ts:.5f}", "output.vtk": False, "output.variance": False}
        sets.update(overrides or {})
        sets["flow.tau_ratio"] = ts / tau_c_key  # the series' own τ*
        rd = out / f"tau_{ts:.5f}"
        done = rd / "summary.json"
        if done.exists() and json.loads(done.read_text()).get("status") == "completed":
            tracks = pd.read_parquet(rd / "tracks.parquet")
            echo(f"[{k + 1}/{len(series)}] tau* = {ts:.4g}: finished earlier, reused")
        else:
            echo(f"[{k + 1}/{len(series)}] tau* = {ts:.4g} (tau*/theta_cr = {ts / theta_cr:.3g}): {n} grains at rest, "
                 f"{duration_d:g} d/u* ...")
            res = run(case, out=rd, progress=progress, overwrite=rd.exists(), **sets)
            tracks = res.tracks
        tracks = tracks[tracks["t"] >= settle_d * (1.0 - 1e-9)]
        volumes = None
        if base.particle.shape != "sphere":
            volumes = pd.read_parquet(rd / "particles.parquet", columns=["particle", "volume"]).set_index(
                "particle")["volume"]
        area = lx * lz
        q_star = einstein_number(displacement_rate(tracks, area, volumes), ts)
        ms = motion_statistics(tracks)
        stats[ts] = ms
        row = {"tau_star": ts, "tau_ratio_shields": ts / theta_cr, "q_star": q_star,
               "fraction_moving": ms["fraction_moving"], "rest_mean_d_u": ms["rest_mean"],
               "step_mean_d": ms["step_mean"], "rests": int(len(ms["rest_times"])),
               "steps": int(len(ms["step_lengths"]))}
        for name, (a, tc) in FORMULAS.items():
            row[name] = formula_q_star(ts, a, theta_cr if tc is None else tc)
        if ub_plus is not None:
            h = ds.re_tau * nu / u_star
            row["Ackers-White"] = ackers_white(d, u_star=u_star, velocity=ub_plus * u_star, depth=h,
                                               s=1.0 + R, nu=nu)["q_star"]
        rows.append(row)
        echo(f"    q* = {q_star:.3g}, moving {100 * ms['fraction_moving']:.2f} %")
    table = pd.DataFrame(rows)
    tau_c, why = crossing(table["tau_star"], table["q_star"])
    rest_all = np.concatenate([stats[t]["rest_times"] for t in series]) if series else np.array([])
    step_all = np.concatenate([stats[t]["step_lengths"] for t in series]) if series else np.array([])
    result = {
        "tau_star_c": tau_c, "tau_star_c_reason": why, "q_star_threshold": Q_STAR_THRESHOLD,
        "diameter_m": d, "d_star": dstar, "shields_soulsby_whitehouse_1997": theta_cr,
        "tau_star_c_over_shields": None if tau_c is None else tau_c / theta_cr,
        "grains": n, "bed_spheres": n_bed, "bed_d": [lx, lz], "duration_d_u": duration_d,
        "settle_d_u": settle_d, "shape": base.particle.shape,
        "flow": {"source": base.flow.source, "dataset": str(getattr(ds, "path", ""))},
        "table": table.to_dict(orient="records"),
        "rest_times": tail_shape(rest_all), "step_lengths": tail_shape(np.abs(step_all)),
        "units": "tau_star: Shields number; q_star = q/sqrt(R g d^3); rest times in d/u*; step lengths in d",
    }
    (out / "threshold.json").write_text(json.dumps(result, indent=1, default=float))
    table.to_csv(out / "threshold.csv", index=False)
    _figure(table, result, stats, out / "threshold.png")
    return result


def _figure(table, result, stats, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.5))
    ts = table["tau_star"].to_numpy()
    grid = np.geomspace(ts.min() * 0.9, ts.max() * 1.1, 100)
    a.loglog(ts, np.maximum(table["q_star"], 1e-9), "ko-", label="saltation (resting bed)")
    for name, (coef, tau_c) in FORMULAS.items():
        tau_c = tau_c or result["shields_soulsby_whitehouse_1997"]
        a.loglog(grid, [formula_q_star(t, coef, tau_c) for t in grid], "--", label=name)
    if "Ackers-White" in table:
        a.loglog(ts, table["Ackers-White"], ":", label="Ackers–White (capacity)")
    a.axhline(Q_STAR_THRESHOLD, color="grey", lw=0.8)
    a.axvline(result["shields_soulsby_whitehouse_1997"], color="grey", ls="--", lw=0.8,
              label="Shields (Soulsby & Whitehouse 1997)")
    if result["tau_star_c"]:
        a.axvline(result["tau_star_c"], color="k", lw=1.0, label=f"τ*c = {result['tau_star_c']:.4f}")
    a.set_ylim(1e-7, 1.0)
    a.set_xlabel("τ*")
    a.set_ylabel("q* = q/√(R g d³)")
    a.set_title(f"d = {1e3 * result['diameter_m']:.2f} mm, D* = {result['d_star']:.1f}")
    a.legend(fontsize=7)
    for ax, key, unit in ((b, "rest_times", "d/u*"), (c, "step_lengths", "d")):
        for t in ts:
            s = np.abs(stats[t][key])
            if len(s) >= 10:
                s = np.sort(s)
                ax.loglog(s, 1.0 - np.arange(len(s)) / len(s), label=f"τ* = {t:.3g}")
        ax.set_xlabel(f"{key.replace('_', ' ')} ({unit})")
        ax.set_ylabel("exceedance")
        if ax.get_lines():
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
