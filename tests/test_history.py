"""Basset history integral: window + exponential tail (saltation/physics/history.py).

Orders are measured, not assumed: each convergence test fits the observed order
over successive halvings of Δt and checks it against the order the scheme is
designed for.
"""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import dawsn, fresnel, wofz

from saltation.physics import history as H


# ------------------------------------------------------------------ helpers
def run_windowed(n_window, dt, n_steps, slip_of_t):
    """I(t_k), k = 0 … n_steps, from the windowed scheme fed slip(t_k)."""
    co = H.make_history_coefficients(dt, n_window)
    s = H.allocate_history_state(1, n_window)
    sh, me, ta = s.slip_hist[0], s.meta[0], s.tail[0]
    w = np.zeros(3)
    out = np.zeros(3)
    w[:] = slip_of_t(0.0)
    H.history_reset(w, sh, me, ta)
    result = np.zeros(n_steps + 1)
    for k in range(1, n_steps + 1):
        w[:] = slip_of_t(k * dt)
        H.history_push(w, sh, me, ta, co.tail_decay, co.tail_c_old, co.tail_c_new)
        H.history_integral(sh, me, ta, co.window_weights, co.tail_weight, out)
        result[k] = out[0]
    return result


def observed_order(dts, errors):
    return np.polyfit(np.log(dts), np.log(np.abs(errors)), 1)[0]


def sin_case(omega=2.0, phase=0.7):
    """u_r = sin(ωτ + φ): I = ω ∫₀ᵗ cos(ω(t-s) + φ) s^-1/2 ds (Fresnel integrals)."""
    def slip(t):
        return np.sin(omega * t + phase)

    def deriv(t):
        return omega * np.cos(omega * t + phase)

    def exact(t):
        S, C = fresnel(np.sqrt(2 * omega * t / np.pi))
        f = np.sqrt(2 * np.pi / omega)
        return omega * f * (np.cos(omega * t + phase) * C + np.sin(omega * t + phase) * S)
    return slip, deriv, exact


def relax_case():
    """u_r = 1 - e^-τ: I = 2 D(√t), D the Dawson function."""
    return (lambda t: 1 - np.exp(-t), lambda t: np.exp(-t),
            lambda t: 2 * dawsn(np.sqrt(t)))


def tail_kernel(s, t_win):
    ti = H.TAIL_TIMES * t_win
    return np.sum(H.TAIL_WEIGHTS * np.sqrt(np.e / ti) * np.exp(-s / (2 * ti)))


def reference_with_tail_kernel(deriv, t, t_win):
    """What the windowed scheme converges to: exact kernel over the window,
    the exponential-sum kernel beyond it (scipy quad, s = x² on the window)."""
    win = quad(lambda x: 2 * deriv(t - x * x), 0, math.sqrt(min(t, t_win)),
               epsabs=1e-13, epsrel=1e-12, limit=200)[0]
    if t <= t_win:
        return win
    return win + quad(lambda s: deriv(t - s) * tail_kernel(s, t_win), t_win, t,
                      epsabs=1e-13, epsrel=1e-12, limit=400)[0]


# ------------------------------------------------------------------ the weights
def test_window_weights_are_the_published_beta():
    """γ = β·D: van Hinsberg's β (closed form) times the finite-difference map."""
    for n_int, central in ((7, False), (12, True)):
        dt = 0.3
        beta = np.zeros(n_int + 1)
        beta[0] = 4 / 3
        k = np.arange(1, n_int)
        beta[1:n_int] = 4 / 3 * ((k - 1) ** 1.5 - 2 * k ** 1.5 + (k + 1) ** 1.5)
        beta[n_int] = 4 / 3 * ((n_int - 1) ** 1.5 - n_int ** 1.5 + 1.5 * math.sqrt(n_int))
        D = np.zeros((n_int + 1, n_int + 2))
        D[0, :3] = [1.5, -2.0, 0.5]
        for m in range(1, n_int + (1 if central else 0)):
            D[m, m - 1], D[m, m + 1] = 0.5, -0.5
        if not central:
            D[n_int, n_int - 2:n_int + 1] = [-0.5, 2.0, -1.5]
        gamma = np.zeros(n_int + 2)
        H._window_weights(n_int, central, dt, gamma)
        np.testing.assert_allclose(gamma, beta @ D / math.sqrt(dt), rtol=1e-12, atol=1e-12)


def test_tail_kernel_fit_accuracy():
    """Published (t̃ᵢ, aᵢ): s^-1/2 fitted to the documented relative accuracy."""
    for x, tol in ((1.0, 1e-4), (3.0, 1.5e-3), (10.0, 2.5e-3), (100.0, 7e-3),
                   (1000.0, 0.04)):
        assert abs(tail_kernel(x, 1.0) * math.sqrt(x) - 1) < tol


def test_prefactor_matches_spec_forms():
    alpha, tau_star, rp = 1 / 3.15, 0.057, 73.0
    re_star = math.sqrt(tau_star) * rp
    p = H.basset_acceleration_prefactor(alpha, re_star)
    assert p == pytest.approx(9 * alpha / (math.sqrt(math.pi * rp) * tau_star ** 0.25))


def test_memory_per_particle():
    s = H.allocate_history_state(10, 100)
    per_particle = sum(a.nbytes for a in s) / 10
    assert per_particle == H.history_state_bytes(100) == 24 * 100 + 312 + 32 * H.N_JUMPS


# ------------------------------------------------------------------ exactness
def test_constant_acceleration_exact():
    """u_r = aτ: I = 2a√t. Full reference and window are exact (g constant);
    beyond the window the scheme integrates the exponential-sum kernel exactly."""
    a, dt, n_w = 3.0, 0.01, 16
    t = np.arange(201) * dt
    assert H.full_history_integral(a * t, dt) == pytest.approx(2 * a * math.sqrt(2.0), rel=1e-13)
    res = run_windowed(n_w, dt, 200, lambda s: a * s)
    t_win = n_w * dt
    inside = t[1:n_w + 1]
    np.testing.assert_allclose(res[1:n_w + 1], 2 * a * np.sqrt(inside), rtol=1e-12)
    ti = H.TAIL_TIMES * t_win
    for k in (n_w + 1, 50, 200):
        tail = a * np.sum(H.TAIL_WEIGHTS * np.sqrt(np.e / ti) * 2 * ti
                          * (np.exp(-t_win / (2 * ti)) - np.exp(-t[k] / (2 * ti))))
        assert res[k] == pytest.approx(2 * a * math.sqrt(t_win) + tail, rel=1e-11)


def test_linear_acceleration_exact():
    """u_r = bτ²/2 (du_r/dτ = bτ): I = (4/3) b t^{3/2}, exact for both."""
    b, dt, n_w = 2.0, 0.02, 20
    t = np.arange(101) * dt
    slip = b * t ** 2 / 2
    for k in (2, 3, 10, 100):
        assert H.full_history_integral(slip[:k + 1], dt) == pytest.approx(
            4 / 3 * b * t[k] ** 1.5, rel=1e-12)
    res = run_windowed(n_w, dt, n_w, lambda s: b * s * s / 2)
    np.testing.assert_allclose(res[2:], 4 / 3 * b * t[2:n_w + 1] ** 1.5, rtol=1e-12)


def test_vector_input_and_zero_history():
    t = np.arange(11) * 0.1
    series = np.stack([t, 2 * t, -t], axis=1)
    out = H.full_history_integral(series, 0.1)
    np.testing.assert_allclose(out, 2 * math.sqrt(1.0) * np.array([1, 2, -1]), rtol=1e-13)
    assert H.full_history_integral(np.ones(5), 0.1) == pytest.approx(0.0, abs=1e-14)


# ------------------------------------------------------------------ convergence
@pytest.mark.parametrize("case", [sin_case, relax_case])
def test_full_reference_is_second_order(case):
    slip, _, exact = case()
    T = 2.0
    ns = np.array([50, 100, 200, 400, 800])
    errs = np.array([H.full_history_integral(slip(np.arange(n + 1) * T / n), T / n) - exact(T)
                     for n in ns])
    p = observed_order(T / ns, errs)
    assert 1.9 < p < 2.15, (p, errs)
    assert abs(errs[-1]) < 2e-5


@pytest.mark.parametrize("case", [sin_case, relax_case])
def test_windowed_scheme_is_second_order(case):
    """Window + tail against the same integral with the tail kernel it uses
    (so the kernel-fit error, independent of Δt, is not mixed in); t_win fixed,
    N_w doubles as Δt halves; checked at several times up to 20 windows."""
    slip, deriv, _ = case()
    t_win, T = 0.25, 5.0
    t_check = np.array([0.125, 1.0, 2.5, 5.0])
    ref = np.array([reference_with_tail_kernel(deriv, t, t_win) for t in t_check])
    n_ws = np.array([8, 16, 32, 64])
    errs = []
    for n_w in n_ws:
        dt = t_win / n_w
        res = run_windowed(n_w, dt, int(round(T / dt)), slip)
        errs.append(np.max(np.abs(res[np.rint(t_check / dt).astype(int)] - ref)))
    p = observed_order(t_win / n_ws, np.array(errs))
    assert 1.85 < p < 2.15, (p, errs)


@pytest.mark.parametrize("case", [sin_case, relax_case])
def test_windowed_matches_full_reference_over_20_windows(case):
    """Window + tail vs the full-history quadrature at every step over 20 window
    lengths: they differ by the tail-kernel fit only, ≤ 0.3 % of max |I|."""
    slip, _, exact = case()
    n_w, t_win = 16, 0.25
    dt = t_win / n_w
    n = 20 * n_w
    t = np.arange(n + 1) * dt
    res = run_windowed(n_w, dt, n, slip)
    series = slip(t)
    full = np.array([H.full_history_integral(series[:k + 1], dt) for k in range(1, n + 1)])
    scale = np.abs(full).max()
    diff = np.abs(res[1:] - full)
    assert diff[:n_w].max() < 1e-13 * scale         # identical inside the first window
    assert diff.max() < 3e-3 * scale
    # and both are close to the exact integral
    assert np.abs(full - exact(t[1:])).max() < 3e-3 * scale


def test_reset_forgets_history():
    n_w, dt = 8, 0.05
    co = H.make_history_coefficients(dt, n_w)
    s = H.allocate_history_state(2, n_w)
    w = np.zeros(3)
    out = np.zeros(3)
    # particle 0: long history, then reset; particle 1: fresh
    for i in (0, 1):
        H.history_reset(w, s.slip_hist[i], s.meta[i], s.tail[i])
    for k in range(1, 40):
        w[:] = [math.sin(k * dt), k * dt, 0.0]
        H.history_push(w, s.slip_hist[0], s.meta[0], s.tail[0], co.tail_decay,
                       co.tail_c_old, co.tail_c_new)
    w[:] = [1.0, -2.0, 0.5]
    for i in (0, 1):
        H.history_reset(w, s.slip_hist[i], s.meta[i], s.tail[i])
    res = []
    for k in range(1, 30):
        w[:] = [1.0 + 0.3 * k * dt, -2.0, 0.5 - (k * dt) ** 2]
        for i in (0, 1):
            H.history_push(w, s.slip_hist[i], s.meta[i], s.tail[i], co.tail_decay,
                           co.tail_c_old, co.tail_c_new)
        r = []
        for i in (0, 1):
            H.history_integral(s.slip_hist[i], s.meta[i], s.tail[i], co.window_weights,
                               co.tail_weight, out)
            r.append(out.copy())
        res.append(r)
    for r0, r1 in res:
        np.testing.assert_array_equal(r0, r1)


# ------------------------------------------------------------------ coupled to RK4
def _basset_roots(b, c):
    return np.roots([1.0, c * math.sqrt(math.pi), b]).astype(complex)


def _erfc_term(r, t):
    # e^{r²t} erfc(-r√t) = w(-i r √t), Faddeeva w
    return wofz(-1j * r * np.sqrt(t))


def exact_step_response(A, b, c, t):
    """du/dt = A - b u - c ∫₀ᵗ u'(τ)(t-τ)^-1/2 dτ, u(0) = 0 (Laplace transform:
    U = A / (s (s + c√π √s + b)), factorised in √s with roots r1, r2)."""
    r1, r2 = _basset_roots(b, c)
    v = A / (r1 - r2) * ((_erfc_term(r1, t) - 1) / r1 - (_erfc_term(r2, t) - 1) / r2)
    return v.real


def exact_ramp_response(A, b, c, t):
    """Same with forcing A·t (smooth start: u'(0) = 0)."""
    r1, r2 = _basset_roots(b, c)

    def f2(r):
        return (((_erfc_term(r, t) - 1) / r - 2 * np.sqrt(t / np.pi)) / r - t) / r
    return (A / (r1 - r2) * (f2(r1) - f2(r2))).real


def rk4_with_history(A, b, c, T, n, n_window, ramp, fluid=None, full=False):
    """Classic RK4 with the Basset term as physics/history.py documents it: I_n held
    over the stages, then the implicit trapezoidal step end.  The model is
    du/dt = A(t) - b (u - U) - c I[u - U], U a uniform steady fluid velocity
    (zero by default), starting at zero slip: u(0) = U."""
    dt = T / n
    co = H.make_history_coefficients(dt, n_window)
    s = H.allocate_history_state(1, n_window)
    sh, me, ta = s.slip_hist[0], s.meta[0], s.tail[0]
    still = np.zeros(3) if fluid is None else np.asarray(fluid, float)
    u = still.copy()
    H.history_reset(u - still, sh, me, ta)
    i_start, acc = np.zeros(3), np.zeros(3)

    def rhs(v, t):
        acc[:] = (A * t if ramp else A) - b * (v - still)
        H.add_basset_acceleration(c, i_start, acc)
        return acc.copy()

    i_carry = np.zeros(3)
    for k in range(n):
        t = k * dt
        H.history_integral(sh, me, ta, co.window_weights, co.tail_weight, i_start)
        if k > 0:   # the carried I_{n+1} of the previous step end is the same number
            np.testing.assert_allclose(i_carry, i_start, rtol=1e-10, atol=1e-12)
        k1 = rhs(u, t)
        k2 = rhs(u + 0.5 * dt * k1, t + 0.5 * dt)
        k3 = rhs(u + 0.5 * dt * k2, t + 0.5 * dt)
        k4 = rhs(u + dt * k3, t + dt)
        u = u + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        H.history_end_step(u, still, i_start, c, dt, sh, me, ta, co.window_weights,
                           co.tail_weight, co.tail_decay, co.tail_c_old, co.tail_c_new,
                           i_carry, co.tail_time)
    return u if full else u[0]


def test_rk4_coupling_uses_the_slip():
    """Galilean check: in a uniform fluid velocity U the grain's slip evolves as
    in still fluid (the step end must store u - u_f, not u)."""
    U = np.array([3.0, -0.5, 1.25])
    moving = rk4_with_history(1.0, 1.0, 0.5, 2.0, 100, 30, False, fluid=U, full=True)
    still = rk4_with_history(1.0, 1.0, 0.5, 2.0, 100, 30, False, full=True)
    np.testing.assert_allclose(moving - U, still, atol=1e-12)


def test_exact_basset_solutions_are_consistent():
    # algebraic approach to the terminal velocity: u ≈ A/b - A c/(b² √t) (small-s
    # limit of the transform), and the Basset term slows the approach
    A, b, c = 1.0, 1.0, 0.5
    t = 400.0
    assert exact_step_response(A, b, c, t) == pytest.approx(
        A / b - A * c / (b * b * math.sqrt(t)), abs=1e-4)
    assert exact_step_response(A, b, c, 2.0) < (A / b) * (1 - math.exp(-2.0))
    # reference by the full quadrature with a fine step
    assert rk4_with_history(A, b, c, 2.0, 800, 802, False) == pytest.approx(
        exact_step_response(A, b, c, 2.0), abs=2e-5)


@pytest.mark.parametrize("ramp, order_lo, order_hi", [(False, 1.4, 1.6), (True, 1.8, 2.2)])
def test_rk4_coupling_order(ramp, order_lo, order_hi):
    """Combined RK4 + history: order 3/2 when the history starts with a finite
    acceleration (I ≈ 2g(0)√t: the case after every reset), order 2 for a
    smooth start.  Window covers the whole run (no kernel-fit error)."""
    A, b, c, T = 1.0, 1.0, 0.5, 2.0
    exact = exact_ramp_response(A, b, c, T) if ramp else exact_step_response(A, b, c, T)
    ns = np.array([100, 200, 400, 800])
    errs = np.array([rk4_with_history(A, b, c, T, n, n + 2, ramp) - exact for n in ns])
    p = observed_order(T / ns, errs)
    assert order_lo < p < order_hi, (p, errs)


def test_rk4_coupling_is_stable_for_large_history_prefactor():
    """The implicit newest-node weight keeps the coupling stable where an
    explicit (lagged) history term diverges: P = 1, Δt up to 0.8 τ_drag."""
    A, b, c, T = 1.0, 1.0, 1.0, 40.0
    exact = exact_step_response(A, b, c, T)
    for dt in (0.05, 0.2, 0.8):
        n = int(round(T / dt))
        assert rk4_with_history(A, b, c, T, n, 50, False) == pytest.approx(exact, abs=0.01)


def test_rk4_with_tail_close_to_exact():
    """With a short window (t_win = T/20) the kernel fit adds ~1e-4 u*: stated
    tolerance 5e-4 of the velocity."""
    A, b, c, T = 1.0, 1.0, 0.5, 2.0
    exact = exact_step_response(A, b, c, T)
    for n in (200, 400):
        assert rk4_with_history(A, b, c, T, n, n // 20, False) == pytest.approx(exact, abs=5e-4)


# ---------------------------------------------------------------- slip steps kept through impacts
P_PROBE = 1e-7


def _drive_prescribed_slip(slip_of_t, steps, dt, n_steps, n_window=10, impacts="keep", phi=0.0):
    """Production history kernels fed a prescribed slip u_r(t) (a vanishing prefactor: the
    grain's velocity is the slip itself, uf = 0), with impulsive steps at the starts of the
    given step indices (marked as impacts). Returns per step: t_{n+1}, the history impulse
    ∫ I dt over the step that the force applies (held I_n in the stages, the trapezoidal
    end-of-step closure, the exact slip-step part), and the full I(t_{n+1}) (carried I +
    the kept steps' Δ/√lag). ``phi``: the steps happened that fraction of a step before the
    step's start they are marked at (history_mark_impact_at)."""
    co = H.make_history_coefficients(dt, n_window, impacts=impacts)
    s = H.allocate_history_state(1, n_window)
    sh, me, ta = s.slip_hist[0], s.meta[0], s.tail[0]
    i_hist = np.zeros(3)
    out = []
    still = np.zeros(3)
    for n in range(n_steps):
        t = n * dt
        if n in steps:
            if phi == 0.0:
                H.history_mark_impact(me)
            else:
                H.history_mark_impact_at(me, phi)
        # the impact comes after a step's end: the slip at a step's start is post-impact,
        # the sample that closes the step before it pre-impact
        H.history_start_step(slip_of_t(t, True).copy(), sh, me, ta, i_hist, dt, co.keep_impacts, co.tail_time,
                             co.tail_weight)
        i_start = i_hist.copy()
        u_star = slip_of_t(t + dt, False).copy()
        u = u_star.copy()
        # a vanishing prefactor P: the end-of-step velocity change is -P × (its part of the
        # impulse); the stages held -P I_n over Δt
        H.history_end_step(u, still, i_hist, P_PROBE, dt, sh, me, ta, co.window_weights, co.tail_weight,
                           co.tail_decay, co.tail_c_old, co.tail_c_new, i_hist, co.tail_time)
        impulse = dt * i_start + (u_star - u) / P_PROBE
        full = i_hist.copy()
        for j in range(H.N_JUMPS):
            if me[H.META_JUMPS + j] > 0:
                a = me[H.META_JUMPS + j] / H.AGE_TICKS
                full += ta[H.N_MODES + j] / np.sqrt(a * dt)
        out.append((t + dt, impulse, full))
    return out


def test_a_step_in_slip_enters_the_history_as_delta_over_sqrt_lag():
    """u_r = a t plus a step Δ at t_c: I = 2a√t + Δ/√(t − t_c) exactly; the history
    impulse ∫ I dt = (4/3) a t^{3/2} + 2Δ√(t − t_c). The step alone is exact while it is
    in the window (10 steps), then carries the exponential tail's kernel error (the tail
    is in units of the window, so that error does not fall with Δt)."""
    delta = np.array([-1.2, 0.8, 0.3])
    for dt in (0.02, 0.01):
        n_c = int(round(0.5 / dt))
        t_c = n_c * dt

        def step_only(t, post, t_c=t_c):
            return delta if t > t_c - (1e-12 if post else -1e-12) else 0.0 * delta

        rows = _drive_prescribed_slip(step_only, {n_c}, dt, int(round(3.0 / dt)))
        ts = np.array([r[0] for r in rows])
        cum = np.cumsum([r[1] for r in rows], axis=0)
        exact = 2.0 * np.outer(np.sqrt(np.clip(ts - t_c, 0, None)), delta)
        in_window = ts <= t_c + 10 * dt + 1e-12
        np.testing.assert_allclose(cum[in_window], exact[in_window], atol=1e-6 * np.abs(delta).max(), rtol=0)  # probe round-off
        assert np.max(np.abs(cum - exact)) < 1e-3 * np.abs(exact).max()
        for t_check in (t_c + 3 * dt, t_c + 2.0):  # I itself, in the window and long after
            k = int(round(t_check / dt)) - 1
            np.testing.assert_allclose(rows[k][2], delta / np.sqrt(ts[k] - t_c), rtol=3e-3)
    # with a smooth part too: both parts together (the smooth part second order after its
    # finite-acceleration start, physics/history.py)
    a = np.array([0.3, -0.1, 0.05])
    dt, n_c = 0.01, 50
    t_c = n_c * dt
    rows = _drive_prescribed_slip(
        lambda t, post: a * t + (delta if t > t_c - (1e-12 if post else -1e-12) else 0.0), {n_c}, dt, 300)
    ts = np.array([r[0] for r in rows])
    cum = np.cumsum([r[1] for r in rows], axis=0)
    exact = (4.0 / 3.0) * np.outer(ts**1.5, a) + 2.0 * np.outer(np.sqrt(np.clip(ts - t_c, 0, None)), delta)
    assert np.max(np.abs(cum - exact)) < 2e-3


def test_a_step_inside_a_time_step_is_dated_where_it_happened():
    """A slip step at t_c = t_n − φΔt (an impact at a fraction 1 − φ of the step before
    t_n, marked with its age φ): the kernels give the impulse from t_n on,
    2Δ(√(t − t_c) − √(φΔt)); the part before t_n, 2Δ√(φΔt), is the caller's
    (flight/spheres.flight_remainder). Dated at t_n instead (the old rule) the impulse
    would be 2Δ√(t − t_n): off by ~2Δ√(φΔt) right after the impact."""
    delta = np.array([-1.2, 0.8, 0.3])
    dt, n_c, phi = 0.02, 25, 0.37
    t_n = n_c * dt
    t_c = t_n - phi * dt

    def step_only(t, post):
        return delta if t > t_n - (1e-12 if post else -1e-12) else 0.0 * delta

    rows = _drive_prescribed_slip(step_only, {n_c}, dt, 80, phi=phi)
    ts = np.array([r[0] for r in rows])
    cum = np.cumsum([r[1] for r in rows], axis=0)
    after = ts > t_n + 1e-12
    exact = 2.0 * np.outer(np.sqrt(np.clip(ts - t_c, 0, None)) - np.sqrt(phi * dt), delta)
    in_window = after & (ts <= t_c + 10 * dt)
    np.testing.assert_allclose(cum[in_window], exact[in_window], atol=1e-6 * np.abs(delta).max(), rtol=0)
    # I itself carries Δ/√(t − t_c), with the step's own age
    k = int(round((t_n + 3 * dt) / dt)) - 1
    np.testing.assert_allclose(rows[k][2], delta / np.sqrt(ts[k] - t_c), rtol=1e-6)  # the age to 2⁻²⁰ step
    # the old dating is far off in the first steps
    node = _drive_prescribed_slip(step_only, {n_c}, dt, 80)
    cum_node = np.cumsum([r[1] for r in node], axis=0)
    first = int(np.argmax(after))
    assert np.abs(cum_node[first] - exact[first]).max() > 0.1 * np.abs(exact[first]).max()


def test_restart_option_drops_the_step_and_the_memory():
    a, delta = np.array([0.3, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    dt, n_c = 0.01, 50

    def slip(t, post):
        return a * t + (delta if t > n_c * dt - (1e-12 if post else -1e-12) else 0.0)

    keep = _drive_prescribed_slip(slip, {n_c}, dt, 120, impacts="keep")
    restart = _drive_prescribed_slip(slip, {n_c}, dt, 120, impacts="restart")
    k = 80  # t = 0.81, 30 steps after the impact
    t = keep[k][0]
    assert restart[k][2][0] == pytest.approx(2 * a[0] * np.sqrt(t - n_c * dt), rel=0.02)  # memory restarted
    assert keep[k][2][0] == pytest.approx(2 * a[0] * np.sqrt(t) + delta[0] / np.sqrt(t - n_c * dt), rel=0.02)
    with pytest.raises(ValueError, match="impacts must be one of"):
        H.make_history_coefficients(dt, 10, impacts="forget")


def test_a_bounce_sequence_against_an_independent_full_history_quadrature():
    """Smooth slip (a sine) with four impacts, two of them inside one window: the
    production state (window + tail + kept steps, bounded memory) against the plain
    full-history quadrature of the smooth part plus the exact Σ Δ_k/√(t − t_k)."""
    dt, n_window = 0.01, 10
    hits = {30: np.array([-0.9, 0.6, 0.1]), 34: np.array([0.5, -0.4, 0.0]), 140: np.array([-0.7, 0.5, 0.2]),
            290: np.array([1.1, -0.3, -0.2])}

    def smooth(t):
        return np.array([0.5 * np.sin(2.0 * t), 0.2 * np.cos(3.0 * t), 0.1 * t])

    def slip(t, post):
        s = smooth(t)
        for n, d in hits.items():
            if t > n * dt - (1e-12 if post else -1e-12):
                s = s + d
        return s

    rows = _drive_prescribed_slip(slip, set(hits), dt, 400, n_window=n_window)
    series = np.array([smooth(k * dt) for k in range(401)])
    for k in (36, 60, 150, 200, 295, 399):
        t = rows[k][0]
        ref = H.full_history_integral(series[: k + 2], dt)
        for n, d in hits.items():
            if t > n * dt + 1e-12:
                ref = ref + d / np.sqrt(t - n * dt)
        np.testing.assert_allclose(rows[k][2], ref, atol=5e-3, rtol=0)
