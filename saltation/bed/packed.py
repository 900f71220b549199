"""Packed bed: one hexagonal layer of fixed spheres (SPEC §4, option 2).

Geometry (particle units, d = 1)
--------------------------------
Bed spheres of diameter d sit with their centres at ``y = −1/2``, so their tops are at
``y = 0``, the bed top of the virtual bed (a grain's centre height ``y`` is measured from
it everywhere in the code). In the (x, z) plane they form a hexagonal (close-packed)
layer, periodic in x and z over the particle domain ``Lx × Lz``: ``nx = round(Lx)``
spheres per row at spacing ``sx = Lx/nx``, ``nr = 2·round(Lz/√3)`` rows at spacing
``sz = Lz/nr`` (an even number, so the half-spacing shift of every other row is
periodic). Spacings differ from the touching values 1 and √3/2 by the rounding only
(< 1/(2 Lx) and < 1/(√3 Lz) relative); slightly stretched rows leave gaps far too small
for a grain to pass (a grain resting in a hollow between three touching bed spheres has
its centre at ``y = −1/2 + √(2/3) = 0.316``).

Contact search: the bed sphere centres are sorted once into a contacts/cells.py grid (cells of at
least one diameter, x and z periodic, one layer in y) by the same counting sort as the
grains; a grain whose centre is below ``y = 1/2`` (only then can it reach a bed sphere)
looks at the 3 × 3 cells around it and measures separations by the minimum image.

Impact (hard sphere with the real normal)
-----------------------------------------
After a grain's move in a step (free flight, then grain–grain contacts) from x₀ to x₁
with end velocity u: if x₁ lies within one diameter of some bed sphere centres c, the
time of entry is found by running the move back along u (linear back-tracking, first
order in Δt; the virtual bed finds its contact on the step's Hermite path and flies the
rest of the step with the fluid forces, flight/spheres._bed_impact): τ = the positive root of |x₁ − τu − c| = 1, the largest over the
spheres overlapped (the first one hit). At the contact point x_h = x₁ − τu the normal is
n = (x_h − c)/|x_h − c|; SPEC §4's impulse (``bed.virtual.rebound``, restitution e, Coulomb
friction f, spin included) gives the new velocity and spin, and the grain moves on for
the remaining τ. That is repeated (at most ``MAX_BOUNCES`` times per step) for a second
sphere hit within τ — a grain deflected off the lee face of one sphere strikes the next.
Finally any residual overlap (a grain that started the step inside a sphere's reach, a
resting grain pressed down by its weight) is removed by moving the grain radially out of
each overlapped sphere in turn (a few Gauss–Seidel sweeps); that never changes the
velocity, and grains never end a step inside a bed sphere.

Jumps and resting grains. A grain touching the bed in consecutive steps is rolling or
resting, not saltating: only an impact after at least one step without bed contact
closes a jump (SPEC §6: a jump runs from one bed impact to the next); while the contact
lasts, the start of the next jump is moved along with the grain. Every impulse counts as
a bed collision. The Basset history restarts at each impulse, as on the virtual bed
(physics/history.py explains why).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..contacts.cells import allocate_cells, build_cells, make_grid, min_image
from ..physics.history import history_mark_impact
from .jumps import BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT, close_jump
from .virtual import NO_IMPACT, rebound

RADIUS = 0.5  # grain radius (d)
BED_CENTRE_Y = -0.5  # bed sphere centres: their tops at y = 0
MAX_BOUNCES = 4  # impulses per grain and step at most
PUSH_SWEEPS = 8  # Gauss–Seidel sweeps that remove residual overlaps

__all__ = ["PackedBed", "make_packed_bed", "bed_from_centres", "hexagonal_pockets", "packed_bed_check_particle", "bed_overlap", "BED_CENTRE_Y"]


class PackedBed(NamedTuple):
    # flat (no nested CellGrid): Numba's parallel loops cannot take nested named tuples
    centres: np.ndarray  # (M, 3) bed sphere centres (d), y = BED_CENTRE_Y
    box: np.ndarray  # (3,) Lx, 1, Lz of the contacts/cells.py grid (periodic in x and z)
    ncell: np.ndarray  # (3,) int64 cells per axis
    size: np.ndarray  # (3,) cell edges (d)
    cell_start: np.ndarray  # (C,) int64
    cell_count: np.ndarray  # (C,) int64
    order: np.ndarray  # (M,) int64 bed sphere ids sorted by cell
    spacing: np.ndarray  # (2,) sx, sz (d)


def hexagonal_layer(lx: float, lz: float) -> tuple[np.ndarray, float, float]:
    """Centres (M, 3) of a periodic hexagonal layer filling lx × lz (d), and (sx, sz)."""
    nx = max(1, int(round(lx)))
    nr = 2 * max(1, int(round(lz / math.sqrt(3.0))))
    sx = lx / nx
    sz = lz / nr
    ix, ir = np.meshgrid(np.arange(nx), np.arange(nr), indexing="ij")
    x = (ix + 0.5 * (ir % 2)) * sx
    z = ir * sz
    centres = np.column_stack([x.ravel(), np.full(x.size, BED_CENTRE_Y), z.ravel()])
    return centres, sx, sz


def make_packed_bed(lx: float, lz: float, cut: float = 1.0) -> PackedBed:
    """The bed layer for a particle domain lx × lz (d), sorted into cells of ≥ ``cut``
    (≥ 1 d: the largest contact distance of a grain centre and a bed sphere centre).

    Raises ValueError for a domain under 3 d in x or z (SPEC §9 keeps domains ≥ 3 d)."""
    if not (lx >= 3.0 and lz >= 3.0):
        raise ValueError(f"packed bed needs a domain of at least 3 d in x and z, got {lx!r} × {lz!r} d")
    centres, sx, sz = hexagonal_layer(lx, lz)
    return bed_from_centres(centres, lx, lz, cut, (sx, sz))


def bed_from_centres(centres, lx: float, lz: float, cut: float = 1.0, spacing=(1.0, 1.0)) -> PackedBed:
    """A bed of fixed spheres of diameter d at the given centres (M, 3) (d; x and z in
    [0, lx) × [0, lz), periodic), sorted into cells of ≥ ``cut``. ``make_packed_bed``
    gives the hexagonal layer; tests build other geometries (rails) with it."""
    centres = np.ascontiguousarray(centres, dtype=np.float64)
    grid = make_grid((lx, 1.0, lz), max(1.0, float(cut)), (True, False, True))
    cell_of, cell_start, cell_count, order = allocate_cells(len(centres), grid)
    build_cells(centres, grid, cell_of, cell_start, cell_count, order)
    return PackedBed(centres, grid.box, grid.n, grid.size, cell_start, cell_count, order,
                     np.array([float(spacing[0]), float(spacing[1])]))


def hexagonal_pockets(lx: float, lz: float) -> np.ndarray:
    """Centres (P, 3) of a grain resting in each hollow of the hexagonal layer of
    ``make_packed_bed(lx, lz)``: the point at distance d from the three bed spheres of a
    triangle (two per bed sphere; y = −1/2 + √(1 − R²) with R the triangle's
    circumradius, √(2/3) − 1/2 = 0.316 d for touching spheres). x and z in the box."""
    _, sx, sz = hexagonal_layer(lx, lz)
    nx, nr = int(round(lx / sx)), int(round(lz / sz))  # the layer's spheres per row and rows
    out = []
    for r in range(nr):
        shift = 0.5 * (r % 2)  # row r's offset; row r + 1 has the other one
        z0, z1 = r * sz, (r + 1) * sz
        for ix in range(nx):
            a = np.array([(ix + shift) * sx, z0])
            b = np.array([(ix + 1 + shift) * sx, z0])
            # the row-(r+1) sphere between a and b, and the row-r sphere between two of row r+1
            above = np.array([(ix + shift + 0.5) * sx, z1])
            above_next = np.array([(ix + shift + 1.5) * sx, z1])
            for tri in ((a, b, above), (b, above, above_next)):
                cx, cz, rad = _circumcircle(*tri)
                out.append((cx % lx, BED_CENTRE_Y + math.sqrt(max(1.0 - rad * rad, 0.0)), cz % lz))
    return np.array(out)


def _circumcircle(p, q, r):
    """Centre (x, z) and radius of the circle through three points in the (x, z) plane."""
    ax, az = p
    bx, bz = q
    cx, cz = r
    dd = 2.0 * (ax * (bz - cz) + bx * (cz - az) + cx * (az - bz))
    ux = ((ax * ax + az * az) * (bz - cz) + (bx * bx + bz * bz) * (cz - az) + (cx * cx + cz * cz) * (az - bz)) / dd
    uz = ((ax * ax + az * az) * (cx - bx) + (bx * bx + bz * bz) * (ax - cx) + (cx * cx + cz * cz) * (bx - ax)) / dd
    return ux, uz, math.hypot(ax - ux, az - uz)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def bed_cell(pb, x, z):
    """(ix, iz) of the bed cell holding the point (x, z) (periodic)."""
    lx, lz = pb.box[0], pb.box[2]
    sx = x - lx * math.floor(x / lx)
    sz = z - lz * math.floor(z / lz)
    return min(int(sx / pb.size[0]), pb.ncell[0] - 1), min(int(sz / pb.size[2]), pb.ncell[2] - 1)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def bed_stencil_cell(pb, ix, iz, s):
    """Cell id of entry s (0..8) of the 3 × 3 cells around (ix, iz); one layer in y."""
    nx, nz = pb.ncell[0], pb.ncell[2]
    return ((ix + s // 3 - 1) % nx) * nz + (iz + s % 3 - 1) % nz


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def bed_offset(pb, k, x, y, z):
    """Minimum-image offset (x, y, z) − centre of bed sphere k."""
    return (min_image(x - pb.centres[k, 0], pb.box[0], 1), y - pb.centres[k, 1],
            min_image(z - pb.centres[k, 2], pb.box[2], 1))


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def end_jump(st, p, length, height, t_hit, bed):
    """A bed impact at t_hit ends grain p's flight (length, height in d): a jump if it
    was one (bed/jumps.py)."""
    close_jump(st, p, st.jump_t0[p], length, height, t_hit, bed[BED_MIN_JUMP_DURATION], bed[BED_MIN_JUMP_HEIGHT])


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _nearest_entry(pb, x, y, z, u, v, w, limit, reach):
    """The overlapped bed sphere the grain at (x, y, z) moving with (u, v, w) entered
    first within the last ``limit`` time: (sphere id or −1, τ ≤ limit). ``reach``: the
    contact distance of centres (1 for a grain of d = 1; ½ + r for a sphere of radius r,
    at most one cell). τ is the positive root of |a − τ u| = reach."""
    ix, iz = bed_cell(pb, x, z)
    best = -1
    best_tau = -1.0
    v2 = u * u + v * v + w * w
    r2 = reach * reach
    for s in range(9):
        c = bed_stencil_cell(pb, ix, iz, s)
        for q in range(pb.cell_start[c], pb.cell_start[c] + pb.cell_count[c]):
            k = pb.order[q]
            ax, ay, az = bed_offset(pb, k, x, y, z)
            a2 = ax * ax + ay * ay + az * az
            if a2 >= r2:
                continue
            if v2 > 0.0:
                av = ax * u + ay * v + az * w
                tau = (av + math.sqrt(max(av * av - v2 * (a2 - r2), 0.0))) / v2
            else:
                tau = limit
            tau = min(max(tau, 0.0), limit)
            if tau > best_tau:
                best_tau = tau
                best = k
    return best, best_tau


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def bed_overlap(pb, x, y, z):
    """Largest overlap (d) of a grain at (x, y, z) with any bed sphere (0 if none)."""
    worst = 0.0
    ix, iz = bed_cell(pb, x, z)
    for s in range(9):
        c = bed_stencil_cell(pb, ix, iz, s)
        for q in range(pb.cell_start[c], pb.cell_start[c] + pb.cell_count[c]):
            k = pb.order[q]
            ax, ay, az = bed_offset(pb, k, x, y, z)
            r = math.sqrt(ax * ax + ay * ay + az * az)
            if 1.0 - r > worst:
                worst = 1.0 - r
    return worst


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _push_out(pb, pos):
    """Move the grain radially out of every bed sphere it overlaps (Gauss–Seidel);
    returns True when it overlapped any."""
    touched = False
    for _sweep in range(PUSH_SWEEPS):
        moved = False
        ix, iz = bed_cell(pb, pos[0], pos[2])
        for s in range(9):
            c = bed_stencil_cell(pb, ix, iz, s)
            for q in range(pb.cell_start[c], pb.cell_start[c] + pb.cell_count[c]):
                k = pb.order[q]
                ax, ay, az = bed_offset(pb, k, pos[0], pos[1], pos[2])
                r2 = ax * ax + ay * ay + az * az
                if r2 >= 1.0:
                    continue
                r = math.sqrt(r2)
                if r > 0.0:
                    f = (1.0 - r) / r * (1.0 + 1e-12)
                    pos[0] += f * ax
                    pos[1] += f * ay
                    pos[2] += f * az
                else:
                    pos[1] = pb.centres[k, 1] + 1.0
                moved = True
                touched = True
        if not moved:
            break
    return touched


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def packed_bed_check_particle(st, w, p, t, dt, step, coef_bed, pb, last_contact):
    """Impacts of grain p on the packed bed after its move in step ``step`` (t → t + dt);
    module docstring. coef_bed = (e, f, ...). last_contact (N,) int64: the last step in
    which the grain touched the bed. Returns the number of impulses applied."""
    pos = st.pos[p]
    vel = st.vel[p]
    spin = st.spin[p]
    if pos[1] >= RADIUS:  # centres of bed spheres at −1/2: out of reach
        if pos[1] > st.jump_ymax[p]:
            st.jump_ymax[p] = pos[1]
        return 0
    e = coef_bed[0]
    f = coef_bed[1]
    n = w.normal[p]
    remaining = dt
    hits = 0
    for _it in range(MAX_BOUNCES):
        k, tau = _nearest_entry(pb, pos[0], pos[1], pos[2], vel[0], vel[1], vel[2], remaining, 1.0)
        if k < 0:
            break
        # contact point: back along the end-of-step velocity (linear; module docstring)
        xh = pos[0] - tau * vel[0]
        yh = pos[1] - tau * vel[1]
        zh = pos[2] - tau * vel[2]
        ax, ay, az = bed_offset(pb, k, xh, yh, zh)
        r = math.sqrt(ax * ax + ay * ay + az * az)
        if r == 0.0:
            ax, ay, az, r = 0.0, 1.0, 0.0, 1.0
        n[0] = ax / r
        n[1] = ay / r
        n[2] = az / r
        if r < 1.0:  # entered before the step began (clipped τ): onto the surface, radially
            s = 1.0 / r - 1.0
            xh += ax * s
            yh += ay * s
            zh += az * s
        code = rebound(vel, spin, n, e, f, RADIUS)
        if code == NO_IMPACT:
            # touching but separating: nothing to do here (the push-out handles overlap)
            pos[0] = xh + tau * vel[0]
            pos[1] = yh + tau * vel[1]
            pos[2] = zh + tau * vel[2]
            break
        hits += 1
        st.impacts[p] += 1
        t_hit = t + dt - tau
        if hits == 1:
            if last_contact[p] < step - 1:
                # airborne since an earlier step: a jump ends here (SPEC §6)
                end_jump(st, p, xh - st.jump_x0[p], st.jump_ymax[p] - RADIUS, t_hit, coef_bed)
            st.jump_t0[p] = t_hit
            st.jump_x0[p] = xh
        history_mark_impact(st.hist_meta[p])  # the next step takes the slip step (physics/history.py)
        pos[0] = xh + tau * vel[0]
        pos[1] = yh + tau * vel[1]
        pos[2] = zh + tau * vel[2]
        remaining = tau
        if remaining <= 0.0:
            break
    touched = _push_out(pb, pos)
    if hits > 0 or touched:
        last_contact[p] = step
        st.fresh[p] = 0  # moved: the fluid must be sampled again
        if hits == 0:
            # resting or rolling contact without an impulse: the next jump starts here
            st.jump_t0[p] = t + dt
            st.jump_x0[p] = pos[0]
        st.jump_ymax[p] = pos[1]
    elif pos[1] > st.jump_ymax[p]:
        st.jump_ymax[p] = pos[1]
    return hits
