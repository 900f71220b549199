"""Free-flight force terms (saltation/physics/forces.py, SPEC §2)."""

import math

import numpy as np
import pytest

from saltation.physics import forces as F

RE_STAR = 17.4       # d = 0.69 mm, Rp = 73, tau* ~ 0.057
TAU_STAR = 0.057


def coefficients(**kw):
    base = dict(tau_star=TAU_STAR, re_star=RE_STAR)
    base.update(kw)
    return F.make_coefficients(**base)


def evaluate(up, uf, coef, grad=None, dudt=None, vort=None, spin=None, top=None, bot=None):
    up = np.asarray(up, float)
    uf = np.asarray(uf, float)
    grad = np.zeros((3, 3)) if grad is None else np.asarray(grad, float)
    dudt = np.zeros(3) if dudt is None else np.asarray(dudt, float)
    vort = np.zeros(3) if vort is None else np.asarray(vort, float)
    spin = np.zeros(3) if spin is None else np.asarray(spin, float)
    top = uf.copy() if top is None else np.asarray(top, float)
    bot = uf.copy() if bot is None else np.asarray(bot, float)
    out = np.zeros(3)
    terms = np.zeros((F.N_TERMS, 3))
    F.fluid_acceleration(up, uf, grad, dudt, vort, spin, top, bot, coef, out)
    F.fluid_acceleration_terms(up, uf, grad, dudt, vort, spin, top, bot, coef, terms)
    return out, terms


# ------------------------------------------------------------------ drag law
def test_yen_stokes_limit():
    for re in (1e-6, 1e-5, 1e-4):
        assert F.yen_drag_coefficient(re) * re / 24.0 == pytest.approx(1.0, abs=2e-3)


def test_yen_guard_at_zero_is_finite():
    cd0 = F.yen_drag_coefficient(0.0)
    assert math.isfinite(cd0) and cd0 > 0
    assert F.drag_factor(0.0, RE_STAR) == pytest.approx(24.0 / RE_STAR)


def test_yen_continuous_and_decreasing():
    re = np.geomspace(1e-3, 1e5, 4001)           # ratio 1.0046 between neighbours
    cd = np.array([F.yen_drag_coefficient(r) for r in re])
    assert np.all(np.diff(cd) < 0)
    assert np.max(np.abs(np.diff(np.log(cd)))) < 0.006


def test_yen_close_to_standard_drag_curve():
    # Schiller-Naumann (valid Re < ~800) as an independent standard curve
    for re in np.geomspace(1e-3, 200, 30):
        sn = 24.0 / re * (1 + 0.15 * re ** 0.687)
        assert F.yen_drag_coefficient(re) == pytest.approx(sn, rel=0.10)


def test_drag_factor_equals_cd_times_slip():
    for ur in (1e-4, 0.3, 2.0, 15.0):
        assert F.drag_factor(ur, RE_STAR) == pytest.approx(
            F.yen_drag_coefficient(ur * RE_STAR) * ur, rel=1e-12)


# ------------------------------------------------------------------ terms
def test_drag_opposes_slip():
    coef = coefficients(weight=False, lift=False, magnus=False, added_mass=False,
                        fluid_acceleration=False)
    rng = np.random.default_rng(1)
    for _ in range(20):
        up = rng.normal(size=3) * 3
        uf = rng.normal(size=3) * 3
        a, _ = evaluate(up, uf, coef)
        ur = up - uf
        assert np.dot(a, ur) < 0
        assert np.linalg.norm(np.cross(a, ur)) < 1e-12 * np.linalg.norm(a) * np.linalg.norm(ur)
        mag = 0.75 * coef[F.ALPHA] * F.yen_drag_coefficient(np.linalg.norm(ur) * RE_STAR) \
            * np.dot(ur, ur)
        assert np.linalg.norm(a) == pytest.approx(mag, rel=1e-12)


def test_magnus_topspin_pushes_down():
    coef = coefficients(weight=False, drag=False, lift=False, added_mass=False,
                        fluid_acceleration=False)
    a, _ = evaluate([2.0, 0, 0], [0, 0, 0], coef, spin=[0, 0, -3.0])
    assert a[1] < 0
    assert a[0] == 0 and a[2] == 0
    assert a[1] == pytest.approx(0.75 * coef[F.ALPHA] * 1.0 * (-3.0) * 2.0)
    # backspin lifts
    a, _ = evaluate([2.0, 0, 0], [0, 0, 0], coef, spin=[0, 0, 3.0])
    assert a[1] > 0


def test_magnus_uses_relative_spin():
    # a grain spinning at exactly half the fluid vorticity feels no Magnus force
    coef = coefficients(weight=False, drag=False, lift=False, added_mass=False,
                        fluid_acceleration=False)
    a, _ = evaluate([2.0, 0.5, 0], [1.0, 0, 0], coef, spin=[0, 0, -2.0], vort=[0, 0, -4.0])
    assert np.all(a == 0)


def test_lift_up_when_fluid_faster_on_top():
    coef = coefficients(weight=False, drag=False, magnus=False, added_mass=False,
                        fluid_acceleration=False)
    a, _ = evaluate([1.0, 0, 0], [3.0, 0, 0], coef, top=[4.0, 0, 0], bot=[0.0, 0, 0])
    expect = 0.75 * coef[F.ALPHA] * 0.2 * ((1 - 4.0) ** 2 - 1.0 ** 2)
    assert a[1] == pytest.approx(expect)
    assert a[1] > 0 and a[0] == 0 and a[2] == 0


def test_zero_slip_in_uniform_flow_feels_only_weight():
    coef = coefficients()
    a, terms = evaluate([5.0, 0.0, 0.3], [5.0, 0.0, 0.3], coef)
    w = coef[F.ALPHA] / TAU_STAR
    np.testing.assert_allclose(a, [0.0, -w, 0.0], atol=1e-15)
    for k in range(F.N_TERMS):
        if k != F.TERM_WEIGHT:
            assert np.all(terms[k] == 0.0), F.TERM_NAMES[k]


def test_weight_on_slope():
    th = math.radians(3.0)
    coef = coefficients(slope=th, drag=False)
    a, _ = evaluate([0, 0, 0], [0, 0, 0], coef)
    w = coef[F.ALPHA] / TAU_STAR
    np.testing.assert_allclose(a, [w * math.sin(th), -w * math.cos(th), 0.0], rtol=1e-14)


def test_added_mass_and_fluid_acceleration_index_convention():
    # shear u = S y: grad[0, 1] = du/dy = S; plus unsteadiness du/dt
    S, dudt = 2.0, np.array([0.1, -0.2, 0.3])
    grad = np.zeros((3, 3))
    grad[0, 1] = S
    up = np.array([1.0, 0.5, 0.0])      # moves up through the shear
    uf = np.array([3.0, 0.0, 0.0])      # fluid moves along x: (u_f·∇)u_f = 0
    coef = coefficients(weight=False, drag=False, lift=False, magnus=False)
    _, terms = evaluate(up, uf, coef, grad=grad, dudt=dudt)
    al, cm = coef[F.ALPHA], coef[F.CM]
    np.testing.assert_allclose(terms[F.TERM_ADDED_MASS], al * cm * (dudt + [S * 0.5, 0, 0]))
    np.testing.assert_allclose(terms[F.TERM_FLUID_ACC], al * dudt)


def test_terms_sum_to_total_and_switches():
    rng = np.random.default_rng(7)
    coef = coefficients()
    args = dict(grad=rng.normal(size=(3, 3)), dudt=rng.normal(size=3),
                vort=rng.normal(size=3), spin=rng.normal(size=3),
                top=rng.normal(size=3), bot=rng.normal(size=3))
    up, uf = rng.normal(size=3), rng.normal(size=3)
    total, terms = evaluate(up, uf, coef, **args)
    np.testing.assert_allclose(terms.sum(axis=0), total, rtol=1e-13, atol=1e-14)
    assert np.all(np.linalg.norm(terms, axis=1) > 0)
    switches = ["weight", "drag", "lift", "magnus", "added_mass", "fluid_acceleration"]
    for k, name in enumerate(switches):
        off = coefficients(**{name: False})
        t2, terms2 = evaluate(up, uf, off, **args)
        assert np.all(terms2[k] == 0.0)
        np.testing.assert_allclose(t2, total - terms[k], rtol=1e-12, atol=1e-13)


def test_make_coefficients():
    c = F.make_coefficients(tau_star=0.06, Rp=73.0, R=1.65)
    assert c[F.ALPHA] == pytest.approx(1 / 3.15)
    assert c[F.RE_STAR] == pytest.approx(math.sqrt(0.06) * 73.0)
    assert c[F.BASSET_PREFACTOR] == pytest.approx(
        9 * c[F.ALPHA] / (math.sqrt(math.pi * 73.0) * 0.06 ** 0.25))
    assert c.shape == (F.N_COEF,)
    with pytest.raises(ValueError):
        F.make_coefficients(tau_star=0.06, Rp=73.0, re_star=10.0)
    with pytest.raises(ValueError):
        F.make_coefficients(tau_star=0.06)
