"""Diffusion exponents γx, γz of bed-load grains (Nikora et al. 2002; SPEC §6, paper §2.5, §4.4).

⟨X′²⟩(t) = αx t^{2γx}, ⟨Z′²⟩(t) = αz t^{2γz}: X is a grain's streamwise displacement over
an elapsed time t (unwrapped, in d), X′ = X − X̄ and ⟨⟩ the average over the grains at
equal elapsed time, then over several time origins (variance.py explains the plan).
γ is the least-squares slope of log⟨X′²⟩ against log t, halved, over

* the **local** range, between two bed impacts: from the first sampled lag to half the
  typical jump duration T_J (ballistic, γ ≈ 1);
* the **intermediate** range, many jumps: from 3 T_J to the longest lag (half the record
  after the first 10 % is skipped). γ = 0.5 normal diffusion, > 0.5 super-, < 0.5 sub-.

T_J is found from the data: the median duration of the counted jumps in jumps.parquet
(each grain's first 10 dropped, paper §3.2) or, from tracks alone, the median time between
successive bed contacts (local minima of the centre height below 1.5 d). Both windows
can be overridden (``ranges``), as can T_J (``jump_duration``). The median counts every
bed impact, short rebounds included (on the virtual bed the duration distribution has a
peak below 0.5 d/u* besides the saltation hops of 2–5 d/u*), so it is the shorter,
conservative choice for where free flight ends.

Uncertainty: the bootstrap over grains — grains (or groups of grains: variance.py) are
resampled with replacement, the curves and the fits recomputed; ``ci_low``/``ci_high``
are the 2.5 and 97.5 percentiles of γ (a 95 % interval).

Entry point (SPEC §9): ``exponents(tracks, ranges=None)`` with ``tracks`` a tracks
DataFrame (columns particle, t, x, y, z, …; t in d/u*, x, z unwrapped in d) or a run
directory (variance.parquet is used when present, tracks.parquet otherwise). The result
is a dict ``{"local": {"gamma_x", "gamma_z", …}, "intermediate": {…}, "windows": …}``
with ``.table`` (tidy DataFrame) and ``.curves`` (the variance curves).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from .variance import (VARIANCE_FILE, AnalysisError, VarianceAccumulator, make_plan, read_sums,
                       variance_curves)

__all__ = ["exponents", "DiffusionResult", "AnalysisError", "jump_duration_from_tracks", "sums_from_tracks"]

MIN_PARTICLES = 10  # fewer grains give no meaningful ensemble variance
MIN_POINTS = 5  # lags a range must hold for a log–log fit
LOCAL_FRACTION = 0.5  # local range ends at T_J / 2
INTERMEDIATE_START = 3.0  # intermediate range starts at 3 T_J
CONTACT_HEIGHT = 1.5  # d: a local minimum of the centre height below this is a bed contact
DISCARDED_JUMPS = 10  # paper §3.2 (as run.py)
N_BOOTSTRAP = 400
RANGE_NAMES = ("local", "intermediate")
TABLE_COLUMNS = ["direction", "range", "t_min", "t_max", "gamma", "ci_low", "ci_high", "alpha",
                 "n_points", "n_particles", "n_origins", "source"]


class DiffusionResult(dict):
    """``{"local": {...}, "intermediate": {...}, "windows": {...}, "jump_duration": T_J, ...}``.

    Each range entry holds gamma_x, gamma_z, their 95 % bootstrap intervals (ci_x, ci_z),
    t_min, t_max (d/u*) and n_points. Attributes: ``table`` (tidy rows: direction, range,
    t_min, t_max, gamma, ci_low, ci_high, alpha, n_points, n_particles, n_origins, source),
    ``curves`` (lag t, var_x, var_z, n_origins) and ``problems`` (ranges that could not be
    fitted, with the reason; empty unless ``strict=False``).
    """

    table: pd.DataFrame
    curves: pd.DataFrame
    problems: dict


# --------------------------------------------------------------------------- inputs
def jump_duration_from_tracks(tracks: pd.DataFrame, contact_height: float = CONTACT_HEIGHT) -> float | None:
    """Median time (d/u*) between successive bed contacts seen in the tracks (local minima
    of the centre height y below ``contact_height`` d); None when there are none."""
    if "y" not in tracks.columns:
        return None
    durations = []
    for _, g in tracks.sort_values(["particle", "t"]).groupby("particle", sort=False):
        y, t = g["y"].to_numpy(), g["t"].to_numpy()
        if len(y) < 3:
            continue
        is_min = (y[1:-1] < y[:-2]) & (y[1:-1] <= y[2:]) & (y[1:-1] < contact_height)
        tc = t[1:-1][is_min]
        if len(tc) > 1:
            durations.append(np.diff(tc))
    if not durations:
        return None
    return float(np.median(np.concatenate(durations)))


def _jump_duration_from_file(path: Path) -> float | None:
    jumps = pd.read_parquet(path, columns=["jump", "duration"])
    counted = jumps[jumps["jump"] >= DISCARDED_JUMPS]
    use = counted if len(counted) >= 20 else jumps
    return float(use["duration"].median()) if len(use) else None


def _tracks_grid(tracks: pd.DataFrame):
    """x, z (P, J) arrays on the uniform sample grid of the tracks, and its spacing."""
    missing = [c for c in ("particle", "t", "x", "z") if c not in tracks.columns]
    if missing:
        raise AnalysisError(f"the tracks lack column(s) {missing}: need particle, t, x, z (x, z unwrapped, in d; t in d/u*)")
    if len(tracks) == 0:
        raise AnalysisError("the tracks are empty: no sampled positions; run with output.tracks = true "
                            "(or output.variance = true for variance.parquet)")
    times = np.unique(tracks["t"].to_numpy())
    particles = np.unique(tracks["particle"].to_numpy())
    if len(particles) < MIN_PARTICLES:
        raise AnalysisError(f"the tracks hold {len(particles)} grain(s): an ensemble variance needs at least "
                            f"{MIN_PARTICLES} grains (a single-grain validation run has no diffusion statistics)")
    if len(times) < 3:
        raise AnalysisError(f"the tracks hold {len(times)} sample time(s): far too short a record; "
                            f"need hundreds of samples spanning many jump durations")
    steps = np.diff(times)
    dt = float(np.median(steps))
    if np.max(np.abs(steps - dt)) > 1e-6 * max(dt, 1e-300) + 1e-9:
        raise AnalysisError(f"the track sample times are not evenly spaced (steps from {steps.min():.6g} to "
                            f"{steps.max():.6g} d/u*): the ensemble at equal elapsed time needs a uniform sampling")
    if len(tracks) != len(times) * len(particles):
        counts = tracks.groupby("particle").size()
        short = counts[counts < len(times)]
        raise AnalysisError(f"{len(short)} grain(s) (e.g. particle {short.index[0]}) have fewer than the {len(times)} "
                            f"samples of the others: every grain must be sampled at every time")
    t_sorted = tracks.sort_values(["particle", "t"])
    x = t_sorted["x"].to_numpy().reshape(len(particles), len(times))
    z = t_sorted["z"].to_numpy().reshape(len(particles), len(times))
    if not (np.isfinite(x).all() and np.isfinite(z).all()):
        raise AnalysisError("the tracks hold non-finite x or z values")
    return x, z, dt, times


def sums_from_tracks(tracks: pd.DataFrame, n_origins: int = 8, n_groups: int | None = None):
    """(sums, lag times, metadata) from a tracks DataFrame, by feeding its samples to the
    same accumulator the run loop uses (identical sampling plan and numbers)."""
    x, z, dt, times = _tracks_grid(tracks)
    p, j = x.shape
    plan = make_plan(j, dt, n_origins=n_origins)
    acc = VarianceAccumulator(p, plan, n_groups=min(p, 2000) if n_groups is None else n_groups)
    pos = np.zeros((p, 3))
    for s in sorted(acc._due):
        pos[:, 0], pos[:, 2] = x[:, s], z[:, s]
        acc.sample(s, pos)
    meta = acc.metadata()
    meta["t_first"] = float(times[0])
    return acc.sums, plan.lag_times, meta


# --------------------------------------------------------------------------- fitting
def _fit_slopes(logt: np.ndarray, logv: np.ndarray) -> np.ndarray:
    """Least-squares slopes of logv (B, n) against logt (n,), row by row."""
    tc = logt - logt.mean()
    return ((logv - logv.mean(axis=-1, keepdims=True)) @ tc) / (tc @ tc)


def _auto_ranges(t_first: float, t_max: float, jump_duration: float | None, given: dict) -> tuple[dict, dict]:
    ranges, problems = {}, {}
    for name in RANGE_NAMES:
        if name in given and given[name] is not None:
            continue
        if jump_duration is None:
            problems[name] = ("the typical jump duration could not be found (no jumps.parquet and no bed contacts "
                              "in the tracks): give ranges={'local': (t0, t1), 'intermediate': (t2, t3)} in d/u* "
                              "or jump_duration=")
            continue
        if name == "local":
            ranges[name] = (t_first, LOCAL_FRACTION * jump_duration)
        else:
            ranges[name] = (INTERMEDIATE_START * jump_duration, t_max)
    for name, win in given.items():
        if win is None:
            continue
        lo, hi = (float(v) for v in win)
        if not (0 < lo < hi):
            raise AnalysisError(f"ranges[{name!r}] = {win!r}: must be (t_min, t_max) in d/u* with 0 < t_min < t_max")
        ranges[name] = (lo, hi)
    return ranges, problems


def exponents(tracks, ranges=None, *, jump_duration: float | None = None, n_bootstrap: int = N_BOOTSTRAP,
              n_origins: int = 8, seed: int = 0, strict: bool = True) -> DiffusionResult:
    """γx, γz over the local and intermediate ranges (SPEC §6, §9).

    ``tracks``: a tracks DataFrame (t in d/u*, x, z unwrapped in d) or a run directory.
    ``ranges``: ``{"local": (t_min, t_max), "intermediate": (t_min, t_max)}`` in d/u*; a
    range left out is set from the typical jump duration T_J (``jump_duration`` or found
    from the data). ``strict``: raise :class:`AnalysisError` when a range cannot be fitted
    (default); with ``strict=False`` such ranges are left out and ``result.problems`` says why.
    """
    given = dict(ranges or {})
    source = "tracks"
    if isinstance(tracks, (str, Path)):
        run_dir = Path(tracks)
        if not run_dir.is_dir():
            raise AnalysisError(f"{run_dir} is not a run directory")
        if jump_duration is None and (run_dir / "jumps.parquet").exists():
            jump_duration = _jump_duration_from_file(run_dir / "jumps.parquet")
        if (run_dir / VARIANCE_FILE).exists():
            sums, lags, meta = read_sums(run_dir / VARIANCE_FILE)
            source = VARIANCE_FILE
            if meta["n_particles"] < MIN_PARTICLES:
                raise AnalysisError(f"{run_dir} holds {meta['n_particles']} grain(s): an ensemble variance needs at "
                                    f"least {MIN_PARTICLES} grains")
        elif (run_dir / "tracks.parquet").exists():
            frame = pd.read_parquet(run_dir / "tracks.parquet", columns=["particle", "t", "x", "y", "z"])
            if jump_duration is None:
                jump_duration = jump_duration_from_tracks(frame)
            sums, lags, meta = sums_from_tracks(frame, n_origins=n_origins)
            source = "tracks.parquet"
        else:
            raise AnalysisError(f"{run_dir} has neither {VARIANCE_FILE} nor tracks.parquet: run with "
                                f"output.variance = true (or output.tracks = true) to get diffusion statistics")
    elif isinstance(tracks, pd.DataFrame):
        if jump_duration is None and not all(n in given for n in RANGE_NAMES):
            jump_duration = jump_duration_from_tracks(tracks) if len(tracks) else None
        sums, lags, meta = sums_from_tracks(tracks, n_origins=n_origins)
    elif tracks is None:
        raise AnalysisError("no tracks given: pass a tracks DataFrame or a run directory")
    else:
        raise AnalysisError(f"tracks must be a DataFrame or a run directory, not {type(tracks).__name__}")

    var_x, var_z, n_or = variance_curves(sums)
    positive = lags > 0
    curves = pd.DataFrame({"t": lags[positive], "var_x": var_x[positive], "var_z": var_z[positive],
                           "n_origins": n_or[positive]})
    curves = curves[curves["n_origins"] > 0].reset_index(drop=True)
    if len(curves) == 0:
        raise AnalysisError("no displacement statistics were accumulated (the run stopped before the first lag)")
    t_first, t_last = float(curves["t"].iloc[0]), float(curves["t"].iloc[-1])
    dt = float(meta["dt"])
    n_particles = int(meta["n_particles"])
    win, problems = _auto_ranges(t_first, t_last, jump_duration, given)

    # bootstrap weights over groups of grains (groups = grains unless variance.parquet pooled them)
    rng = np.random.default_rng(seed)
    g = sums.shape[0]
    draws = rng.integers(0, g, size=(n_bootstrap, g))
    weights = np.zeros((n_bootstrap, g))
    np.add.at(weights, (np.arange(n_bootstrap)[:, None], draws), 1.0)
    bx, bz, _ = variance_curves(sums, weights)
    keep = np.isin(lags, curves["t"].to_numpy())
    bx, bz = bx[:, keep], bz[:, keep]

    result = DiffusionResult()
    rows = []
    t = curves["t"].to_numpy()
    for name, (lo, hi) in win.items():
        sel = (t >= lo * (1 - 1e-9)) & (t <= hi * (1 + 1e-9))
        npts = int(sel.sum())
        if npts < MIN_POINTS:
            problems[name] = _too_few_points(name, lo, hi, npts, dt, t_last, jump_duration)
            continue
        vx, vz = curves["var_x"].to_numpy()[sel], curves["var_z"].to_numpy()[sel]
        if (vx <= 0).any() or (vz <= 0).any():
            problems[name] = (f"the {name} range [{lo:.4g}, {hi:.4g}] d/u* has zero displacement variance at some "
                              f"lags (grains that do not move, or identical grains): no power law to fit")
            continue
        logt = np.log(t[sel])
        entry = {"t_min": float(t[sel][0]), "t_max": float(t[sel][-1]), "n_points": npts,
                 "window": (float(lo), float(hi))}
        for direction, v, bv in (("x", vx, bx[:, sel]), ("z", vz, bz[:, sel])):
            slope = float(_fit_slopes(logt, np.log(v)[None, :])[0])
            alpha = float(np.exp(np.mean(np.log(v)) - slope * logt.mean()))
            ok = (bv > 0).all(axis=1)
            boot = 0.5 * _fit_slopes(logt, np.log(np.where(bv[ok] > 0, bv[ok], 1.0)))
            if len(boot) >= 20:
                lo_ci, hi_ci = (float(q) for q in np.percentile(boot, [2.5, 97.5]))
            else:
                lo_ci = hi_ci = float("nan")
            gamma = 0.5 * slope
            entry[f"gamma_{direction}"] = gamma
            entry[f"ci_{direction}"] = (lo_ci, hi_ci)
            entry[f"alpha_{direction}"] = alpha
            rows.append({"direction": direction, "range": name, "t_min": entry["t_min"], "t_max": entry["t_max"],
                         "gamma": gamma, "ci_low": lo_ci, "ci_high": hi_ci, "alpha": alpha, "n_points": npts,
                         "n_particles": n_particles, "n_origins": int(curves["n_origins"][sel].min()), "source": source})
        result[name] = entry
    if problems and strict:
        raise AnalysisError("; ".join(f"{k}: {v}" for k, v in problems.items()))
    result["windows"] = {k: v for k, v in win.items()}
    result["jump_duration"] = jump_duration
    result["sample_interval"] = dt
    result["n_particles"] = n_particles
    result["source"] = source
    result.table = pd.DataFrame(rows, columns=TABLE_COLUMNS)
    result.curves = curves
    result.problems = problems
    return result


def _too_few_points(name, lo, hi, npts, dt, t_last, jump_duration) -> str:
    need = f"at least {MIN_POINTS} are needed"
    tj = f", T_J = {jump_duration:.3g} d/u*" if jump_duration else ""
    if hi >= t_last * (1 - 1e-9) or lo > t_last:
        # bounded by the longest lag: 5 lags at 20 per decade span a factor 1.6, and the
        # longest lag is 0.45 of the record (half of what follows the 10 % skip)
        return (f"the {name} range [{lo:.4g}, {hi:.4g}] d/u*{tj} holds {npts} lag(s) of the variance curve; {need}. "
                f"The longest lag is {t_last:.4g} d/u* (0.45 of the record): the run is too short; a run of at least "
                f"{1.6 * lo / 0.45:.4g} d/u* would be enough")
    return (f"the {name} range [{lo:.4g}, {hi:.4g}] d/u*{tj} holds {npts} lag(s) of the variance curve (samples every "
            f"{dt:.4g} d/u*); {need}: sample at least every {hi / MIN_POINTS:.3g} d/u* (output.variance_interval "
            f"or output.tracks_interval, in s = d/u* x the case's time scale) or widen the range")


def load_summary(run_dir) -> dict:
    return json.loads((Path(run_dir) / "summary.json").read_text())
