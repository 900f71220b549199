"""Diffusion exponents γx, γz of bed-load grains (Nikora et al. 2002; SPEC §6, paper §2.5, §4.4).

⟨X′²⟩(t) = αx t^{2γx}, ⟨Z′²⟩(t) = αz t^{2γz}: X is a grain's streamwise displacement over
an elapsed time t (unwrapped, in d), X′ = X − X̄ and ⟨⟩ the average over the grains at
equal elapsed time, then over several time origins (variance.py explains the plan).
γ is the least-squares slope of log⟨X′²⟩ against log t, halved, over

* the **local** range, between two bed impacts: from the first sampled lag to ½ t_c
  (ballistic, γ ≈ 1);
* the **intermediate** range, many jumps: from 3 t_c to the longest lag (half the record
  after the first 10 % is skipped), or to t_g where a global range is seen. γ = 0.5 normal
  diffusion, > 0.5 super-, < 0.5 sub-;
* the **global** range, many rest periods (resting grains make it sub-diffusive, γ < 0.5):
  from t_g to the longest lag, only where the curve bends a second time (below).

**The crossover t_c** is found from the streamwise curve ⟨X′²⟩(t) itself: log⟨X′²⟩ against
log t is fitted by two straight segments that meet at a breakpoint (continuous
piecewise-linear least squares, the breakpoint scanned on a fine grid), after the curve is
interpolated onto a grid of 20 points per decade fixed in absolute log t (so that curves
sampled at different lags weigh each decade alike). The uncertainty of t_c is the 95 %
interval of the breakpoints refitted to the bootstrap curves (below). For grains that hop
with independent velocities, the breakpoint sits where the ballistic asymptote var(u) t²
meets the diffusive one, t_c ≈ E[T²]/E[T] ≈ the typical jump duration, so ½ t_c and 3 t_c
are the fractions of T_J the ranges always used. The spanwise curve's breakpoint is fitted
too and reported (``crossover_z``), not used.

**The global range** is found from the same curve by a continuous **three**-segment fit
of log⟨X′²⟩ against log t on the same grid (:func:`global_bend`; both breakpoints t_c <
t_g scanned jointly, 0.005 decade apart, each segment at least ``CROSSOVER_MIN_SIDE`` grid
points). The second bend is accepted only when (1) neither breakpoint falls at an end of
its scan, (2) the log–log slope drops across t_c by ``CROSSOVER_MIN_DROP`` = 0.2 and
(3) across t_g by ``GLOBAL_MIN_DROP`` = 0.3 (γ by 0.15), (4) at least
``GLOBAL_MIN_BEYOND`` = 8 grid points (0.4 decade) lie beyond t_g, and (5) the 2.5 % bound
of t_g's bootstrap interval is at least 3 t_c · 10^0.2, so that the intermediate window
[3 t_c, t_g] holds its ``MIN_POINTS`` lags in nearly every replicate (a gradual single
bend, which three segments split in two, fails this). Otherwise no global range is
reported (``result["global_bend"]["reason"]`` says which test failed) and nothing below
changes. t_g's 95 % interval comes from the bootstrap curves, as t_c's.

**Rule for the windows** (each range not given in ``ranges``), the same for a tracks
DataFrame, a tracks file and a run directory:

1. ``jump_duration=`` given: [first lag, ½ T_J] and [3 T_J, longest lag];
2. otherwise the crossover t_c of ⟨X′²⟩: [first lag, ½ t_c] and [3 t_c, longest lag];
3. only when no crossover is found (the fit's breakpoint falls at an end of the curve, or
   the slope does not drop across it by ``CROSSOVER_MIN_DROP``): the typical jump duration
   T_J from the data, as 1;
4. where the three-segment fit accepts a second bend t_g: the intermediate window ends at
   t_g, the global window is [t_g, longest lag], and in 2 t_c is the three-segment fit's
   first breakpoint (a two-segment fit of a three-range curve puts its one breakpoint
   between the two bends). Without a second bend the windows are those of 1–3 and there
   is no global range.

T_J from the data is the median duration of the counted jumps in jumps.parquet (each
grain's first 10 dropped, paper §3.2) or, from tracks with a centre height y, the median
time between successive bed contacts (local minima of y below 1.5 d). It is reported
(``jump_duration``) as a cross-check of t_c; it does not set the windows unless rule 3
applies, because the two estimates differ (on the default run 1.7 d/u* from jumps.parquet,
3 d/u* from the 0.5 d/u* track samples) and a DataFrame does not see jumps.parquet. So a
run directory and its tracks DataFrame give the same windows: identical when the curves
are (variance.parquet sampled as the tracks, or no variance.parquet), within the
bootstrap interval of t_c when variance.parquet is sampled more finely than the tracks.

Uncertainty: the bootstrap over grains — grains (or groups of grains: variance.py) are
resampled with replacement, the curves and the fits recomputed; ``ci_low``/``ci_high``
are the 2.5 and 97.5 percentiles of γ (a 95 % interval). It covers the sampling noise of
the ensemble, not the choice of model: where the bend from ballistic to intermediate is
gradual, t_c also depends on how far the curve reaches on each side.

Entry point (SPEC §9): ``exponents(tracks, ranges=None)`` with ``tracks`` a tracks
DataFrame (columns particle, t, x, z, optionally y, …; t in d/u*, x, z unwrapped in d) or
a run directory (variance.parquet is used when present, tracks.parquet otherwise). The
result is a dict ``{"local": {"gamma_x", "gamma_z", …}, "intermediate": {…}, "global": {…}
(only where seen), "windows": …, "crossover": …, "global_bend": …}`` with ``.table`` (tidy DataFrame) and ``.curves`` (the variance curves).
``read_tracks_file`` reads a CSV or Parquet file of tracks (``saltation analyze FILE``).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..engine.statistics import DISCARDED_JUMPS  # paper §3.2, as the run's statistics
from .variance import VARIANCE_FILE, AnalysisError, VarianceAccumulator, make_plan, read_sums, variance_curves

__all__ = ["exponents", "DiffusionResult", "AnalysisError", "crossover", "global_bend", "jump_duration_from_tracks",
           "read_tracks_file", "sums_from_tracks"]

MIN_PARTICLES = 10  # fewer grains give no meaningful ensemble variance
MIN_POINTS = 5  # lags a range must hold for a log–log fit
LOCAL_FRACTION = 0.5  # local range ends at t_c / 2 (or T_J / 2)
INTERMEDIATE_START = 3.0  # intermediate range starts at 3 t_c (or 3 T_J)
CROSSOVER_PER_DECADE = 20  # grid of the two-segment fit, points per decade of t
CROSSOVER_SUBSTEPS = 10  # candidate breakpoints per grid interval (0.005 decade apart)
CROSSOVER_MIN_SIDE = 4  # grid points each segment holds at least
CROSSOVER_MIN_DROP = 0.2  # log–log slope must fall by this (γ by 0.1) across the breakpoint
CROSSOVER_DIRECTION = "x"  # the curve whose breakpoint sets the windows
CONTACT_HEIGHT = 1.5  # d: a local minimum of the centre height below this is a bed contact
N_BOOTSTRAP = 400
GLOBAL_MIN_DROP = 0.3  # log–log slope must fall by this (γ by 0.15) across the second breakpoint t_g
GLOBAL_MIN_BEYOND = 8  # grid points beyond t_g at least (0.4 decade: 8 lags of the 20-per-decade plan)
RANGE_NAMES = ("local", "intermediate")  # the ranges always fitted (and compared with the paper)
GLOBAL = "global"  # the third range, fitted only where the curve shows a second bend
ALL_RANGES = RANGE_NAMES + (GLOBAL,)
TABLE_COLUMNS = ["direction", "range", "t_min", "t_max", "gamma", "ci_low", "ci_high", "alpha",
                 "n_points", "n_particles", "n_origins", "source", "windows_from", "t_c", "t_c_low", "t_c_high"]
GLOBAL_COLUMNS = ["t_g", "t_g_low", "t_g_high"]  # added to the table only where a global range is seen
TRACK_COLUMNS = {"particle": "grain id", "t": "time, d/u*", "x": "streamwise position, unwrapped, d",
                 "z": "spanwise position, unwrapped, d"}


class DiffusionResult(dict):
    """``{"local": {...}, "intermediate": {...}, "global": {...} (only where a second bend is
    seen), "windows": {...}, "windows_from": {...}, "crossover": {...}, "crossover_z": {...},
    "global_bend": {...}, "jump_duration": T_J, "jump_duration_from": …}``.

    Each range entry holds gamma_x, gamma_z, their 95 % bootstrap intervals (ci_x, ci_z),
    t_min, t_max (d/u*) and n_points. ``windows_from`` says per range what set its window
    ("ranges", "jump_duration", "crossover", "jump_duration (no crossover: …)" or, for the
    global range, "second bend"); ``crossover`` is the two-segment fit of ⟨X′²⟩
    (:func:`crossover`), ``crossover_z`` that of ⟨Z′²⟩ (reported only), ``global_bend`` the
    three-segment fit of ⟨X′²⟩ (:func:`global_bend`: t_c, t_g and their intervals, or why no
    global range is seen). ``jump_duration`` is T_J as given or found from the data
    (None if unknown), ``jump_duration_from`` where it came from ("given", "jumps.parquet",
    "bed contacts in the tracks" or None). Attributes: ``table`` (tidy rows: direction, range, t_min, t_max,
    gamma, ci_low, ci_high, alpha, n_points, n_particles, n_origins, source, windows_from,
    t_c, t_c_low, t_c_high — t_c being the crossover that set the windows — and, only where a
    global range is seen, t_g, t_g_low, t_g_high), ``curves`` (lag t, var_x, var_z, n_origins) and ``problems``
    (ranges that could not be fitted, with the reason; empty unless ``strict=False``).
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


def _expected_columns() -> str:
    return ", ".join(f"{k} ({v})" for k, v in TRACK_COLUMNS.items())


def read_tracks_file(path, *, diameter: float = 1.0, time_scale: float = 1.0) -> pd.DataFrame:
    """A tracks table from a CSV or Parquet file, in the units ``exponents`` takes.

    Columns: particle, t, x, z required (y and any others optional and kept). t in d/u*,
    x, z (and y) in d, x and z unwrapped (no periodic jumps); one row per grain and sample
    time, every grain sampled at the same evenly spaced times. Other units: ``diameter``
    is the grain diameter in the file's length unit (x, y, z are divided by it),
    ``time_scale`` the time d/u* in the file's time unit (t is divided by it); γ does not
    depend on them, t_c, the windows and α do. Sample times written with few digits are
    snapped to the grid of the median spacing (within 1 % of a spacing).
    """
    path = Path(path)
    if not path.is_file():
        raise AnalysisError(f"{path} is not a file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        frame = pd.read_csv(path)
    elif suffix in (".parquet", ".pq"):
        frame = pd.read_parquet(path)
    else:
        raise AnalysisError(f"{path}: a tracks file must be .csv or .parquet (columns {_expected_columns()})")
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in TRACK_COLUMNS if c not in frame.columns]
    if missing:
        raise AnalysisError(f"{path} lacks column(s) {', '.join(missing)}: a tracks file needs {_expected_columns()}; "
                            f"y (centre height, d) and others are optional. It has: {', '.join(frame.columns) or 'none'}")
    if not (diameter > 0 and time_scale > 0):
        raise AnalysisError(f"diameter = {diameter}, time_scale = {time_scale}: both must be positive")
    bad = [c for c in ("t", "x", "z", "y") if c in frame.columns and not pd.api.types.is_numeric_dtype(frame[c])]
    if bad:
        raise AnalysisError(f"{path}: column(s) {', '.join(bad)} are not numeric")
    frame = frame.copy()
    frame["t"] = frame["t"].astype(float) / time_scale
    for c in ("x", "y", "z"):
        if c in frame.columns:
            frame[c] = frame[c].astype(float) / diameter
    times = np.unique(frame["t"].to_numpy())
    if len(times) > 2:
        dt = float(np.median(np.diff(times)))
        k = (frame["t"].to_numpy() - times[0]) / dt
        if dt > 0 and np.max(np.abs(k - np.round(k))) < 0.01:
            frame["t"] = times[0] + np.round(k) * dt
    return frame


def _tracks_grid(tracks: pd.DataFrame):
    """x, z (P, J) arrays on the uniform sample grid of the tracks, and its spacing."""
    missing = [c for c in TRACK_COLUMNS if c not in tracks.columns]
    if missing:
        raise AnalysisError(f"the tracks lack column(s) {missing}: need {_expected_columns()}")
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


def _log_grid(t, var, boot, n_segments: int):
    """log var interpolated (linearly in log–log) onto the grid log t = k ln10 / 20 inside
    the curve's span: (grid, rows, reason) with rows[0] the curve and rows[1:] the usable
    bootstrap replicates; reason is "" unless the curve is too short for ``n_segments``."""
    t, var = np.asarray(t, float), np.asarray(var, float)
    ok = (t > 0) & (var > 0) & np.isfinite(var)
    if ok.sum() < 2:
        return np.zeros(0), np.zeros((0, 0)), "the variance curve has fewer than 2 positive points"
    lt, lv = np.log(t[ok]), np.log(var[ok])
    k0 = int(np.ceil(CROSSOVER_PER_DECADE * lt[0] / np.log(10) - 1e-9))
    k1 = int(np.floor(CROSSOVER_PER_DECADE * lt[-1] / np.log(10) + 1e-9))
    grid = np.arange(k0, k1 + 1) * np.log(10) / CROSSOVER_PER_DECADE
    n = len(grid)
    if n < n_segments * CROSSOVER_MIN_SIDE + 1:
        word = {2: "two", 3: "three"}.get(n_segments, str(n_segments))
        return grid, np.zeros((0, n)), (f"the curve spans {lt[-1] / np.log(10) - lt[0] / np.log(10):.2f} decade(s) of t: "
                                        f"a {word}-segment fit needs at least "
                                        f"{(n_segments * CROSSOVER_MIN_SIDE) / CROSSOVER_PER_DECADE:.2f}")
    interp = np.stack([np.interp(grid, lt, e) for e in np.eye(len(lt))], axis=1)  # (n, len(lt))
    ys = [(interp @ lv)[None, :]]
    if boot is not None and len(boot):
        b = np.asarray(boot, float)[:, ok]
        good = (b > 0).all(axis=1) & np.isfinite(b).all(axis=1)
        if good.any():
            ys.append(np.log(b[good]) @ interp.T)
    return grid, np.concatenate(ys), ""


def crossover(t, var, boot=None, *, direction: str = CROSSOVER_DIRECTION) -> dict:
    """Ballistic-to-intermediate crossover of a variance curve: the breakpoint t_c of a
    continuous two-segment least-squares fit of log ``var`` against log ``t``.

    The curve is interpolated (linearly in log–log) onto the grid t = 10^(k/20) inside its
    span, so the fit weighs each decade alike whatever the lags; candidate breakpoints lie
    0.005 decade apart with at least ``CROSSOVER_MIN_SIDE`` grid points on each side.
    ``boot`` (B, len(t)): bootstrap replicates of the curve, refitted for the 95 %
    interval of t_c (replicates whose breakpoint falls at an end of the scan count as
    no crossover). Returns {"found", "t_c", "ci" (2.5, 97.5 %), "gamma_before",
    "gamma_after" (half the two slopes), "var_c" (the fit's value at t_c, d²: the segments are
    var_c (t/t_c)^(2γ)), "fit_range", "n_points" (grid points),
    "n_boot" (replicates with a crossover), "direction", "reason" (why none was found)}.
    """
    out = {"direction": direction, "found": False, "t_c": None, "ci": (float("nan"), float("nan")),
           "gamma_before": None, "gamma_after": None, "var_c": None, "fit_range": None, "n_points": 0, "n_boot": 0, "reason": ""}
    grid, yy, why = _log_grid(t, var, boot, 2)
    out["n_points"] = len(grid)
    if why:
        out["reason"] = why
        return out
    n, y = len(grid), yy[0]
    out["fit_range"] = (float(np.exp(grid[0])), float(np.exp(grid[-1])))
    lo, hi = grid[CROSSOVER_MIN_SIDE - 1], grid[n - CROSSOVER_MIN_SIDE]
    cands = np.linspace(lo, hi, max(2, round((hi - lo) / (grid[1] - grid[0]) * CROSSOVER_SUBSTEPS) + 1))
    design = np.stack([np.ones((len(cands), n)), np.minimum(grid[None, :] - cands[:, None], 0.0),
                       np.maximum(grid[None, :] - cands[:, None], 0.0)], axis=-1)  # (C, n, 3)
    q, _ = np.linalg.qr(design)
    proj = np.einsum("bn,cnk->bck", yy, q)
    sse = (yy * yy).sum(axis=1)[:, None] - (proj * proj).sum(axis=-1)  # (B+1, C)
    best = np.argmin(sse, axis=1)
    interior = (best > 0) & (best < len(cands) - 1)
    c = cands[best[0]]
    coef, *_ = np.linalg.lstsq(design[best[0]], y, rcond=None)
    out["gamma_before"], out["gamma_after"] = 0.5 * float(coef[1]), 0.5 * float(coef[2])
    out["var_c"] = float(np.exp(coef[0]))
    tb = np.exp(cands[best[1:][interior[1:]]])
    out["n_boot"] = len(tb)
    if len(tb) >= 20:
        out["ci"] = tuple(float(v) for v in np.percentile(tb, [2.5, 97.5]))
    if not interior[0]:
        end = "first" if best[0] == 0 else "last"
        out["reason"] = (f"the two-segment fit of ⟨{direction.upper()}′²⟩ puts its breakpoint at the {end} admissible "
                         f"lag ({np.exp(c):.3g} d/u*): no bend from the ballistic to the intermediate range within "
                         f"{out['fit_range'][0]:.3g}–{out['fit_range'][1]:.3g} d/u* (a record too short, or sampled too "
                         "coarsely)")
        return out
    drop = coef[1] - coef[2]
    if drop < CROSSOVER_MIN_DROP:
        out["reason"] = (f"the log–log slope of ⟨{direction.upper()}′²⟩ changes from {coef[1]:.2f} to {coef[2]:.2f} "
                         f"across the best breakpoint ({np.exp(c):.3g} d/u*): no drop of at least {CROSSOVER_MIN_DROP} "
                         "from a ballistic to an intermediate range")
        return out
    out["found"], out["t_c"] = True, float(np.exp(c))
    return out


def _three_segment_sse(yy, g, cands, i, j):
    """Least-squares SSE and coefficients (a, s1, d1, d2) of rows ``yy`` (B, n) against the
    continuous three-segment model a + s1 g + d1 (g − c_i)+ + d2 (g − c_j)+, for candidate
    pairs (i, j) given as index arrays broadcastable to (B, P)."""
    h = np.maximum(g[None, :] - cands[:, None], 0.0)  # (C, n) hinges
    hi, hj = h[i], h[j]  # (…, P, n) or (B, P, n)
    n = len(g)
    shape = np.broadcast_shapes(hi.shape, hj.shape)
    m = np.empty(shape[:-1] + (4, 4))
    m[..., 0, 0], m[..., 0, 1] = n, g.sum()
    m[..., 1, 1] = g @ g
    m[..., 0, 2], m[..., 0, 3] = hi.sum(-1), hj.sum(-1)
    m[..., 1, 2], m[..., 1, 3] = hi @ g, hj @ g
    m[..., 2, 2], m[..., 3, 3] = (hi * hi).sum(-1), (hj * hj).sum(-1)
    m[..., 2, 3] = (hi * hj).sum(-1)
    iu = np.triu_indices(4, 1)
    m[..., iu[1], iu[0]] = m[..., iu[0], iu[1]]
    hy = yy @ h.T  # (B, C)
    rows = np.arange(len(yy))[:, None]
    ib, jb = np.broadcast_to(i, (len(yy),) + np.shape(i)[-1:]), np.broadcast_to(j, (len(yy),) + np.shape(j)[-1:])
    v = np.stack(np.broadcast_arrays(yy.sum(1)[:, None], (yy @ g)[:, None], hy[rows, ib], hy[rows, jb]), axis=-1)
    coef = np.linalg.solve(m, v[..., None])[..., 0]  # (B, P, 4)
    sse = (yy * yy).sum(1)[:, None] - (coef * v).sum(-1)
    return sse, coef


def global_bend(t, var, boot=None, *, direction: str = CROSSOVER_DIRECTION) -> dict:
    """The second bend of a variance curve, into the **global** range (Nikora et al. 2002:
    many rest periods, resting grains make it sub-diffusive): the two breakpoints t_c < t_g
    of a continuous three-segment least-squares fit of log ``var`` against log t, on the
    same 20-per-decade grid as :func:`crossover`.

    Both breakpoints are scanned jointly on the candidates of :func:`crossover` (0.005 decade
    apart, every segment holding at least ``CROSSOVER_MIN_SIDE`` grid points): first on the
    grid points, then refined within ±1 grid interval of the best pair. ``boot``
    replicates are refitted alike for the 95 % intervals of t_c and t_g. The second bend is
    **accepted** (``found``) only when (1) neither breakpoint falls at an end of its scan,
    (2) the log–log slope drops across t_c by ``CROSSOVER_MIN_DROP`` (a ballistic-to-
    intermediate crossover), (3) it drops across t_g by ``GLOBAL_MIN_DROP``, (4) at least
    ``GLOBAL_MIN_BEYOND`` grid points (0.4 decade) lie beyond t_g, and (5) the lower (2.5 %)
    bound of t_g's bootstrap interval (t_g itself without replicates) is at least
    ``INTERMEDIATE_START`` t_c · 10^((MIN_POINTS − 1)/20): the intermediate window [3 t_c,
    t_g] keeps its ``MIN_POINTS`` lags in nearly every replicate (a gradual ballistic-to-
    intermediate bend, which a three-segment fit splits in two, fails this); otherwise ``reason`` says which failed and
    no global range is reported. Returns {"found", "t_c", "t_c_ci", "t_g", "ci" (of t_g,
    2.5, 97.5 %), "gammas" (half the three slopes), "var_c", "var_g" (the fit at t_c, t_g,
    d²), "fit_range", "n_points", "n_beyond" (grid points beyond t_g), "n_boot", "direction",
    "reason"}.
    """
    nan2 = (float("nan"), float("nan"))
    out = {"direction": direction, "found": False, "t_c": None, "t_c_ci": nan2, "t_g": None, "ci": nan2,
           "gammas": None, "var_c": None, "var_g": None, "fit_range": None, "n_points": 0, "n_beyond": 0, "n_boot": 0,
           "reason": ""}
    grid, yy, why = _log_grid(t, var, boot, 3)
    out["n_points"] = n = len(grid)
    if why:
        out["reason"] = why + " (no global range)"
        return out
    out["fit_range"] = (float(np.exp(grid[0])), float(np.exp(grid[-1])))
    step = grid[1] - grid[0]
    sub = CROSSOVER_SUBSTEPS
    lo, hi = grid[CROSSOVER_MIN_SIDE - 1], grid[n - CROSSOVER_MIN_SIDE]
    n_c = int(round((hi - lo) / step * sub)) + 1
    cands = np.linspace(lo, hi, n_c)
    gap = (CROSSOVER_MIN_SIDE - 1) * sub  # the middle segment holds CROSSOVER_MIN_SIDE grid points too
    mid = grid.mean()
    g, c = grid - mid, cands - mid
    coarse = np.arange(0, n_c, sub)
    ii, jj = np.meshgrid(coarse, coarse, indexing="ij")
    keep = jj - ii >= gap
    ii, jj = ii[keep], jj[keep]
    sse, _ = _three_segment_sse(yy, g, c, ii, jj)
    best = np.argmin(sse, axis=1)
    bi, bj = ii[best], jj[best]  # (B,)
    d = np.arange(-sub, sub + 1)
    ri = np.clip(bi[:, None, None] + d[None, :, None], 0, n_c - 1) + 0 * d[None, None, :]
    rj = np.clip(bj[:, None, None] + d[None, None, :], 0, n_c - 1) + 0 * d[None, :, None]
    ri, rj = ri.reshape(len(yy), -1), rj.reshape(len(yy), -1)
    sse, coef = _three_segment_sse(yy, g, c, ri, rj)
    sse = np.where(rj - ri >= gap, sse, np.inf)
    k = np.argmin(sse, axis=1)
    rows = np.arange(len(yy))
    fi, fj, fc = ri[rows, k], rj[rows, k], coef[rows, k]
    interior = (fi > 0) & (fj < n_c - 1)
    b1, b2 = cands[fi[0]], cands[fj[0]]
    a, s1, d1, d2 = fc[0]
    slopes = (s1, s1 + d1, s1 + d1 + d2)
    out["gammas"] = tuple(0.5 * float(v) for v in slopes)
    out["t_c"], out["t_g"] = float(np.exp(b1)), float(np.exp(b2))
    out["var_c"] = float(np.exp(a + s1 * (b1 - mid)))
    out["var_g"] = float(np.exp(a + s1 * (b2 - mid) + d1 * (b2 - b1)))
    out["n_beyond"] = n_beyond = int((grid > b2 + 1e-9).sum())
    ok_b = interior[1:]
    out["n_boot"] = int(ok_b.sum())
    if ok_b.sum() >= 20:
        out["t_c_ci"] = tuple(float(v) for v in np.exp(np.percentile(cands[fi[1:][ok_b]], [2.5, 97.5])))
        out["ci"] = tuple(float(v) for v in np.exp(np.percentile(cands[fj[1:][ok_b]], [2.5, 97.5])))
    lab = f"⟨{direction.upper()}′²⟩"
    room = INTERMEDIATE_START * out["t_c"] * 10 ** ((MIN_POINTS - 1) / CROSSOVER_PER_DECADE)
    low_g = out["ci"][0] if np.isfinite(out["ci"][0]) else out["t_g"]
    if not interior[0]:
        end = "first admissible lag" if fi[0] == 0 else "last admissible lag"
        out["reason"] = (f"the three-segment fit of {lab} puts a breakpoint at the {end} "
                         f"({np.exp(b1 if fi[0] == 0 else b2):.3g} d/u*): no second bend within "
                         f"{out['fit_range'][0]:.3g}–{out['fit_range'][1]:.3g} d/u*")
    elif slopes[0] - slopes[1] < CROSSOVER_MIN_DROP:
        out["reason"] = (f"the three-segment fit of {lab} has no ballistic-to-intermediate bend at its first breakpoint "
                         f"({out['t_c']:.3g} d/u*: log–log slope {slopes[0]:.2f} to {slopes[1]:.2f}, a drop below "
                         f"{CROSSOVER_MIN_DROP})")
    elif slopes[1] - slopes[2] < GLOBAL_MIN_DROP:
        out["reason"] = (f"the log–log slope of {lab} changes from {slopes[1]:.2f} to {slopes[2]:.2f} across the second "
                         f"breakpoint ({out['t_g']:.3g} d/u*): no drop of at least {GLOBAL_MIN_DROP} into a global range")
    elif n_beyond < GLOBAL_MIN_BEYOND:
        out["reason"] = (f"the second breakpoint of {lab} ({out['t_g']:.3g} d/u*, slope {slopes[1]:.2f} to {slopes[2]:.2f}) "
                         f"has {n_beyond} grid point(s) ({n_beyond / CROSSOVER_PER_DECADE:.2f} decade) beyond it; a global "
                         f"range needs {GLOBAL_MIN_BEYOND} ({GLOBAL_MIN_BEYOND / CROSSOVER_PER_DECADE:.2f} decade): a longer "
                         "record would show whether there is one")
    elif low_g < room:
        which = "the 2.5 % bound of its bootstrap interval" if np.isfinite(out["ci"][0]) else "it"
        out["reason"] = (f"the second breakpoint of {lab} ({out['t_g']:.3g} d/u*, {which} {low_g:.3g} d/u*) is not "
                         f"clearly beyond {room:.3g} d/u* = {INTERMEDIATE_START:g} t_c x 10^"
                         f"{(MIN_POINTS - 1) / CROSSOVER_PER_DECADE:g} (t_c = {out['t_c']:.3g} d/u*): a gradual "
                         f"ballistic-to-intermediate bend split in two, not an intermediate range of {MIN_POINTS} lags "
                         "followed by a global one")
    else:
        out["found"] = True
    return out


def _auto_ranges(t_first: float, t_max: float, jump_duration: float | None, given: dict,
                 cross: dict | None = None, jump_given: bool = False, bend: dict | None = None) -> tuple[dict, dict, dict]:
    """Windows of the ranges (the module docstring's rule), the problems, and per range
    what set its window."""
    ranges, problems, origin = {}, {}, {}
    second = bend is not None and bend["found"]
    for name in RANGE_NAMES:
        if name in given and given[name] is not None:
            continue
        if jump_given:
            scale, origin[name] = jump_duration, "jump_duration"
        elif second:
            scale, origin[name] = bend["t_c"], "crossover"
        elif cross is not None and cross["found"]:
            scale, origin[name] = cross["t_c"], "crossover"
        elif jump_duration is not None:
            why = cross["reason"] if cross is not None else "not fitted"
            scale, origin[name] = jump_duration, f"jump_duration (no crossover: {why})"
        else:
            why = f"no ballistic-to-intermediate crossover in ⟨X′²⟩ ({cross['reason']}), and " if cross else ""
            problems[name] = (why + "the typical jump duration could not be found (no jumps.parquet and no bed "
                              "contacts in the tracks): give ranges={'local': (t0, t1), 'intermediate': (t2, t3)} in "
                              "d/u* or jump_duration=")
            continue
        if name == "local":
            ranges[name] = (t_first, LOCAL_FRACTION * scale)
        else:
            ranges[name] = (INTERMEDIATE_START * scale, bend["t_g"] if second else t_max)
    if second and given.get(GLOBAL) is None:
        ranges[GLOBAL], origin[GLOBAL] = (bend["t_g"], t_max), "second bend"
    for name, win in given.items():
        if win is None:
            continue
        lo, hi = (float(v) for v in win)
        if not (0 < lo < hi):
            raise AnalysisError(f"ranges[{name!r}] = {win!r}: must be (t_min, t_max) in d/u* with 0 < t_min < t_max")
        ranges[name] = (lo, hi)
        origin[name] = "ranges"
    return ranges, problems, origin


def exponents(tracks, ranges=None, *, jump_duration: float | None = None, n_bootstrap: int = N_BOOTSTRAP,
              n_origins: int = 8, seed: int = 0, strict: bool = True) -> DiffusionResult:
    """γx, γz over the local and intermediate ranges, and the global range where the curve
    shows it (SPEC §6, §9).

    ``tracks``: a tracks DataFrame (t in d/u*, x, z unwrapped in d) or a run directory.
    ``ranges``: ``{"local": (t_min, t_max), "intermediate": (t_min, t_max), "global": …}`` in
    d/u*; a range left out is set from ``jump_duration`` (T_J, d/u*) when given, else from
    the crossover t_c of ⟨X′²⟩ (:func:`crossover`), else from T_J found in the data, and
    the intermediate range ends where the global one begins, at t_g, where
    :func:`global_bend` finds a second bend (the module docstring's rule). ``n_origins``:
    time origins of the statistics for tracks (1: from a release at the first origin). ``strict``: raise :class:`AnalysisError` when a range cannot be fitted
    (default); with ``strict=False`` such ranges are left out and ``result.problems`` says why.
    """
    given = dict(ranges or {})
    jump_given = jump_duration is not None
    jump_from = "given" if jump_given else None
    source = "tracks"
    if isinstance(tracks, (str, Path)):
        run_dir = Path(tracks)
        if not run_dir.is_dir():
            raise AnalysisError(f"{run_dir} is not a run directory")
        if jump_duration is None and (run_dir / "jumps.parquet").exists():
            jump_duration = _jump_duration_from_file(run_dir / "jumps.parquet")
            jump_from = "jumps.parquet" if jump_duration is not None else None
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
                jump_from = "bed contacts in the tracks" if jump_duration is not None else None
            sums, lags, meta = sums_from_tracks(frame, n_origins=n_origins)
            source = "tracks.parquet"
        else:
            raise AnalysisError(f"{run_dir} has neither {VARIANCE_FILE} nor tracks.parquet: run with "
                                f"output.variance = true (or output.tracks = true) to get diffusion statistics")
    elif isinstance(tracks, pd.DataFrame):
        if jump_duration is None and not all(n in given for n in RANGE_NAMES):
            jump_duration = jump_duration_from_tracks(tracks) if len(tracks) else None
            jump_from = "bed contacts in the tracks" if jump_duration is not None else None
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

    # bootstrap weights over groups of grains (groups = grains unless variance.parquet pooled them)
    rng = np.random.default_rng(seed)
    g = sums.shape[0]
    draws = rng.integers(0, g, size=(n_bootstrap, g))
    weights = np.zeros((n_bootstrap, g))
    np.add.at(weights, (np.arange(n_bootstrap)[:, None], draws), 1.0)
    bx, bz, _ = variance_curves(sums, weights)
    keep = np.isin(lags, curves["t"].to_numpy())
    bx, bz = bx[:, keep], bz[:, keep]

    t = curves["t"].to_numpy()
    cross = crossover(t, curves["var_x"].to_numpy(), bx, direction="x")
    cross_z = crossover(t, curves["var_z"].to_numpy(), bz, direction="z")
    bend = global_bend(t, curves["var_x"].to_numpy(), bx, direction="x")
    win, problems, origin = _auto_ranges(t_first, t_last, jump_duration, given, cross, jump_given, bend)
    if bend["found"]:
        t_c_row = {"t_c": bend["t_c"], "t_c_low": bend["t_c_ci"][0], "t_c_high": bend["t_c_ci"][1],
                   "t_g": bend["t_g"], "t_g_low": bend["ci"][0], "t_g_high": bend["ci"][1]}
    else:
        t_c_row = {"t_c": cross["t_c"] if cross["found"] else float("nan"), "t_c_low": cross["ci"][0],
                   "t_c_high": cross["ci"][1]}

    result = DiffusionResult()
    rows = []
    for name, (lo, hi) in win.items():
        sel = (t >= lo * (1 - 1e-9)) & (t <= hi * (1 + 1e-9))
        npts = int(sel.sum())
        if npts < MIN_POINTS:
            problems[name] = _too_few_points(name, lo, hi, npts, dt, t_last, _basis(origin[name], jump_duration, bend if bend["found"] else cross))
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
                         "n_particles": n_particles, "n_origins": int(curves["n_origins"][sel].min()), "source": source,
                         "windows_from": origin[name], **t_c_row})
        result[name] = entry
    if problems and strict:
        raise AnalysisError("; ".join(f"{k}: {v}" for k, v in problems.items()))
    result["windows"] = {k: v for k, v in win.items()}
    result["windows_from"] = dict(origin)
    result["crossover"] = cross
    result["crossover_z"] = cross_z
    result["global_bend"] = bend
    result["jump_duration"] = jump_duration
    result["jump_duration_from"] = jump_from
    result["sample_interval"] = dt
    result["n_particles"] = n_particles
    result["source"] = source
    result.table = pd.DataFrame(rows, columns=TABLE_COLUMNS + (GLOBAL_COLUMNS if bend["found"] else []))
    result.curves = curves
    result.problems = problems
    return result


def _basis(origin: str, jump_duration, cross) -> str:
    """What a window was scaled by, for messages."""
    if origin == "crossover":
        return f", crossover t_c = {cross['t_c']:.3g} d/u*"
    if origin == "second bend":
        return f", second bend t_g = {cross['t_g']:.3g} d/u*"
    if origin.startswith("jump_duration") and jump_duration:
        return f", T_J = {jump_duration:.3g} d/u*"
    return ""


def _too_few_points(name, lo, hi, npts, dt, t_last, tj) -> str:
    need = f"at least {MIN_POINTS} are needed"
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
