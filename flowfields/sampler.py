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
* Rough bed (the LES carries a porous layer of grains, flowfields.rough_bed): y⁺ = 0 is
  the bed top, and the stored grid runs down into the layer (negative y⁺) to its floor
  ``y_floor`` (the LES wall under the layer). Between the bed top and the first cell
  centres above it the velocity is the trilinear interpolant between the cell centres
  straddling the bed top (the LES's own slip and shear there, no wall law); inside the
  layer it is the LES's superficial velocity, so a grain dipping below the bed top sees
  the slow pore flow (for lift, its bottom), not zero; below the lowest centre it falls
  linearly to zero at the floor (``sublayer_slope`` = 0), and below the floor it is zero.
  For a smooth wall ``y_floor`` = 0 and ``sublayer_slope`` = 1 give the viscous-sublayer
  law below (same arithmetic bit for bit).

The grid and data travel as a ``FlowArrays`` named tuple, which Numba passes to
``@njit`` functions as a plain tuple of arrays and numbers.

How the kernels are made fast (they run four times per grain and time step):

* the two bracketing snapshots are blended per grid node on the raw (possibly int16)
  values, then one trilinear pass gives the value, its gradient and its change over
  the snapshot interval; scale and offset (quantization) are applied once at the end;
* each of the 8 nodes is read once with its 3 components (adjacent in memory), not
  once per component (``_node3``; ~4 % less time per sample, same arithmetic);
* ``sample_column`` samples a grain's centre (with gradient) and its top and bottom
  (velocity only) on one vertical: x, z and time are located once;
* the periodic index is taken modulo the period in floating point (an integer division
  per axis cost ~20 % of a sample: grains leave the first period within seconds);
* the y search is a binary search of fixed trip count with a conditional move;
* ``gather_cell`` / ``velocity_in_cell`` split a velocity sample into the cell's 8
  nodes blended in time and the trilinear weights, so that a caller can reuse the
  gathered nodes for another point of the same cell at the same time (flight/spheres.py:
  the two RK4 stages at t + Δt/2, and the last stage and the end-of-step sample at t + Δt);
* the public kernels are compiled without reference counting (``_nrt=False``: they
  take arrays and allocate nothing, and an atomic increment/decrement per array
  argument and per view costs more than the arithmetic) and with fused multiply-add
  contraction (``fastmath={"contract"}``: round-off-level changes only; no assumption
  about NaN or infinity, so non-finite data still propagate and are detected).
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
    y_floor: float  # fluid at rest below: 0 (smooth wall) or the bottom of a rough bed's layer (< 0)
    sublayer_slope: float  # below y[0]: 1 the viscous sublayer u⁺ = y⁺, 0 linear to zero (inside a rough bed)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _locate_periodic(s, s0, ds, n):
    """Index of the lower neighbour and the weight of the upper one on a periodic axis.
    Any input (even a non-finite one) gives indices inside [0, n)."""
    q = (s - s0) / ds
    fl = np.floor(q)
    w = q - fl
    # fl mod n in floating point (exact for |fl| < 2**52 / n; no integer division)
    i = int(fl - n * np.floor(fl / n))
    if i >= n:
        i -= n
    if i < 0 or i >= n:  # non-finite input
        i = 0
    i1 = i + 1
    if i1 >= n:
        i1 = 0
    return i, i1, w


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _locate_y(y, yp):
    """The largest j <= len(y) - 2 with y[j] <= yp, for yp in [y[0], y[-1]]: the cell
    y[j] <= yp < y[j+1] (j = len(y) - 2 at the top). Binary search whose trip count
    depends on len(y) only, the step a conditional move: no mispredicted branches."""
    lo = 0
    n = y.shape[0] - 1
    while n > 1:
        half = n >> 1
        if y[lo + half] <= yp:
            lo += half
        n -= half
    return lo


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def wall_normal(f, yp):
    """Where the height yp falls on the stretched y axis:
    (status, j0, j1, wy, dyc, sublayer) with dyc = y[j1] - y[j0] (0 for a single plane).
    Heights are clamped to [y[0], y[-1]]; ``sublayer`` flags yp < y[0] (SPEC §3)."""
    ny = f.y.shape[0]
    y1 = f.y[0]
    status = OK
    ys = yp
    if yp < f.y_floor:
        status = BELOW_WALL
    if ys > f.y[ny - 1]:
        ys = f.y[ny - 1]
        status = ABOVE_TOP
    sublayer = ys < y1
    if sublayer:
        ys = y1
    if ny == 1:
        return status, 0, 0, 0.0, 0.0, sublayer
    j0 = _locate_y(f.y, ys)
    dyc = f.y[j0 + 1] - f.y[j0]
    return status, j0, j0 + 1, (ys - f.y[j0]) / dyc, dyc, sublayer


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _node3(d, n0, n1, wt, i, j, k):
    """The three stored components at node (i, j, k), linear in time (weight wt on n1),
    and their changes from n0 to n1: one row of 3 values per snapshot (contiguous)."""
    a0 = np.float64(d[n0, i, j, k, 0])
    a1 = np.float64(d[n0, i, j, k, 1])
    a2 = np.float64(d[n0, i, j, k, 2])
    e0 = np.float64(d[n1, i, j, k, 0]) - a0
    e1 = np.float64(d[n1, i, j, k, 1]) - a1
    e2 = np.float64(d[n1, i, j, k, 2]) - a2
    return a0 + wt * e0, a1 + wt * e1, a2 + wt * e2, e0, e1, e2


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _trilinear(v000, v100, v010, v110, v001, v101, v011, v111, wx, wy, wz):
    """Trilinear value of one component from its 8 node values."""
    a00 = v000 + wx * (v100 - v000)
    a10 = v010 + wx * (v110 - v010)
    a01 = v001 + wx * (v101 - v001)
    a11 = v011 + wx * (v111 - v011)
    b0 = a00 + wy * (a10 - a00)
    b1 = a01 + wy * (a11 - a01)
    return b0 + wz * (b1 - b0)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _trilinear_with_gradient(v000, v100, v010, v110, v001, v101, v011, v111,
                             e000, e100, e010, e110, e001, e101, e011, e111, wx, wy, wz):
    """Value, derivatives along the index axes and change over the snapshot interval of
    one component from its 8 node values (exact derivatives of the trilinear interpolant;
    per cell: multiply by 1/dx, 1/dyc, 1/dz)."""
    a00 = v000 + wx * (v100 - v000)
    a10 = v010 + wx * (v110 - v010)
    a01 = v001 + wx * (v101 - v001)
    a11 = v011 + wx * (v111 - v011)
    b0 = a00 + wy * (a10 - a00)
    b1 = a01 + wy * (a11 - a01)
    val = b0 + wz * (b1 - b0)
    dx00 = v100 - v000
    dx10 = v110 - v010
    dx01 = v101 - v001
    dx11 = v111 - v011
    ex0 = dx00 + wy * (dx10 - dx00)
    ex1 = dx01 + wy * (dx11 - dx01)
    ey0 = a10 - a00
    ey1 = a11 - a01
    f00 = e000 + wx * (e100 - e000)
    f10 = e010 + wx * (e110 - e010)
    f01 = e001 + wx * (e101 - e001)
    f11 = e011 + wx * (e111 - e011)
    h0 = f00 + wy * (f10 - f00)
    h1 = f01 + wy * (f11 - f01)
    return val, ex0 + wz * (ex1 - ex0), ey0 + wz * (ey1 - ey0), b1 - b0, h0 + wz * (h1 - h0)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _gradient_at(f, n0, n1, wt, i0, i1, wx, j0, j1, wy, dyc, k0, k1, wz, u, g, dudt):
    """u, g, ∂u/∂t (u⁺ units) at a located point inside the stored y range. The 8 nodes
    are read once each, all 3 components together (they are adjacent in memory)."""
    d = f.data
    inv_dx = 1.0 / f.dx
    inv_dz = 1.0 / f.dz
    inv_dy = 1.0 / dyc if dyc > 0.0 else 0.0  # a single plane: no y-derivative
    inv_dt = 1.0 / f.dt if f.nt > 1 else 0.0
    p000 = _node3(d, n0, n1, wt, i0, j0, k0)
    p100 = _node3(d, n0, n1, wt, i1, j0, k0)
    p010 = _node3(d, n0, n1, wt, i0, j1, k0)
    p110 = _node3(d, n0, n1, wt, i1, j1, k0)
    p001 = _node3(d, n0, n1, wt, i0, j0, k1)
    p101 = _node3(d, n0, n1, wt, i1, j0, k1)
    p011 = _node3(d, n0, n1, wt, i0, j1, k1)
    p111 = _node3(d, n0, n1, wt, i1, j1, k1)
    _store_component(f, 0, p000[0], p100[0], p010[0], p110[0], p001[0], p101[0], p011[0], p111[0],
                     p000[3], p100[3], p010[3], p110[3], p001[3], p101[3], p011[3], p111[3],
                     wx, wy, wz, inv_dx, inv_dy, inv_dz, inv_dt, u, g, dudt)
    _store_component(f, 1, p000[1], p100[1], p010[1], p110[1], p001[1], p101[1], p011[1], p111[1],
                     p000[4], p100[4], p010[4], p110[4], p001[4], p101[4], p011[4], p111[4],
                     wx, wy, wz, inv_dx, inv_dy, inv_dz, inv_dt, u, g, dudt)
    _store_component(f, 2, p000[2], p100[2], p010[2], p110[2], p001[2], p101[2], p011[2], p111[2],
                     p000[5], p100[5], p010[5], p110[5], p001[5], p101[5], p011[5], p111[5],
                     wx, wy, wz, inv_dx, inv_dy, inv_dz, inv_dt, u, g, dudt)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _store_component(f, c, v000, v100, v010, v110, v001, v101, v011, v111,
                     e000, e100, e010, e110, e001, e101, e011, e111,
                     wx, wy, wz, inv_dx, inv_dy, inv_dz, inv_dt, u, g, dudt):
    # component c of u, g and ∂u/∂t from its 8 node values, scaled to u⁺ units
    val, ex, ey, ez, et = _trilinear_with_gradient(
        v000, v100, v010, v110, v001, v101, v011, v111,
        e000, e100, e010, e110, e001, e101, e011, e111, wx, wy, wz)
    sc = f.scale[c]
    u[c] = val * sc + f.offset[c]
    g[c, 0] = ex * sc * inv_dx
    g[c, 1] = ey * sc * inv_dy
    g[c, 2] = ez * sc * inv_dz
    dudt[c] = et * sc * inv_dt


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _sublayer_with_gradient(f, yp, u, g, dudt):
    # SPEC §3 viscous sublayer between the wall and the first cell centre (slope s = 1),
    # or linear to zero at a rough bed's floor (s = 0); heights from the floor
    y1 = f.y[0] - f.y_floor
    yq = yp - f.y_floor
    r = yq / y1
    u1x = u[0]
    u1y = u[1]
    u1z = u[2]
    if f.sublayer_slope != 0.0:  # written as before the rough bed: same bits for a smooth wall
        u[0] = yq + r * (u1x - y1)
        g[0, 1] = 1.0 + (u1x - y1) / y1
    else:
        u[0] = r * u1x
        g[0, 1] = u1x / y1
    u[1] = r * u1y
    u[2] = r * u1z
    for c in range(3):
        dudt[c] = r * dudt[c]
        g[c, 0] = r * g[c, 0]
        g[c, 2] = r * g[c, 2]
    g[1, 1] = u1y / y1
    g[2, 1] = u1z / y1


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _node_velocity(d, n0, n1, wt, i, j, k):
    """The three stored components at node (i, j, k), linear in time (``_node3``
    without the changes)."""
    v = _node3(d, n0, n1, wt, i, j, k)
    return v[0], v[1], v[2]


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def gather_cell(f, n0, n1, wt, i0, i1, j0, j1, k0, k1):
    """The 8 nodes of a located cell, each read once with its 3 components (adjacent in
    memory) and blended in time: 24 raw values, node by node in the order 000, 100,
    010, 110, 001, 101, 011, 111. Points of one cell at one time share it
    (flight/spheres.py reuses it between RK4 stages)."""
    d = f.data
    a = _node_velocity(d, n0, n1, wt, i0, j0, k0)
    b = _node_velocity(d, n0, n1, wt, i1, j0, k0)
    c = _node_velocity(d, n0, n1, wt, i0, j1, k0)
    e = _node_velocity(d, n0, n1, wt, i1, j1, k0)
    g = _node_velocity(d, n0, n1, wt, i0, j0, k1)
    h = _node_velocity(d, n0, n1, wt, i1, j0, k1)
    m = _node_velocity(d, n0, n1, wt, i0, j1, k1)
    q = _node_velocity(d, n0, n1, wt, i1, j1, k1)
    return (a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], e[0], e[1], e[2],
            g[0], g[1], g[2], h[0], h[1], h[2], m[0], m[1], m[2], q[0], q[1], q[2])


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def velocity_in_cell(f, c, wx, wy, wz, yp, sublayer):
    """Velocity (u⁺, three floats) at weights (wx, wy, wz) inside a gathered cell
    (``gather_cell``); the SPEC §3 sublayer law when ``sublayer`` (yp < y[0]).
    ``_velocity_at_height`` goes through it too."""
    u0 = _trilinear(c[0], c[3], c[6], c[9], c[12], c[15], c[18], c[21], wx, wy, wz) * f.scale[0] + f.offset[0]
    u1 = _trilinear(c[1], c[4], c[7], c[10], c[13], c[16], c[19], c[22], wx, wy, wz) * f.scale[1] + f.offset[1]
    u2 = _trilinear(c[2], c[5], c[8], c[11], c[14], c[17], c[20], c[23], wx, wy, wz) * f.scale[2] + f.offset[2]
    if sublayer:
        y1 = f.y[0] - f.y_floor
        yq = yp - f.y_floor
        r = yq / y1
        if f.sublayer_slope != 0.0:  # the viscous sublayer, as before the rough bed
            u0 = yq + r * (u0 - y1)
        else:
            u0 = r * u0
        u1 = r * u1
        u2 = r * u2
    return u0, u1, u2


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _velocity_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, yp, u):
    """Velocity only (u⁺) at height yp with the x, z and time location already known.
    Zero below the wall. Returns the status code."""
    status, j0, j1, wy, _, sublayer = wall_normal(f, yp)
    if status == BELOW_WALL:
        u[0] = 0.0
        u[1] = 0.0
        u[2] = 0.0
        return status
    cell = gather_cell(f, n0, n1, wt, i0, i1, j0, j1, k0, k1)
    u[0], u[1], u[2] = velocity_in_cell(f, cell, wx, wy, wz, yp, sublayer)
    return status


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def _gradient_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, yp, u, g, dudt):
    """u, g, ∂u/∂t (wall units) at height yp with the x, z and time location known."""
    status, j0, j1, wy, dyc, sublayer = wall_normal(f, yp)
    if status == BELOW_WALL:
        for c in range(3):
            u[c] = 0.0
            dudt[c] = 0.0
            for k in range(3):
                g[c, k] = 0.0
        return status
    _gradient_at(f, n0, n1, wt, i0, i1, wx, j0, j1, wy, dyc, k0, k1, wz, u, g, dudt)
    if sublayer:
        _sublayer_with_gradient(f, yp, u, g, dudt)
    if status == ABOVE_TOP:
        # the top value is held constant above the range: no y-derivative there
        for c in range(3):
            g[c, 1] = 0.0
    return status


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy")
def locate_xzt(f, xp, zp, tp):
    """Periodic x and z cells and the looping time interval of a point."""
    i0, i1, wx = _locate_periodic(xp, f.x0, f.dx, f.nx)
    k0, k1, wz = _locate_periodic(zp, f.z0, f.dz, f.nz)
    if f.nt == 1:
        return i0, i1, wx, k0, k1, wz, 0, 0, 0.0
    n0, n1, wt = _locate_periodic(tp, f.t0, f.dt, f.nt)
    return i0, i1, wx, k0, k1, wz, n0, n1, wt


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, fastmath={"contract"})
def sample_point(f, xp, yp, zp, tp, u, g, dudt, with_gradient=True):
    """Velocity u (3,), gradient g[i, j] = ∂u_i/∂x_j (3, 3) and ∂u/∂t (3,) at one point.

    All in wall units. Returns a status code (OK, ABOVE_TOP, BELOW_WALL). With
    with_gradient=False only u is written (cheaper); g and dudt are left as they are."""
    i0, i1, wx, k0, k1, wz, n0, n1, wt = locate_xzt(f, xp, zp, tp)
    if with_gradient:
        return _gradient_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, yp, u, g, dudt)
    return _velocity_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, yp, u)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, fastmath={"contract"})
def sample_column(f, xp, yp, zp, tp, y_top, y_bottom, u, g, dudt, u_top, u_bottom, with_gradient=True):
    """``sample_point`` at (xp, yp, zp) (with gradient unless with_gradient=False: then g
    and dudt are left as they are) plus the velocity alone at the heights y_top and
    y_bottom of the same vertical (x, z and time located once).
    Velocities at points below the wall are zero. Returns the status of the centre."""
    i0, i1, wx, k0, k1, wz, n0, n1, wt = locate_xzt(f, xp, zp, tp)
    if with_gradient:
        status = _gradient_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, yp, u, g, dudt)
    else:
        status = _velocity_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, yp, u)
    _velocity_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, y_top, u_top)
    _velocity_at_height(f, n0, n1, wt, i0, i1, wx, k0, k1, wz, y_bottom, u_bottom)
    return status


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def vorticity_from_gradient(g, w):
    """ω = ∇ × u from g[i, j] = ∂u_i/∂x_j."""
    w[0] = g[2, 1] - g[1, 2]
    w[1] = g[0, 2] - g[2, 0]
    w[2] = g[1, 0] - g[0, 1]


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def sample_many(f, points, tp, u, g, dudt, status):
    """Parallel over points: fill u (N,3), g (N,3,3), dudt (N,3), status (N,)."""
    n = points.shape[0]
    for p in prange(n):
        status[p] = sample_point(
            f, points[p, 0], points[p, 1], points[p, 2], tp, u[p], g[p], dudt[p]
        )


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def sample_velocity_many(f, points, tp, u, status):
    """Parallel over points: velocity only."""
    n = points.shape[0]
    g = np.empty((3, 3))  # not written with_gradient=False
    d = np.empty(3)
    for p in prange(n):
        status[p] = sample_point(f, points[p, 0], points[p, 1], points[p, 2], tp, u[p], g, d, False)
