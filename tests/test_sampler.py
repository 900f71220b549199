"""Interpolation, gradient, periodicity, time looping and sublayer of the flow sampler."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flowfields.dataset import in_memory_dataset

NX, NY, NZ = 6, 7, 5
DX, DZ = 3.0, 2.0
Y = np.array([1.0, 2.0, 4.0, 7.0, 11.0, 16.0, 22.0])  # stretched, first centre y⁺ = 1


def _trilinear_coeffs(rng):
    return rng.normal(size=(3, 8))


def _trilinear_value(c, x, y, z):
    # a + b x + c y + d z + e xy + f xz + g yz + h xyz, per component
    basis = np.stack([np.ones_like(x), x, y, z, x * y, x * z, y * z, x * y * z], axis=-1)
    return basis @ c.T


def _dataset_from_function(fn, times=(0.0,)):
    x = DX * (np.arange(NX) + 0.5)
    z = DZ * (np.arange(NZ) + 0.5)
    X, Yg, Z = np.meshgrid(x, Y, z, indexing="ij")
    u = np.stack([fn(X, Yg, Z, t) for t in times])
    return in_memory_dataset(x, Y, z, u, re_tau=22.0, times_plus=list(times))


def test_trilinear_field_is_reproduced_exactly_inside_the_grid():
    rng = np.random.default_rng(1)
    c = _trilinear_coeffs(rng)
    ds = _dataset_from_function(lambda X, Yg, Z, t: _trilinear_value(c, X, Yg, Z))
    # points strictly inside the non-periodic part of the grid (no seam crossing)
    pts = np.column_stack(
        [rng.uniform(DX * 0.5, DX * (NX - 0.5), 200), rng.uniform(Y[0], Y[-1], 200), rng.uniform(DZ * 0.5, DZ * (NZ - 0.5), 200)]
    )
    u, g, _ = ds.sample(pts, 0.0)
    np.testing.assert_allclose(u, _trilinear_value(c, pts[:, 0], pts[:, 1], pts[:, 2]), rtol=1e-5, atol=1e-4)


def test_gradient_of_trilinear_field_is_exact():
    rng = np.random.default_rng(2)
    c = _trilinear_coeffs(rng)
    ds = _dataset_from_function(lambda X, Yg, Z, t: _trilinear_value(c, X, Yg, Z))
    pts = np.column_stack([rng.uniform(2, 14, 100), rng.uniform(1.5, 20, 100), rng.uniform(1.5, 8, 100)])
    _, g, _ = ds.sample(pts, 0.0)
    x, y, z = pts.T
    # analytic derivatives of a + b x + c y + d z + e xy + f xz + g yz + h xyz
    dudx = c[:, 1][None] + c[:, 4][None] * y[:, None] + c[:, 5][None] * z[:, None] + c[:, 7][None] * (y * z)[:, None]
    dudy = c[:, 2][None] + c[:, 4][None] * x[:, None] + c[:, 6][None] * z[:, None] + c[:, 7][None] * (x * z)[:, None]
    dudz = c[:, 3][None] + c[:, 5][None] * x[:, None] + c[:, 6][None] * y[:, None] + c[:, 7][None] * (x * y)[:, None]
    np.testing.assert_allclose(g[:, :, 0], dudx, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(g[:, :, 1], dudy, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(g[:, :, 2], dudz, rtol=1e-4, atol=1e-4)


def test_gradient_and_vorticity_of_smooth_periodic_field_converge():
    """Shear + periodic vortex field: gradient error falls ~ second order with refinement."""
    errs = []
    for n in (16, 32, 64):
        lx = 100.0
        x = lx / n * (np.arange(n) + 0.5)
        z = x.copy()
        y = np.linspace(1.0, 50.0, n)
        X, Yg, Z = np.meshgrid(x, y, z, indexing="ij")
        k = 2 * np.pi / lx
        ux = 0.3 * Yg + np.sin(k * Z)
        uy = np.sin(k * X) * 0.5
        uz = np.cos(k * X)
        u = np.stack([ux, uy, uz], axis=-1)[None]
        ds = in_memory_dataset(x, y, z, u, re_tau=50.0, times_plus=[0.0])
        rng = np.random.default_rng(3)
        p = np.column_stack([rng.uniform(0, lx, 300), rng.uniform(5, 45, 300), rng.uniform(0, lx, 300)])
        w = ds.vorticity(p, 0.0)
        # ω = (∂w/∂y − ∂v/∂z, ∂u/∂z − ∂w/∂x, ∂v/∂x − ∂u/∂y)
        wx = np.zeros(len(p))
        wy = k * np.cos(k * p[:, 2]) + k * np.sin(k * p[:, 0])
        wz = 0.5 * k * np.cos(k * p[:, 0]) - 0.3
        errs.append(np.max(np.abs(w - np.column_stack([wx, wy, wz]))))
    # gradient of the trilinear interpolant is first order pointwise, second at centres:
    # require at least first-order decay and a small error on the finest grid
    assert errs[1] < 0.6 * errs[0] and errs[2] < 0.6 * errs[1]
    assert errs[2] < 0.02


@settings(max_examples=50, deadline=None)
@given(
    x=st.floats(-50, 50),
    y=st.floats(1.0, 22.0),
    z=st.floats(-50, 50),
    m=st.integers(-3, 3),
    q=st.integers(-3, 3),
)
def test_periodic_in_x_and_z(x, y, z, m, q):
    rng = np.random.default_rng(4)
    u = rng.normal(size=(1, NX, len(Y), NZ, 3))
    ds = in_memory_dataset(DX * (np.arange(NX) + 0.5), Y, DZ * (np.arange(NZ) + 0.5), u, 22.0, [0.0])
    a = ds.velocity([[x, y, z]], 0.0)
    b = ds.velocity([[x + m * NX * DX, y, z + q * NZ * DZ]], 0.0)
    np.testing.assert_allclose(a, b, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(y=st.floats(1.0, 22.0), z=st.floats(0, NZ * DZ), eps=st.floats(1e-9, 1e-6))
def test_continuous_across_the_periodic_seam(y, z, eps):
    rng = np.random.default_rng(5)
    u = rng.normal(size=(1, NX, len(Y), NZ, 3))
    ds = in_memory_dataset(DX * (np.arange(NX) + 0.5), Y, DZ * (np.arange(NZ) + 0.5), u, 22.0, [0.0])
    lx = NX * DX
    left = ds.velocity([[lx - eps, y, z]], 0.0)
    right = ds.velocity([[lx + eps, y, z]], 0.0)
    np.testing.assert_allclose(left, right, atol=1e-4)


def test_time_is_linear_between_snapshots_and_loops():
    times = [0.0, 2.0, 4.0]
    ds = _dataset_from_function(lambda X, Yg, Z, t: np.stack([np.full_like(X, t), 0 * X, 0 * X], axis=-1), times)
    p = [[4.0, 5.0, 3.0]]
    assert ds.velocity(p, 1.0)[0, 0] == pytest.approx(1.0)
    assert ds.velocity(p, 3.5)[0, 0] == pytest.approx(3.5)
    assert ds.dudt(p, 1.0)[0, 0] == pytest.approx(1.0)
    # period = 3 snapshots × 2 = 6: t = 7 ≡ 1
    assert ds.velocity(p, 7.0)[0, 0] == pytest.approx(1.0)
    # after the last snapshot the series runs back to the first: t = 5 halfway 4 → 0
    assert ds.velocity(p, 5.0)[0, 0] == pytest.approx(2.0)


def test_viscous_sublayer_profile_and_continuity():
    ds = _dataset_from_function(lambda X, Yg, Z, t: np.stack([0.9 * Yg + 0.2 * np.sin(X), 0.1 + 0 * X, 0.3 + 0 * X], axis=-1))
    x, z = 4.0, 3.0
    u1 = ds.velocity([[x, Y[0], z]], 0.0)[0]
    below = ds.velocity([[x, Y[0] * (1 - 1e-9), z]], 0.0)[0]
    np.testing.assert_allclose(u1, below, atol=1e-6)  # continuous at the first centre
    half = ds.velocity([[x, 0.5 * Y[0], z]], 0.0)[0]
    # u_x = y + (y/y1)(u1 - y1); v, w linear to zero
    assert half[0] == pytest.approx(0.5 + 0.5 * (u1[0] - 1.0))
    assert half[1] == pytest.approx(0.5 * u1[1])
    assert half[2] == pytest.approx(0.5 * u1[2])
    np.testing.assert_allclose(ds.velocity([[x, 0.0, z]], 0.0)[0], 0.0, atol=1e-12)
    g = ds.gradient([[x, 0.3, z]], 0.0)[0]
    assert g[0, 1] == pytest.approx(1.0 + (u1[0] - 1.0) / 1.0)


def test_points_outside_wall_normal_range_are_refused_with_the_point_named():
    ds = _dataset_from_function(lambda X, Yg, Z, t: np.stack([Yg, 0 * X, 0 * X], axis=-1))
    with pytest.raises(ValueError, match=r"point 1 at y⁺ = 30"):
        ds.velocity([[1.0, 5.0, 1.0], [1.0, 30.0, 1.0]], 0.0)
    with pytest.raises(ValueError, match=r"point 0 at y⁺ = -1"):
        ds.velocity([[1.0, -1.0, 1.0]], 0.0)
    with pytest.raises(ValueError, match="not finite"):
        ds.velocity([[np.nan, 1.0, 1.0]], 0.0)
