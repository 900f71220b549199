"""Basset history force: window + exponential tail (SPEC §2).

    a_bs(t) = -P · I(t),   I(t) = ∫₀ᵗ (du_r/dτ) (t - τ)^(-1/2) dτ,   P = 9α/√(π Re*)

(particle units; ``basset_acceleration_prefactor``).  ``u_r = u_p - u_f`` is
the slip velocity; t = 0 is the last reset (see below).

Scheme (van Hinsberg, ten Thije Boonkkamp & Clercx 2011, J. Comput. Phys.
230:1465)
--------------------------------------------------------------------------
Split the integral at lag t_win = N_w Δt.

*Window* (lags 0 … t_win).  g = du_r/dτ is interpolated linearly between the
nodes t - nΔt and the kernel s^(-1/2) is integrated exactly on each interval:

    I_win = √Δt Σ_{n=0}^{N} β_n g_n,
    β_0 = 4/3,  β_n = (4/3)[(n-1)^{3/2} - 2n^{3/2} + (n+1)^{3/2}],
    β_N = (4/3)[(N-1)^{3/2} - N^{3/2} + (3/2)√N]

(evaluated here interval by interval in a cancellation-free form).  The node
derivatives come from the stored slip samples by second-order finite
differences: central inside, three-point one-sided at the newest sample and at
t = 0.  The two linear maps are folded into one table of weights on the slip
samples, so I_win is a single dot product over the N_w + 2 newest samples.

*Tail* (lags > t_win).  For s ≥ t_win, s^(-1/2) ≈ Σᵢ aᵢ √(e/tᵢ) exp(-s/(2tᵢ)),
tᵢ = t̃ᵢ t_win, m = 10 published pairs (t̃ᵢ, aᵢ) of SPEC §2.  Each mode
Fᵢ = ∫ √(e/tᵢ) exp(-(t-τ)/(2tᵢ)) g(τ) dτ over the tail obeys

    Fᵢ(t+Δt) = exp(-Δt/(2tᵢ)) Fᵢ(t) + [contribution of the interval that
               just left the window, g linear on it, exponential integrated
               exactly],

so I_tail = Σ aᵢ Fᵢ costs O(m) work and memory.  Both parts are second order
in Δt.  The exponential sum approximates the kernel to a relative error of
6e-5 at s = t_win, 2e-3 at 10 t_win, 6e-3 at 100 t_win and 3 % at 1000 t_win
(it under-estimates far memory), so choose t_win of the order of a tenth of
the longest history (a jump) or more.

State (allocated by the caller for all N particles; ``allocate_history_state``)
-----------------------------------------------------------------------------
===============  ====================  =========================================
slip_hist        float64 [N, N_w+2, 3]  ring buffer of slip samples u_r(t - jΔt)
meta             int64   [N, 3+J]       META_HEAD: slot of the newest sample,
                                        META_COUNT: samples since reset
                                        (capped at N_w + 2; negative: an impact
                                        is pending), META_PENDING: that impact's
                                        age, then the J = N_JUMPS ages (ticks)
tail             float64 [N, m+J, 3]    tail modes Fᵢ, then the kept steps Δu_r
===============  ====================  =========================================

Memory per particle: 24 N_w + 312 + 32 J bytes (N_w = 100, J = 4: 2 840 B),
independent of the run length.  Shared coefficients (``make_history_coefficients``): a weight
table of (N_w+3)·(N_w+2) doubles (81 kB for N_w = 100) and 4 arrays of m.

Use inside classic RK4 (the choice made here)
---------------------------------------------
The integral at an RK4 stage time would need the stage slip as a new node.
Instead the history term is integrated over each step by the trapezoidal rule
with its newest-node part implicit:

    at the start of step n:  I_n = history_integral(...)  (or carried, below)
    in every stage:          a_bs = -P I_n     (held; add_basset_acceleration)
    after the RK4 update u*: history_end_step(u*, u_f(x_{n+1}, t_{n+1}), I_n, ...,
                                              i_next)

``history_end_step`` replaces the held value by the trapezoidal average
-PΔt (I_n + I_{n+1})/2, where I_{n+1} = I*_{n+1} + γ₀ u_r(t_{n+1}) is linear in
the unknown end slip (γ₀ ≈ 2.55/√Δt is the weight of the newest sample, I*
everything else, known once the window has been advanced):

    u_{n+1} (1 + PΔtγ₀/2) = u* - (PΔt/2) (I*_{n+1} - γ₀ u_f,{n+1} - I_n),

then stores u_r(t_{n+1}) = u_{n+1} - u_f,{n+1} as the newest sample and
returns I_{n+1} (``i_next``): a caller keeping I per particle ([N, 3], 24 B
more) carries it to the next step and never needs ``history_integral`` in the
loop (after a reset I = 0 exactly).  With the Basset term switched off no history
call is needed at all.  The
correction is O(Δt² ΔI)·P per step, so positions may be left alone (the exact
displacement of the correction, which grows linearly over the step, is
(Δt/3)(u_{n+1} - u*); adding it is optional).

Why: the trapezoidal average is second order; the stages see the history held
constant, which perturbs the other forces' stage values by O(Δt² İ), an
O(Δt³) local error; and the implicit newest-node weight removes the
instability of lagged feedback (an explicit treatment, e.g. extrapolating I
over the step, is unstable once P√Δt ≳ 0.2, i.e. Δt ≳ 0.1 τ_p for small
grains).  The combined scheme is therefore second order where the history is
smooth; RK4's fourth order for the other terms is not reached.  Right after a
reset the history starts with a finite acceleration, I ≈ 2 g(0) √t, whose
curvature is singular at t = 0, and the error sums to O(Δt^{3/2}).  The tests
measure both orders against exact solutions of the Basset equation.

Impacts and contacts keep the history (default; SPEC §2 revised)
------------------------------------------------------------------
A bed impact or a grain contact changes the slip impulsively: a step Δu_r at t_c, whose
exact contribution to the integral is Δu_r/√(t − t_c). Lukerchenko et al. (2012) show
that this collision-generated part of the Basset force is of the same size as the
flight part and largely cancels it, so it is kept: the impact site only *marks* the
history (``history_mark_impact``: the sample count turns negative, nothing is lost), and
the next step (``history_start_step``) finds the step in the slip, Δu_r = u_r(now) −
newest sample, and

* shifts the stored samples by Δu_r, so the window keeps a continuous (smooth) slip whose
  quadrature is unchanged (its node derivatives are differences of samples);
* keeps the step exactly in one of N_JUMPS slots per grain (its age in ``meta[META_JUMPS
  + j]``, in ticks of 1/AGE_TICKS step, −1 when free; Δu_r in ``tail[N_MODES + j]``): over each step
  [t_n, t_n + Δt] it adds the exact impulse −P Δu_r · 2(√(t_n + Δt − t_c) − √(t_n − t_c))
  (``history_end_step``), no quadrature of the singular kernel;
* once the step is a window length old (t − t_c = t_win) it passes into the exponential
  tail modes exactly — mode i gains √(e/tᵢ) exp(−(t − t_c)/(2tᵢ)) Δu_r, the tail's own
  kernel — and the slot is freed. More than N_JUMPS steps inside one window (a grain
  chattering on the bed) fold the oldest early, with the tail kernel at its age.

The step's time t_c is where it happened: an impact on the virtual bed at a fraction s
of its hydrodynamic step marks it ``(1 − s)`` steps old at the step's end
(``history_mark_impact_at``; flight/spheres._bed_impact, which also gives the grain the
impulse −P Δu_r · 2√((1 − s)Δt) over the rest of that step). Contacts resolved inside
the step and packed-bed impacts are dated at the step's end (``history_mark_impact``).
Dating every bed impact at the step's end lost the first part of that impulse, 2√(φΔt)
with φ = 1 − s, a first-order error in Δt that showed as +2 % in U at Δt = 0.02 d/u*
(free flight, benchmarks/study_dt.py). This is exact up to the tail's kernel error; the
smooth part keeps its second order. The RK4 stages hold the smooth I_n only; the steps'
impulses enter at the step end (an O(Δt) change of the stage forces, not of the impulse).
Memory stays bounded: 32 bytes more per slot.

``[forces] basset_impacts = "restart"`` (kept for comparison) restarts the memory at
every impact instead (``history_reset`` with the post-rebound slip as the first sample),
the first round's choice: the history force is zero at take-off and builds up as √t
over the jump; memory of earlier jumps and of the impulsive change itself is dropped.
Release (a grain's first step) always starts a fresh history.
"""

import math
from typing import NamedTuple

import numpy as np
from numba import njit

# published tail constants (SPEC §2): times in units of t_win, weights
TAIL_TIMES = np.array([0.1, 0.3, 1.0, 3.0, 10.0, 40.0, 190.0, 1000.0, 6500.0, 50000.0])
TAIL_WEIGHTS = np.array([
    0.23477481312586, 0.28549576238194, 0.28479416718255, 0.26149775537574,
    0.32056200511938, 0.35354490689146, 0.39635904496921, 0.42253908596514,
    0.48317384225265, 0.63661146557001])
N_MODES = 10
DEFAULT_WINDOW_STEPS = 100

META_HEAD = 0
META_COUNT = 1
META_PENDING = 2  # age (ticks) at the next step's start of the slip step an impact marked
META_JUMPS = 3   # meta[META_JUMPS + j]: age in ticks of kept slip step j (-1: free)
N_JUMPS = 4      # slip steps kept exactly inside the window, per grain
AGE_TICKS = 1 << 20  # ticks per step: a slip step's age, from its time within the step it happened in
IMPACTS = ("keep", "restart")


def basset_acceleration_prefactor(alpha, re_star):
    """P = 9α/√(π Re*): a_bs = -P · I in particle units (SPEC §2 derivation:
    (3/2) d² √(πρμ) over the virtual mass (ρp + Cm ρ) πd³/6 gives (9α/d)√(ν/π))."""
    return 9.0 * alpha / math.sqrt(math.pi * re_star)


# ---------------------------------------------------------------- window weights
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _window_weights(n_int, oldest_central, dt, gamma):
    """Weights γ_j on slip samples w_j = u_r(t - jΔt), j = 0 … n_int (+1 if
    ``oldest_central``), such that Σ γ_j w_j = ∫₀^{n_int Δt} g(t-s) s^(-1/2) ds
    with g linear between nodes and node values from finite differences.
    ``gamma`` must have length ≥ n_int + 2; it is overwritten."""
    for j in range(gamma.shape[0]):
        gamma[j] = 0.0
    if n_int <= 0:
        return
    rs = 1.0 / math.sqrt(dt)     # √Δt · (1/Δt): β is in units √Δt, g = (Δt g)/Δt
    if n_int == 1 and not oldest_central:
        # two samples: g constant = (w0 - w1)/Δt; ∫₀^Δt s^(-1/2) ds = 2√Δt
        gamma[0] = 2.0 * rs
        gamma[1] = -2.0 * rs
        return
    for n in range(n_int):
        # interval [n, n+1] (in units Δt), g linear: exact moments of s^(-1/2)
        sa = math.sqrt(n)
        ssum = sa + math.sqrt(n + 1.0)
        q = sa / ssum
        b_new = (2.0 / 3.0) * (2.0 - q) / ssum * rs      # weight of g_n
        b_old = (2.0 / 3.0) * (1.0 + q) / ssum * rs      # weight of g_{n+1}
        # node n: Δt g_n as a difference of samples
        if n == 0:
            gamma[0] += 1.5 * b_new
            gamma[1] -= 2.0 * b_new
            gamma[2] += 0.5 * b_new
        else:
            gamma[n - 1] += 0.5 * b_new
            gamma[n + 1] -= 0.5 * b_new
        m = n + 1
        if m < n_int or oldest_central:
            gamma[m - 1] += 0.5 * b_old
            gamma[m + 1] -= 0.5 * b_old
        else:
            # oldest node at t = 0: one-sided three-point (forward in time)
            gamma[m] -= 1.5 * b_old
            gamma[m - 1] += 2.0 * b_old
            gamma[m - 2] -= 0.5 * b_old


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _build_window_table(n_window, dt, table):
    # row k = number of stored samples since reset (k ≥ N_w + 2: full window)
    for k in range(n_window + 3):
        if k <= n_window + 1:
            _window_weights(k - 1, False, dt, table[k])
        else:
            _window_weights(n_window, True, dt, table[k])


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _phi1(x):
    # (1 - e^{-x}(1 + x))/x², with its series where the formula cancels
    if x < 1.0e-2:
        return 0.5 - x / 3.0 + x * x / 8.0 - x * x * x / 30.0 + x * x * x * x / 144.0
    return (1.0 - math.exp(-x) * (1.0 + x)) / (x * x)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _phi0(x):
    # (1 - e^{-x})/x
    if x < 1.0e-8:
        return 1.0 - 0.5 * x
    return -math.expm1(-x) / x


class HistoryCoefficients(NamedTuple):
    window_weights: np.ndarray   # (N_w+3, N_w+2): row = samples since reset
    tail_decay: np.ndarray       # (m,) exp(-Δt/(2tᵢ))
    tail_c_old: np.ndarray       # (m,) coefficient of Δt·g at the older node
    tail_c_new: np.ndarray       # (m,) coefficient of Δt·g at the newer node
    tail_weight: np.ndarray      # (m,) aᵢ
    dt: float
    n_window: int
    t_window: float
    tail_time: np.ndarray        # (m,) tᵢ (absolute, d/u*): folding a slip step into the tail
    keep_impacts: bool           # True: impacts keep the history (slip steps); False: restart


def make_history_coefficients(dt, n_window=DEFAULT_WINDOW_STEPS,
                              tail_times=TAIL_TIMES, tail_weights=TAIL_WEIGHTS, impacts="keep"):
    """Shared (all particles) coefficients for a fixed step ``dt`` and a window of
    ``n_window`` ≥ 2 steps (t_win = n_window·dt); ``impacts``: "keep" (the slip step
    enters the history) or "restart" (the memory restarts at every impact)."""
    if impacts not in IMPACTS:
        raise ValueError(f"impacts must be one of {IMPACTS}, got {impacts!r}")
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt!r}")
    n_window = int(n_window)
    if n_window < 2:
        raise ValueError(f"n_window must be >= 2, got {n_window}")
    tail_times = np.asarray(tail_times, dtype=np.float64)
    tail_weights = np.asarray(tail_weights, dtype=np.float64)
    table = np.zeros((n_window + 3, n_window + 2))
    _build_window_table(n_window, float(dt), table)
    t_win = n_window * dt
    ti = tail_times * t_win
    x = dt / (2.0 * ti)
    amp = np.sqrt(np.e / ti) * np.exp(-0.5 / tail_times)   # √(e/tᵢ) e^{-t_win/(2tᵢ)}
    phi0 = np.array([_phi0(v) for v in x])
    phi1 = np.array([_phi1(v) for v in x])
    # ∫_{t_win}^{t_win+Δt} √(e/tᵢ)e^{-s/(2tᵢ)} [g_new (1-σ/Δt) + g_old σ/Δt] ds,
    # σ = s - t_win; written for Δt·g, hence no Δt factor left
    c_new = amp * (phi0 - phi1)
    c_old = amp * phi1
    return HistoryCoefficients(table, np.exp(-x), c_old, c_new, tail_weights.copy(),
                               float(dt), n_window, t_win, ti, impacts == "keep")


class HistoryState(NamedTuple):
    slip_hist: np.ndarray   # float64 (N, N_w+2, 3)
    meta: np.ndarray        # int64 (N, 2)
    tail: np.ndarray        # float64 (N, m, 3)


def allocate_history_state(n_particles, n_window=DEFAULT_WINDOW_STEPS):
    """Zeroed history state for ``n_particles`` (a fresh history starts at the first step)."""
    meta = np.zeros((n_particles, META_JUMPS + N_JUMPS), dtype=np.int64)
    meta[:, META_JUMPS:] = -1
    return HistoryState(np.zeros((n_particles, n_window + 2, 3)), meta,
                        np.zeros((n_particles, N_MODES + N_JUMPS, 3)))


def history_state_bytes(n_window=DEFAULT_WINDOW_STEPS):
    """Bytes of history state per particle: 24 N_w + 24 m + 64 + 32 J (= 24 N_w + 432)."""
    return 8 * (3 * (n_window + 2) + META_JUMPS + 3 * N_MODES + 4 * N_JUMPS)


# ---------------------------------------------------------------- per-particle kernels
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_reset(slip0, slip_hist, meta, tail):
    """Start a new history whose first sample is ``slip0`` (bed impact, release).
    Arguments are one particle's slices: slip_hist[i], meta[i], tail[i]."""
    meta[META_HEAD] = 0
    meta[META_COUNT] = 1
    meta[META_PENDING] = 0
    for c in range(3):
        slip_hist[0, c] = slip0[c]
    for k in range(tail.shape[0]):
        for c in range(3):
            tail[k, c] = 0.0
    for j in range(N_JUMPS):
        meta[META_JUMPS + j] = -1


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_mark_impact_at(meta, age):
    """An impact or contact changed the grain's velocity impulsively, ``age`` (a fraction
    of the step, in [0, 1]) before the end of the step: the next step takes the slip step
    into the history with that age (kept in ticks, AGE_TICKS per step), or restarts it
    (``history_start_step``). Two in one step make one slip step, dated by the earlier."""
    ticks = int(round(age * AGE_TICKS))
    if meta[META_COUNT] > 0:
        meta[META_COUNT] = -meta[META_COUNT]
        meta[META_PENDING] = ticks
    elif meta[META_COUNT] < 0:
        meta[META_PENDING] = max(meta[META_PENDING], ticks)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_mark_impact(meta):
    """``history_mark_impact_at`` the end of the step (a contact resolved inside the
    step, a packed-bed impact: dated at the step's end)."""
    history_mark_impact_at(meta, 0.0)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _fold_jump(meta, tail, j, age, dt, tail_time, tail_weight):
    # slip step j, `age` steps old (a float), into the tail modes: Δ √(e/tᵢ) exp(-age Δt/(2tᵢ));
    # returns what it adds to I (Σ aᵢ × that)
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for k in range(N_MODES):
        amp = math.sqrt(math.e / tail_time[k]) * math.exp(-age * dt / (2.0 * tail_time[k]))
        d0 = amp * tail[N_MODES + j, 0]
        d1 = amp * tail[N_MODES + j, 1]
        d2 = amp * tail[N_MODES + j, 2]
        tail[k, 0] += d0
        tail[k, 1] += d1
        tail[k, 2] += d2
        s0 += tail_weight[k] * d0
        s1 += tail_weight[k] * d1
        s2 += tail_weight[k] * d2
    for c in range(3):
        tail[N_MODES + j, c] = 0.0
    meta[META_JUMPS + j] = -1
    return s0, s1, s2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_start_step(slip_now, slip_hist, meta, tail, i_hist, dt, keep, tail_time, tail_weight):
    """At the start of a step, before the history force is used: a fresh history at
    release (count 0) or, after an impact (count < 0), the slip step kept (``keep``) or
    the memory restarted. slip_now: the slip u_r now (after the impact)."""
    count = meta[META_COUNT]
    if count > 0:
        return
    if count == 0 or not keep:
        history_reset(slip_now, slip_hist, meta, tail)
        for c in range(3):
            i_hist[c] = 0.0
        return
    count = -count
    meta[META_COUNT] = count
    head = meta[META_HEAD]
    d0 = slip_now[0] - slip_hist[head, 0]
    d1 = slip_now[1] - slip_hist[head, 1]
    d2 = slip_now[2] - slip_hist[head, 2]
    # the stored samples continue the slip smoothly at its new level
    for j in range(slip_hist.shape[0]):
        slip_hist[j, 0] += d0
        slip_hist[j, 1] += d1
        slip_hist[j, 2] += d2
    free = -1
    oldest = -1
    for j in range(N_JUMPS):
        a = meta[META_JUMPS + j]
        if a < 0:
            if free < 0:
                free = j
        elif oldest < 0 or a > meta[META_JUMPS + oldest]:
            oldest = j
    if free < 0:  # all slots taken inside one window: the oldest goes to the tail early
        f0, f1, f2 = _fold_jump(meta, tail, oldest, meta[META_JUMPS + oldest] / AGE_TICKS, dt, tail_time,
                                tail_weight)
        i_hist[0] += f0
        i_hist[1] += f1
        i_hist[2] += f2
        free = oldest
    meta[META_JUMPS + free] = meta[META_PENDING]
    meta[META_PENDING] = 0
    tail[N_MODES + free, 0] = d0
    tail[N_MODES + free, 1] = d1
    tail[N_MODES + free, 2] = d2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def jump_impulse(meta, tail, dt):
    # ∫ over the coming step of Σ Δ/√(t - t_c): Σ Δ · 2(√((a+1)Δt) - √(aΔt))
    q0 = 0.0
    q1 = 0.0
    q2 = 0.0
    for j in range(N_JUMPS):
        if meta[META_JUMPS + j] >= 0:
            a = meta[META_JUMPS + j] / AGE_TICKS
            w = 2.0 * (math.sqrt((a + 1.0) * dt) - math.sqrt(a * dt))
            q0 += w * tail[N_MODES + j, 0]
            q1 += w * tail[N_MODES + j, 1]
            q2 += w * tail[N_MODES + j, 2]
    return q0, q1, q2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def age_jumps(meta, tail, dt, n_window, tail_time, tail_weight):
    # one step older; a window length old: into the tail. Returns what the folded steps
    # add to I at the new time
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for j in range(N_JUMPS):
        a = meta[META_JUMPS + j]
        if a >= 0:
            a += AGE_TICKS
            meta[META_JUMPS + j] = a
            if a >= n_window * AGE_TICKS:
                f0, f1, f2 = _fold_jump(meta, tail, j, a / AGE_TICKS, dt, tail_time, tail_weight)
                s0 += f0
                s1 += f1
                s2 += f2
    return s0, s1, s2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _integral3(slip_hist, meta, tail, window_weights, tail_weight):
    length = slip_hist.shape[0]
    count = meta[META_COUNT]
    head = meta[META_HEAD]
    row = min(count, window_weights.shape[0] - 1)
    nlag = min(count, length)
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for j in range(nlag):
        slot = head - j
        if slot < 0:
            slot += length
        wgt = window_weights[row, j]
        s0 += wgt * slip_hist[slot, 0]
        s1 += wgt * slip_hist[slot, 1]
        s2 += wgt * slip_hist[slot, 2]
    for k in range(N_MODES):
        a = tail_weight[k]
        s0 += a * tail[k, 0]
        s1 += a * tail[k, 1]
        s2 += a * tail[k, 2]
    return s0, s1, s2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_integral(slip_hist, meta, tail, window_weights, tail_weight, out):
    """I(t_n) = ∫₀^{t_n} (du_r/dτ)(t_n - τ)^(-1/2) dτ for one particle, where t_n
    is the time of its newest sample: window dot product + Σ aᵢ Fᵢ."""
    s0, s1, s2 = _integral3(slip_hist, meta, tail, window_weights, tail_weight)
    out[0] = s0
    out[1] = s1
    out[2] = s2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _advance(slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new):
    # open a new newest slot (returned): fold the interval leaving the window
    # into the tail modes first (O(m) work, no allocation)
    length = slip_hist.shape[0]          # N_w + 2
    n_window = length - 2
    count = meta[META_COUNT]
    head = meta[META_HEAD]
    if count >= n_window + 1:
        # interval between lags N_w (older, "A") and N_w - 1 (newer, "B") of the
        # current newest sample moves to lags t_win + Δt … t_win at the new time
        sA = head - n_window
        if sA < 0:
            sA += length
        sB = sA + 1
        if sB >= length:
            sB -= length
        sB1 = sB + 1                      # lag N_w - 2
        if sB1 >= length:
            sB1 -= length
        sA1 = sA - 1                      # lag N_w + 1 (valid only if count > N_w + 1)
        if sA1 < 0:
            sA1 += length
        oldest = count == n_window + 1    # A is the first sample (t = 0)
        for c in range(3):
            dg_new = 0.5 * (slip_hist[sB1, c] - slip_hist[sA, c])          # Δt g_B
            if oldest:
                dg_old = -1.5 * slip_hist[sA, c] + 2.0 * slip_hist[sB, c] \
                    - 0.5 * slip_hist[sB1, c]                             # Δt g_A
            else:
                dg_old = 0.5 * (slip_hist[sB, c] - slip_hist[sA1, c])
            for k in range(N_MODES):
                tail[k, c] = tail_decay[k] * tail[k, c] + tail_c_old[k] * dg_old \
                    + tail_c_new[k] * dg_new
    head += 1
    if head >= length:
        head = 0
    meta[META_HEAD] = head
    meta[META_COUNT] = min(count + 1, length)
    return head


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_push(slip_new, slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new):
    """Append the slip u_r(t_{n+1}) (one particle's slices).  Used when the
    history is recorded without the implicit step end (tests, diagnostics);
    inside RK4 use :func:`history_end_step`, which pushes too."""
    head = _advance(slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new)
    for c in range(3):
        slip_hist[head, c] = slip_new[c]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def add_basset_acceleration(prefactor, i_start, out):
    """out += a_bs = -P I_n: the history term held over the RK4 stages."""
    for c in range(3):
        out[c] -= prefactor * i_start[c]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def history_end_step(u, uf_new, i_start, prefactor, dt, slip_hist, meta, tail,
                     window_weights, tail_weight, tail_decay, tail_c_old, tail_c_new,
                     i_next, tail_time):
    """End of an RK4 step with the history held at ``i_start`` = I_n in the stages.

    u: the RK4 velocity u* at t_{n+1}, replaced in place by the velocity with the
    trapezoidal history term -PΔt(I_n + I_{n+1})/2, its newest sample implicit;
    uf_new: fluid velocity at the grain at t_{n+1}.  Pushes u_r(t_{n+1}) and
    writes I_{n+1} into ``i_next``, which may be ``i_start`` itself: the next
    step then needs no history_integral call (after a reset I = 0). Kept slip steps
    (module docstring) add their exact impulse over the step, then age."""
    head = _advance(slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new)
    q0, q1, q2 = jump_impulse(meta, tail, dt)
    u[0] -= prefactor * q0
    u[1] -= prefactor * q1
    u[2] -= prefactor * q2
    for c in range(3):
        slip_hist[head, c] = 0.0
    # I_{n+1} = I* + γ₀ u_r(t_{n+1}); I* = the integral with the newest sample zeroed
    i0, i1, i2 = _integral3(slip_hist, meta, tail, window_weights, tail_weight)
    row = min(meta[META_COUNT], window_weights.shape[0] - 1)
    g0 = window_weights[row, 0]
    h = 0.5 * prefactor * dt
    u0 = (u[0] - h * (i0 - g0 * uf_new[0] - i_start[0])) / (1.0 + h * g0)
    u1 = (u[1] - h * (i1 - g0 * uf_new[1] - i_start[1])) / (1.0 + h * g0)
    u2 = (u[2] - h * (i2 - g0 * uf_new[2] - i_start[2])) / (1.0 + h * g0)
    u[0] = u0
    u[1] = u1
    u[2] = u2
    w0 = u0 - uf_new[0]
    w1 = u1 - uf_new[1]
    w2 = u2 - uf_new[2]
    slip_hist[head, 0] = w0
    slip_hist[head, 1] = w1
    slip_hist[head, 2] = w2
    f0, f1, f2 = age_jumps(meta, tail, dt, slip_hist.shape[0] - 2, tail_time, tail_weight)
    i_next[0] = i0 + g0 * w0 + f0
    i_next[1] = i1 + g0 * w1 + f1
    i_next[2] = i2 + g0 * w2 + f2


# ---------------------------------------------------------------- reference (tests)
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _full_history(w, dt, gamma, out):
    n = w.shape[0] - 1
    _window_weights(n, False, dt, gamma)
    for c in range(w.shape[1]):
        s = 0.0
        for j in range(n + 1):
            s += gamma[j] * w[n - j, c]
        out[c] = s


def full_history_integral(slip_series, dt):
    """Reference: I at the last sample of ``slip_series`` (samples at t = 0, Δt, …,
    shape (n+1,) or (n+1, 3)) by the same second-order quadrature applied over
    the whole history (no tail).  O(n) per call and O(n) memory: tests only."""
    w = np.asarray(slip_series, dtype=np.float64)
    scalar = w.ndim == 1
    w2 = w.reshape(w.shape[0], -1)
    out = np.zeros(w2.shape[1])
    gamma = np.zeros(w2.shape[0] + 1)
    _full_history(np.ascontiguousarray(w2), float(dt), gamma, out)
    return out[0] if scalar else out
