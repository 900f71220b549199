"""Bed rebound and virtual rough bed (saltation/bed/virtual.py, SPEC §4), and the
counter-based random numbers they draw from (saltation/physics/rng.py)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from saltation.bed import virtual as B
from saltation.physics import rng

R = 0.5
INERTIA = 0.4 * R * R          # (2/5) m r², m = 1


def kinetic_energy(u, w):
    return 0.5 * np.dot(u, u) + 0.5 * INERTIA * np.dot(w, w)


def contact_slip(u, w, n):
    return u + np.cross(w, -R * n)


def unit(v):
    return v / np.linalg.norm(v)


def approaching(u, n):
    """Flip u so that u·n < 0 (and not tangent)."""
    un = np.dot(u, n)
    return u - 2 * un * n if un > 0 else u


finite = st.floats(-10, 10, allow_nan=False)
vec3 = st.tuples(finite, finite, finite).map(np.array)
direction = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
    lambda t: sum(x * x for x in t) > 1e-2).map(lambda t: unit(np.array(t, float)))


# ------------------------------------------------------------------ rebound
def test_elastic_frictionless_conserves_energy_and_flips_normal():
    rs = np.random.default_rng(0)
    for _ in range(50):
        n = unit(rs.normal(size=3))
        u = approaching(rs.normal(size=3) * 3, n)
        w = rs.normal(size=3) * 5
        u1, w1 = u.copy(), w.copy()
        B.rebound(u1, w1, n, 1.0, 0.0)
        np.testing.assert_allclose(u1, u - 2 * np.dot(u, n) * n, atol=1e-13)
        np.testing.assert_array_equal(w1, w)
        assert kinetic_energy(u1, w1) == pytest.approx(kinetic_energy(u, w), rel=1e-13)


def test_sticking_leaves_rolling_without_slip():
    n = unit(np.array([-0.2, 1.0, 0.1]))
    u = np.array([1.0, -2.0, 0.3])
    w = np.array([0.5, 0.0, -1.0])
    code = B.rebound(u, w, n, 0.6, 0.9)
    assert code == B.STICK
    c = contact_slip(u, w, n)
    ct = c - np.dot(c, n) * n
    assert np.linalg.norm(ct) < 1e-13


def test_sliding_removes_exactly_the_coulomb_impulse():
    n = unit(np.array([0.1, 1.0, -0.2]))
    u0 = np.array([4.0, -1.0, 0.5])
    w0 = np.array([0.0, 0.3, 2.0])
    e, f = 0.65, 0.1
    u, w = u0.copy(), w0.copy()
    code = B.rebound(u, w, n, e, f)
    assert code == B.SLIDE
    un0 = np.dot(u0, n)
    assert np.dot(u, n) == pytest.approx(-e * un0)
    c0 = contact_slip(u0, w0, n)
    ct0 = c0 - np.dot(c0, n) * n
    ut0 = u0 - un0 * n
    ut1 = u - np.dot(u, n) * n
    np.testing.assert_allclose(ut0 - ut1, f * (1 + e) * abs(un0) * unit(ct0), atol=1e-13)


def test_not_approaching_is_left_alone():
    u = np.array([1.0, 2.0, 0.0])
    w = np.array([0.0, 0.0, 1.0])
    assert B.rebound(u, w, np.array([0.0, 1.0, 0.0]), 0.5, 0.5) == B.NO_IMPACT
    np.testing.assert_array_equal(u, [1.0, 2.0, 0.0])


@settings(max_examples=300, deadline=None)
@given(u=vec3, w=vec3, n=direction, e=st.floats(0, 1), f=st.floats(0, 1))
def test_rebound_never_creates_energy_and_conserves_contact_angular_momentum(u, w, n, e, f):
    u = approaching(u, n)
    u1, w1 = u.copy(), w.copy()
    code = B.rebound(u1, w1, n, e, f)
    ke0 = kinetic_energy(u, w)
    assert kinetic_energy(u1, w1) <= ke0 * (1 + 1e-12) + 1e-12
    if code != B.NO_IMPACT:
        assert np.dot(u1, n) >= -1e-12 * (1 + np.linalg.norm(u))
        # impulse acts at the contact point: angular momentum about it is conserved
        l0 = np.cross(R * n, u) + INERTIA * w
        l1 = np.cross(R * n, u1) + INERTIA * w1
        np.testing.assert_allclose(l1, l0, atol=1e-10 * (1 + np.abs(l0).max()))


# ------------------------------------------------------------------ virtual bed
descending = st.tuples(st.floats(-20, 20), st.floats(-20, -1e-3), st.floats(-20, 20)).map(
    lambda t: np.array(t, float))
open_unit = st.floats(1e-9, 1 - 1e-9)


@settings(max_examples=300, deadline=None)
@given(u=descending, xi1=open_unit, xi2=open_unit,
       tilt_deg=st.floats(5.0, 45.0))
def test_virtual_normal_within_tilt_and_reachable(u, xi1, xi2, tilt_deg):
    n = np.zeros(3)
    max_tilt = math.radians(tilt_deg)
    ok = B.virtual_bed_normal(u, xi1, xi2, max_tilt, n)
    assert ok == 1
    assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-14)
    assert n[1] >= math.cos(max_tilt) - 1e-12
    assert np.dot(u, n) < 0.0
    # margin: incidence at least MIN_INCIDENCE in the along-path plane
    assert -np.dot(unit(u), n) >= math.sin(B.MIN_INCIDENCE) * math.cos(max_tilt) - 1e-12


def test_grazing_grain_only_meets_stoss_faces():
    u = np.array([5.0, -0.01, 0.0])
    n = np.zeros(3)
    for xi1 in np.linspace(0.001, 0.999, 50):
        for xi2 in (0.01, 0.5, 0.99):
            B.virtual_bed_normal(u, xi1, xi2, B.MAX_TILT, n)
            assert n[0] < 0                 # normal faces the incoming grain


def test_vertical_fall_reaches_both_faces_and_rising_grain_is_refused():
    n = np.zeros(3)
    xs = []
    for xi1 in (0.001, 0.999):
        B.virtual_bed_normal(np.array([0.0, -3.0, 0.0]), xi1, 0.5, B.MAX_TILT, n)
        xs.append(n[0])
    assert min(xs) < -0.4 and max(xs) > 0.4
    assert B.virtual_bed_normal(np.array([1.0, 0.2, 0.0]), 0.5, 0.5, B.MAX_TILT, n) == 0
    np.testing.assert_array_equal(n, [0.0, 1.0, 0.0])


@settings(max_examples=300, deadline=None)
@given(u=descending, w=vec3, xi1=open_unit, xi2=open_unit,
       e=st.floats(0, 1), f=st.floats(0, 1))
def test_bed_rebound_leaves_upwards_without_creating_energy(u, w, xi1, xi2, e, f):
    n = np.zeros(3)
    B.virtual_bed_normal(u, xi1, xi2, B.MAX_TILT, n)
    u1, w1 = u.copy(), w.copy()
    code = B.bed_rebound(u1, w1, n, e, f)
    assert code & 3 in (B.STICK, B.SLIDE)
    assert u1[1] >= 0.0
    assert kinetic_energy(u1, w1) <= kinetic_energy(u, w) * (1 + 1e-12) + 1e-12


def test_lee_face_with_low_restitution_needs_the_second_impact():
    # steep fall onto a lee face, e small: first impact alone leaves downwards
    u = np.array([0.1, -1.0, 0.0])
    n = unit(np.array([0.5, 0.866, 0.0]))
    u1, w1 = u.copy(), np.zeros(3)
    B.rebound(u1, w1, n, 0.08, 0.89)
    assert u1[1] < 0
    u2, w2 = u.copy(), np.zeros(3)
    code = B.bed_rebound(u2, w2, n, 0.08, 0.89)
    assert code & B.SECOND_IMPACT
    assert u2[1] == pytest.approx(-0.08 * u1[1])      # second impact on the flat bed
    assert kinetic_energy(u2, w2) < kinetic_energy(u1, w1)


# ------------------------------------------------------------------ coefficients
def test_coefficient_sets():
    assert B.coefficient_set() == (0.65, 0.10, "schmeeckle-2001")
    assert B.coefficient_set("tsuji-1987")[:2] == (0.80, 0.40)
    e, f, _ = B.coefficient_set("nino-garcia-1994", tau_ratio=1.79)
    assert e == pytest.approx(0.75 - 0.25 * 1.79) and f == 0.89
    assert B.coefficient_set("user", restitution=0.3, friction=0.2)[:2] == (0.3, 0.2)
    with pytest.raises(ValueError):
        B.coefficient_set("nino-garcia-1994", tau_ratio=3.5)       # e < 0
    with pytest.raises(ValueError):
        B.coefficient_set("nino-garcia-1994")
    with pytest.raises(ValueError):
        B.coefficient_set("bogus")
    with pytest.raises(ValueError):
        B.coefficient_set("user", restitution=1.2, friction=0.1)


# ------------------------------------------------------------------ random numbers
@njit(cache=True)
def _draw(seed, n, kind):
    out = np.empty(n)
    for i in range(n):
        if kind == 0:
            out[i] = rng.uniform(seed, i % 97, i // 97)
        else:
            out[i] = rng.normal(seed, i % 97, i // 97)
    return out


def test_rng_deterministic_and_counter_based():
    a = _draw(12345, 1000, 0)
    b = _draw(12345, 1000, 0)
    np.testing.assert_array_equal(a, b)
    # same value whatever the order of evaluation (counter-based)
    assert rng.uniform(12345, 5, 3) == a[3 * 97 + 5]
    c = _draw(12346, 1000, 0)
    assert np.mean(a == c) < 0.01
    x1, x2 = rng.uniform2(1, 2, 3)
    assert (x1, x2) == rng.uniform2(1, 2, 3) and x1 != x2
    assert rng.uniform(1, 2, 3) != rng.uniform(1, 3, 3) != rng.uniform(1, 2, 4)


def test_rng_uniform_and_normal_statistics():
    n = 200_000
    u = _draw(2024, n, 0)
    assert u.min() > 0.0 and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 5 * math.sqrt(1 / 12 / n)
    assert abs(u.var() - 1 / 12) < 5 * math.sqrt(1 / 180 / n)
    counts = np.histogram(u, bins=20, range=(0, 1))[0]
    chi2 = np.sum((counts - n / 20) ** 2 / (n / 20))
    assert chi2 < 50                                 # 19 dof: p ~ 1e-4
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01
    g = _draw(99, n, 1)
    assert abs(g.mean()) < 5 / math.sqrt(n)
    assert abs(g.var() - 1) < 5 * math.sqrt(2 / n)
