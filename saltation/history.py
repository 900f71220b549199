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
meta             int64   [N, 2]         META_HEAD: slot of the newest sample,
                                        META_COUNT: samples since reset
                                        (capped at N_w + 2)
tail             float64 [N, m, 3]      tail modes Fᵢ
===============  ====================  =========================================

Memory per particle: 24 N_w + 304 bytes (N_w = 100: 2 704 B), independent of
the run length.  Shared coefficients (``make_history_coefficients``): a weight
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

Reset at bed impact
-------------------
The caller resets a particle's history (``history_reset`` with the
post-rebound slip as the first sample) at every bed impact and at its release.
A rebound changes the velocity by a finite jump in zero time: as an
"acceleration" it is a Dirac pulse, and the Boussinesq-Basset kernel would turn
it into a force ∝ Δu/√(t - t_impact) that persists through the next jump.
That kernel describes the unsteady Stokes boundary layer of a sphere under
smooth acceleration; it says nothing valid about the wake re-formed by a
collision.  Restarting the memory at the impact keeps only the smooth
in-flight accelerations.  Consequence: the history force is zero at take-off
and builds up as √t over the jump; memory of earlier jumps is discarded, and a
history accumulated before the impact cannot push the grain back after it.
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


def basset_acceleration_prefactor(alpha, re_star):
    """P = 9α/√(π Re*): a_bs = -P · I in particle units (SPEC §2 derivation:
    (3/2) d² √(πρμ) over the virtual mass (ρp + Cm ρ) πd³/6 gives (9α/d)√(ν/π))."""
    return 9.0 * alpha / math.sqrt(math.pi * re_star)


# ---------------------------------------------------------------- window weights
@njit(cache=True, _nrt=False)
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


@njit(cache=True, _nrt=False)
def _build_window_table(n_window, dt, table):
    # row k = number of stored samples since reset (k ≥ N_w + 2: full window)
    for k in range(n_window + 3):
        if k <= n_window + 1:
            _window_weights(k - 1, False, dt, table[k])
        else:
            _window_weights(n_window, True, dt, table[k])


@njit(cache=True, _nrt=False)
def _phi1(x):
    # (1 - e^{-x}(1 + x))/x², with its series where the formula cancels
    if x < 1.0e-2:
        return 0.5 - x / 3.0 + x * x / 8.0 - x * x * x / 30.0 + x * x * x * x / 144.0
    return (1.0 - math.exp(-x) * (1.0 + x)) / (x * x)


@njit(cache=True, _nrt=False)
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


def make_history_coefficients(dt, n_window=DEFAULT_WINDOW_STEPS,
                              tail_times=TAIL_TIMES, tail_weights=TAIL_WEIGHTS):
    """Shared (all particles) coefficients for a fixed step ``dt`` and a window of
    ``n_window`` ≥ 2 steps (t_win = n_window·dt)."""
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
                               float(dt), n_window, t_win)


class HistoryState(NamedTuple):
    slip_hist: np.ndarray   # float64 (N, N_w+2, 3)
    meta: np.ndarray        # int64 (N, 2)
    tail: np.ndarray        # float64 (N, m, 3)


def allocate_history_state(n_particles, n_window=DEFAULT_WINDOW_STEPS, n_modes=N_MODES):
    """Zeroed history state for ``n_particles`` (call history_reset per particle)."""
    return HistoryState(np.zeros((n_particles, n_window + 2, 3)),
                        np.zeros((n_particles, 2), dtype=np.int64),
                        np.zeros((n_particles, n_modes, 3)))


def history_state_bytes(n_window=DEFAULT_WINDOW_STEPS, n_modes=N_MODES):
    """Bytes of history state per particle: 24 N_w + 24 m + 64 (= 24 N_w + 304)."""
    return 8 * (3 * (n_window + 2) + 2 + 3 * n_modes)


# ---------------------------------------------------------------- per-particle kernels
@njit(cache=True, _nrt=False)
def history_reset(slip0, slip_hist, meta, tail):
    """Start a new history whose first sample is ``slip0`` (bed impact, release).
    Arguments are one particle's slices: slip_hist[i], meta[i], tail[i]."""
    meta[META_HEAD] = 0
    meta[META_COUNT] = 1
    for c in range(3):
        slip_hist[0, c] = slip0[c]
    for k in range(tail.shape[0]):
        for c in range(3):
            tail[k, c] = 0.0


@njit(cache=True, _nrt=False)
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
    for k in range(tail.shape[0]):
        a = tail_weight[k]
        s0 += a * tail[k, 0]
        s1 += a * tail[k, 1]
        s2 += a * tail[k, 2]
    return s0, s1, s2


@njit(cache=True, _nrt=False)
def history_integral(slip_hist, meta, tail, window_weights, tail_weight, out):
    """I(t_n) = ∫₀^{t_n} (du_r/dτ)(t_n - τ)^(-1/2) dτ for one particle, where t_n
    is the time of its newest sample: window dot product + Σ aᵢ Fᵢ."""
    s0, s1, s2 = _integral3(slip_hist, meta, tail, window_weights, tail_weight)
    out[0] = s0
    out[1] = s1
    out[2] = s2


@njit(cache=True, _nrt=False)
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
            for k in range(tail.shape[0]):
                tail[k, c] = tail_decay[k] * tail[k, c] + tail_c_old[k] * dg_old \
                    + tail_c_new[k] * dg_new
    head += 1
    if head >= length:
        head = 0
    meta[META_HEAD] = head
    meta[META_COUNT] = min(count + 1, length)
    return head


@njit(cache=True, _nrt=False)
def history_push(slip_new, slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new):
    """Append the slip u_r(t_{n+1}) (one particle's slices).  Used when the
    history is recorded without the implicit step end (tests, diagnostics);
    inside RK4 use :func:`history_end_step`, which pushes too."""
    head = _advance(slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new)
    for c in range(3):
        slip_hist[head, c] = slip_new[c]


@njit(cache=True, _nrt=False)
def add_basset_acceleration(prefactor, i_start, out):
    """out += a_bs = -P I_n: the history term held over the RK4 stages."""
    for c in range(3):
        out[c] -= prefactor * i_start[c]


@njit(cache=True, _nrt=False)
def history_end_step(u, uf_new, i_start, prefactor, dt, slip_hist, meta, tail,
                     window_weights, tail_weight, tail_decay, tail_c_old, tail_c_new,
                     i_next):
    """End of an RK4 step with the history held at ``i_start`` = I_n in the stages.

    u: the RK4 velocity u* at t_{n+1}, replaced in place by the velocity with the
    trapezoidal history term -PΔt(I_n + I_{n+1})/2, its newest sample implicit;
    uf_new: fluid velocity at the grain at t_{n+1}.  Pushes u_r(t_{n+1}) and
    writes I_{n+1} into ``i_next``, which may be ``i_start`` itself: the next
    step then needs no history_integral call (after a reset I = 0)."""
    head = _advance(slip_hist, meta, tail, tail_decay, tail_c_old, tail_c_new)
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
    i_next[0] = i0 + g0 * w0
    i_next[1] = i1 + g0 * w1
    i_next[2] = i2 + g0 * w2


# ---------------------------------------------------------------- reference (tests)
@njit(cache=True, _nrt=False)
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
