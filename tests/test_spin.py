"""Spin equation (saltation/physics/spin.py, SPEC §2)."""

import math

import numpy as np
import pytest

from saltation.physics import spin as S


def test_stokes_row_is_stokes_torque():
    # dimensional check: quartz grain in water, small relative spin (Re_r < 1)
    d, nu, rho, rho_p, ustar = 0.5e-3, 1.0e-6, 1000.0, 2650.0, 0.02
    R = rho_p / rho - 1.0
    re_star = ustar * d / nu
    omega_r = 2.0                                   # rad/s
    assert d * d * omega_r / (4 * nu) < 1.0         # first table row
    spin = np.array([0.0, 0.0, omega_r / (ustar / d)])   # particle units
    rate = np.zeros(3)
    S.spin_rate(spin, np.zeros(3), R, re_star, rate)
    rate_dim = rate[2] * (ustar / d) ** 2           # rad/s²
    mu, a = rho * nu, d / 2
    torque = 8 * math.pi * mu * a ** 3 * omega_r    # Stokes: T = 8πμa³ω
    inertia = math.pi * rho_p * d ** 5 / 60.0       # (2/5) m a²
    assert rate_dim == pytest.approx(-torque / inertia, rel=1e-12)


def test_spin_relaxes_to_half_vorticity():
    vort = np.array([0.4, -1.0, 6.0])
    for s0 in (np.zeros(3), np.array([-20.0, 5.0, 30.0])):
        s = s0.copy()
        k = np.zeros(3)
        dt = 0.01
        for _ in range(5000):           # explicit Euler is enough for a relaxation
            S.spin_rate(s, vort, 1.65, 17.4, k)
            s += dt * k
        np.testing.assert_allclose(s, 0.5 * vort, atol=1e-6)


def test_rate_opposes_relative_spin_and_vanishes_at_half_vorticity():
    rng = np.random.default_rng(3)
    out = np.zeros(3)
    for _ in range(50):
        vort = rng.normal(size=3) * 5
        spin = rng.normal(size=3) * 5
        S.spin_rate(spin, vort, 1.65, 17.4, out)
        rel = spin - 0.5 * vort
        assert np.dot(out, rel) < 0
        assert np.linalg.norm(np.cross(out, rel)) < 1e-10 * np.linalg.norm(out) * np.linalg.norm(rel)
    S.spin_rate(np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, -2.0]), 1.65, 17.4, out)
    assert np.all(out == 0)


def test_rate_matches_coefficient_table():
    R, re_star = 1.65, 17.4
    out = np.zeros(3)
    for re_r in (0.3, 3.0, 15.0, 35.0, 120.0):
        w = 4 * re_r / re_star
        S.spin_rate(np.array([w, 0, 0]), np.zeros(3), R, re_star, out)
        expect = -15 / (16 * math.pi * (1 + R)) * S.spin_coefficient(re_r) * w * w
        assert out[0] == pytest.approx(expect, rel=1e-12)


def test_coefficient_table_values_and_near_continuity():
    assert S.spin_coefficient(0.5) == pytest.approx(16 * math.pi / 0.5)
    assert S.spin_coefficient(5.0) == pytest.approx(16 * math.pi / 5 + 0.0418 * 5)
    assert S.spin_coefficient(15.0) == pytest.approx(5.32 / math.sqrt(15) + 37.2 / 15)
    assert S.spin_coefficient(30.0) == pytest.approx(6.44 / math.sqrt(30) + 32.2 / 30)
    assert S.spin_coefficient(80.0) == pytest.approx(6.45 / math.sqrt(80) + 32.1 / 80)
    for edge in (1.0, 10.0, 20.0, 50.0):
        lo = S.spin_coefficient(edge * (1 - 1e-12))
        hi = S.spin_coefficient(edge)
        assert hi == pytest.approx(lo, rel=0.01)     # tabulated fits join within 1 %
    assert math.isfinite(S.spin_coefficient(0.0))
