"""Numba sampling kernels for flow data on a tensor-product grid (SPEC §3).

One kernel serves every flow source: LES snapshots and the analytic profiles are all
stored as cell-centred velocity on a grid that is uniform and periodic in x and z and
stretched in y (wall at y = 0). Everything here is in wall units (x⁺, y⁺, z⁺, u⁺, t⁺).

* Space: trilinear interpolation between the eight surrounding grid values.
* Time: linear interpolation between the two bracketing snapshots; the series loops
  (after the last snapshot the interpolation runs back to the first one over one
  snapshot interval).
* Gradient ∂u_i/∂x_j: the exact gradient of the trilinear interpolant (piecewise
  bilinear, continuous inside a cell, second-order accurate at cell centres; exact
  for fields that are trilinear themselves). ∂u/∂t: the slope of the linear time
  interpolant.
* Between the wall and the first cell centre y₁ (viscous sublayer, SPEC §3):
  u_x = y⁺ + (y/y₁)(u_x(y₁) − y₁⁺),  u_y = (y/y₁) u_y(y₁),  u_z = (y/y₁) u_z(y₁)
  i.e. the mean follows u⁺ = y⁺ and the fluctuations scale linearly to zero at the
  wall; the profile is continuous at y₁.
* Below the wall (y < 0) the fluid is at rest (status BELOW_WALL); above the top of the
  stored range the value at the top is returned with status ABOVE_TOP so that callers
  can refuse the point.

The grid and data travel as a ``FlowArrays`` named tuple, which Numba passes to
``@njit`` functions as a plain tuple of arrays and numbers.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

OK = 0
ABOVE_TOP = 1
BELOW_WALL = 2


class FlowArrays(NamedTuple):
    """Everything a kernel needs to sample one dataset (wall units)."""

    data: np.ndarray  # (nt, nx, ny, nz, 3) float32 or int16 (quantized)
    scale: np.ndarray  # (3,) float64: u⁺ = data * scale + offset
    offset: np.ndarray  # (3,) float64
    x0: float  # x⁺ of the first cell centre
    dx: float  # uniform spacing in x⁺ (period nx*dx)
    nx: int
    y: np.ndarray  # (ny,) float64 cell-centre y⁺, increasing, y[0] > 0
    z0: float
    dz: float
    nz: int
    t0: float  # t⁺ of the first snapshot
    dt: float  # snapshot interval in t⁺ (loop period nt*dt); 1.0 when nt == 1
    nt: int


@njit(cache=True, inline="always")
def _locate_periodic(s, s0, ds, n):
    """Index of the lower neighbour and the weight of the upper one on a periodic axis."""
    q = (s - s0) / ds
    fl = np.floor(q)
    w = q - fl
    i = int(fl) % n
    if i < 0:
        i += n
    return i, (i + 1) % n, w


@njit(cache=True, inline="always")
def _locate_y(y, yp):
    """Index j with y[j] <= yp < y[j+1] (binary search); yp inside [y[0], y[-1]]."""
    lo = 0
    hi = y.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if y[mid] <= yp:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _trilinear(f, it, wt, wdt, i0, i1, wx, j0, j1, wy, dyc, k0, k1, wz, u, g, dudt, with_gradient):
    """Add snapshot it of the trilinear interpolant with time weight wt.

    u[c] += wt*value, g[c, 0..2] += wt*(d/dx, d/dy, d/dz), dudt[c] += wdt*value
    (dyc = y[j1]-y[j0]; no y-derivative when dyc == 0, i.e. a single plane)."""
    d = f.data
    for c in range(3):
        sc = f.scale[c]
        of = f.offset[c]
        v000 = d[it, i0, j0, k0, c] * sc + of
        v100 = d[it, i1, j0, k0, c] * sc + of
        v010 = d[it, i0, j1, k0, c] * sc + of
        v110 = d[it, i1, j1, k0, c] * sc + of
        v001 = d[it, i0, j0, k1, c] * sc + of
        v101 = d[it, i1, j0, k1, c] * sc + of
        v011 = d[it, i0, j1, k1, c] * sc + of
        v111 = d[it, i1, j1, k1, c] * sc + of
        # interpolate in x first
        a00 = v000 + wx * (v100 - v000)
        a10 = v010 + wx * (v110 - v010)
        a01 = v001 + wx * (v101 - v001)
        a11 = v011 + wx * (v111 - v011)
        b0 = a00 + wy * (a10 - a00)
        b1 = a01 + wy * (a11 - a01)
        val = b0 + wz * (b1 - b0)
        u[c] += wt * val
        dudt[c] += wdt * val
        if not with_gradient:
            continue
        # d/dx
        dx00 = v100 - v000
        dx10 = v110 - v010
        dx01 = v101 - v001
        dx11 = v111 - v011
        ex0 = dx00 + wy * (dx10 - dx00)
        ex1 = dx01 + wy * (dx11 - dx01)
        g[c, 0] += wt * (ex0 + wz * (ex1 - ex0)) / f.dx
        # d/dy
        if dyc > 0.0:
            ey0 = a10 - a00
            ey1 = a11 - a01
            g[c, 1] += wt * (ey0 + wz * (ey1 - ey0)) / dyc
        # d/dz
        g[c, 2] += wt * (b1 - b0) / f.dz


@njit(cache=True)
def sample_point(f, xp, yp, zp, tp, u, g, dudt, with_gradient=True):
    """Velocity u (3,), gradient g[i, j] = ∂u_i/∂x_j (3, 3) and ∂u/∂t (3,) at one point.

    All in wall units. Returns a status code (OK, ABOVE_TOP, BELOW_WALL). With
    with_gradient=False, g is left at zero except in the sublayer (cheaper)."""
    for c in range(3):
        u[c] = 0.0
        dudt[c] = 0.0
        for k in range(3):
            g[c, k] = 0.0
    if yp < 0.0:
        return BELOW_WALL
    status = OK
    ny = f.y.shape[0]
    y1 = f.y[0]
    ytop = f.y[ny - 1]
    ys = yp
    if ys > ytop:
        ys = ytop
        status = ABOVE_TOP
    sublayer = ys < y1
    if sublayer:
        ys = y1
    i0, i1, wx = _locate_periodic(xp, f.x0, f.dx, f.nx)
    k0, k1, wz = _locate_periodic(zp, f.z0, f.dz, f.nz)
    if ny == 1:
        j0 = 0
        j1 = 0
        wy = 0.0
        dyc = 0.0
    else:
        j0 = _locate_y(f.y, ys)
        j1 = j0 + 1
        dyc = f.y[j1] - f.y[j0]
        wy = (ys - f.y[j0]) / dyc
    # time: linear, looping
    if f.nt == 1:
        _trilinear(f, 0, 1.0, 0.0, i0, i1, wx, j0, j1, wy, dyc, k0, k1, wz, u, g, dudt, with_gradient)
    else:
        n0, n1, wt = _locate_periodic(tp, f.t0, f.dt, f.nt)
        _trilinear(f, n0, 1.0 - wt, -1.0 / f.dt, i0, i1, wx, j0, j1, wy, dyc, k0, k1, wz, u, g, dudt, with_gradient)
        _trilinear(f, n1, wt, 1.0 / f.dt, i0, i1, wx, j0, j1, wy, dyc, k0, k1, wz, u, g, dudt, with_gradient)
    if sublayer:
        # SPEC §3 viscous sublayer between the wall and the first cell centre
        r = yp / y1
        u1x = u[0]
        u1y = u[1]
        u1z = u[2]
        u[0] = yp + r * (u1x - y1)
        u[1] = r * u1y
        u[2] = r * u1z
        for c in range(3):
            dudt[c] = r * dudt[c]
            g[c, 0] = r * g[c, 0]
            g[c, 2] = r * g[c, 2]
        g[0, 1] = 1.0 + (u1x - y1) / y1
        g[1, 1] = u1y / y1
        g[2, 1] = u1z / y1
    if status == ABOVE_TOP:
        # the top value is held constant above the range: no y-derivative there
        for c in range(3):
            g[c, 1] = 0.0
    return status


@njit(cache=True, inline="always")
def vorticity_from_gradient(g, w):
    """ω = ∇ × u from g[i, j] = ∂u_i/∂x_j."""
    w[0] = g[2, 1] - g[1, 2]
    w[1] = g[0, 2] - g[2, 0]
    w[2] = g[1, 0] - g[0, 1]


@njit(cache=True, parallel=True)
def sample_many(f, points, tp, u, g, dudt, status):
    """Parallel over points: fill u (N,3), g (N,3,3), dudt (N,3), status (N,)."""
    n = points.shape[0]
    for p in prange(n):
        status[p] = sample_point(
            f, points[p, 0], points[p, 1], points[p, 2], tp, u[p], g[p], dudt[p]
        )


@njit(cache=True, parallel=True)
def sample_velocity_many(f, points, tp, u, status):
    """Parallel over points: velocity only (the gradient comes for free but is dropped)."""
    n = points.shape[0]
    for p in prange(n):
        g = np.empty((3, 3))
        d = np.empty(3)
        status[p] = sample_point(f, points[p, 0], points[p, 1], points[p, 2], tp, u[p], g, d, False)
