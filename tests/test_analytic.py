"""Analytic profiles at known y⁺, sampled through the same kernel as LES data."""
import numpy as np
import pytest

from flowfields.analytic import log_law, profile_dataset, reichardt, rough_log_law


def test_log_law_values():
    assert log_law(100.0) == pytest.approx(np.log(100.0) / 0.41 + 5.5)
    assert log_law(3.0) == pytest.approx(3.0)  # sublayer below the crossing (y⁺ ≈ 11)
    y_cross = 10.8
    assert abs(log_law(y_cross) - y_cross) < 0.3  # continuous at the crossing


def test_rough_log_law_values():
    assert rough_log_law(60.0, ks_plus=20.0) == pytest.approx(2.5 * np.log(90.0))
    assert rough_log_law(0.5, ks_plus=20.0) == 0.0  # below y0 = ks/30


def test_reichardt_is_continuous_from_the_wall():
    assert reichardt(0.0) == pytest.approx(0.0, abs=1e-12)
    assert reichardt(1.0) == pytest.approx(1.0, rel=0.05)  # u⁺ ≈ y⁺ in the sublayer
    assert reichardt(1000.0) == pytest.approx(np.log(1000.0) / 0.41 + 5.0, rel=0.03)


@pytest.mark.parametrize("profile,ref", [
    ("loglaw", lambda y: log_law(y)),
    ("composite", lambda y: reichardt(y)),
    ("rough", lambda y: rough_log_law(y, 35.0)),
])
def test_sampled_profiles_match_the_formula(profile, ref):
    ds = profile_dataset(profile, y_top_plus=1000.0, ks_plus=35.0 if profile == "rough" else None)
    y = np.array([0.5, 2.0, 5.0, 10.0, 30.0, 100.0, 500.0])
    pts = np.column_stack([np.full_like(y, 123.0), y, np.full_like(y, -77.0)])
    u = ds.velocity(pts, 42.0)
    np.testing.assert_allclose(u[:, 0], ref(y), rtol=2e-3, atol=2e-3)
    np.testing.assert_allclose(u[:, 1:], 0.0)
    g = ds.gradient(pts, 0.0)
    # du/dy of the log law = 1/(κ y) in the log region
    if profile == "loglaw":
        np.testing.assert_allclose(g[-2:, 0, 1], 1 / (0.41 * y[-2:]), rtol=0.02)
    assert np.allclose(ds.dudt(pts, 3.0), 0.0)


def test_still_fluid_is_zero():
    ds = profile_dataset("still", y_top_plus=100.0)
    assert np.all(ds.velocity([[1.0, 5.0, 2.0]], 0.0) == 0.0)


def test_unknown_profile_is_refused():
    with pytest.raises(ValueError, match="'spalding' is not one of"):
        profile_dataset("spalding")
