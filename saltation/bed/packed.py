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
After a grain's move in a step (free flight, then grain–grain contacts) from x₀ to x₁:
if x₁ lies within one diameter of some bed sphere centres c, the grain entered the first
of them where the step's path, the cubic Hermite through (x₀, u₀) and (x₁, u₁)
(flight/path.py), first comes within one diameter of its centre (``path_entry``; s = 0
for a sphere it started inside). There, with the path's position and velocity and the
spin linear between the ends, the normal is n = (x_h − c)/|x_h − c|; SPEC §4's impulse
(``bed.virtual.rebound``, restitution e, Coulomb friction f, spin included) gives the new
velocity and spin, and the grain flies on for the rest of the step with its fluid forces
(flight.spheres.flight_remainder, one RK4 step; the Basset slip step dated at the
impact), as on the virtual bed. That is repeated on the rest of the step's path (at most
``MAX_BOUNCES`` times per step) for a second sphere hit — a grain deflected off the lee
face of one sphere strikes the next. (Before: the contact by running the move back along
the end-of-step velocity, that velocity rebounded, the rest of the step in a straight
line without forces and the slip step dated at the step's end: first order in Δt, the
mean jump height +6.6 % at Δt = 0.02 d/u* against 0.0025, 3 000 grains; now +0.9 and
+1.1 % with two seeds: docs/studies/stiffness_dt.md.)
Finally any residual overlap (a grain that started the step inside a sphere's reach, a
resting grain pressed down by its weight) is removed by moving the grain radially out of
each overlapped sphere in turn (a few Gauss–Seidel sweeps); that never changes the
velocity, and grains never end a step inside a bed sphere.

Jumps and resting grains. A grain touching the bed in consecutive steps is rolling or
resting, not saltating: only an impact after at least one step without bed contact
closes a jump (SPEC §6: a jump runs from one bed impact to the next); while the contact
lasts, the start of the next jump is moved along with the grain. Every impulse counts as
a bed collision. Each impulse is a slip step in the Basset history dated at the impact,
as on the virtual bed (physics/history.py, ``forces.basset_impacts``).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..contacts.cells import allocate_cells, build_cells, make_grid, min_image
from ..flight.path import SPHERE, first_inside, hermite_point
from ..flight.spheres import flight_remainder
from ..grains.status import OK
from ..physics.history import history_mark_impact_at
from .jumps import BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT, close_jump
from .virtual import NO_IMPACT, rebound

RADIUS = 0.5  # grain radius (d)
BED_CENTRE_Y = -0.5  # bed sphere centres: their tops at y = 0
MAX_BOUNCES = 4  # impulses per grain and step at most
PUSH_SWEEPS = 8  # Gauss–Seidel sweeps that remove residual overlaps

__all__ = ["PackedBed", "make_packed_bed", "bed_from_centres", "hexagonal_pockets", "packed_bed_check_particle", "path_entry", "bed_overlap", "BED_CENTRE_Y"]


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
def path_entry(pb, x0, x1, u0, u1, h, reach):
    """The bed sphere a point's path entered first in a segment of length h (the cubic
    Hermite through (x0, u0) at its start and (x1, u1) at its end, 3-tuples), among those
    whose centres are within ``reach`` of x1 (1 for a grain of d = 1; ½ + r for a component
    sphere of radius r, at most one cell): (sphere id or −1, s in [0, 1] the fraction of
    the segment at the entry, the centre's image nearest x1). s = 0 for a sphere the path
    started inside."""
    ix, iz = bed_cell(pb, x1[0], x1[2])
    best = -1
    best_s = 2.0
    c0 = c1 = c2 = 0.0
    r2 = reach * reach
    for q9 in range(9):
        cell = bed_stencil_cell(pb, ix, iz, q9)
        for q in range(pb.cell_start[cell], pb.cell_start[cell] + pb.cell_count[cell]):
            k = pb.order[q]
            ax, ay, az = bed_offset(pb, k, x1[0], x1[1], x1[2])
            if ax * ax + ay * ay + az * az >= r2:
                continue
            centre = (x1[0] - ax, x1[1] - ay, x1[2] - az)  # the image the path is near
            b0, b1, b2 = x0[0] - centre[0], x0[1] - centre[1], x0[2] - centre[2]
            if b0 * b0 + b1 * b1 + b2 * b2 < r2:
                s = 0.0
            else:
                s = first_inside(SPHERE, x0, x1, u0, u1, h, centre, reach)
            if s < best_s:
                best_s = s
                best = k
                c0, c1, c2 = centre
    return best, best_s, c0, c1, c2


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def packed_bed_check_particle(f, coef, hc, st, w, p, t, dt, step, coef_bed, pb, last_contact):
    """Impacts of grain p on the packed bed after its move in step ``step`` (t → t + dt)
    from ``w.x0[p]`` to its state; module docstring. f, coef, hc: the flow, force
    coefficients and history coefficients of the free flight (the rest of the step after an
    impact is flown with them: flight.spheres.flight_remainder). coef_bed = (e, f, ...).
    last_contact (N,) int64: the last step in which the grain touched the bed. Returns the
    number of impulses applied."""
    pos = st.pos[p]
    vel = st.vel[p]
    spin = st.spin[p]
    if pos[1] >= RADIUS:  # centres of bed spheres at −1/2: out of reach
        if pos[1] > st.jump_ymax[p]:
            st.jump_ymax[p] = pos[1]
        return 0
    e = coef_bed[0]
    fr = coef_bed[1]
    n = w.normal[p]
    t_seg = t  # the segment flown last: from w.x0[p] at t_seg to the step's end
    hits = 0
    for _it in range(MAX_BOUNCES):
        h = t + dt - t_seg
        x0 = w.x0[p]
        k, s, c0, c1, c2 = path_entry(pb, (x0[0], x0[1], x0[2]), (pos[0], pos[1], pos[2]), (x0[3], x0[4], x0[5]),
                                      (vel[0], vel[1], vel[2]), h, 1.0)
        if k < 0:
            break
        # the state at the entry, on the segment's path (second order; module docstring)
        end = (pos[0], pos[1], pos[2], vel[0], vel[1], vel[2], spin[0], spin[1], spin[2])
        for i in range(3):
            pos[i], vel[i] = hermite_point(x0[i], end[i], x0[3 + i], end[3 + i], s, h)
            spin[i] = (1.0 - s) * x0[6 + i] + s * end[6 + i]
        ax, ay, az = pos[0] - c0, pos[1] - c1, pos[2] - c2
        r = math.sqrt(ax * ax + ay * ay + az * az)
        if r == 0.0:
            ax, ay, az, r = 0.0, 1.0, 0.0, 1.0
        n[0] = ax / r
        n[1] = ay / r
        n[2] = az / r
        if r < 1.0:  # the segment started inside (s = 0): onto the surface, radially
            pos[0] = c0 + n[0]
            pos[1] = c1 + n[1]
            pos[2] = c2 + n[2]
        du0, du1, du2 = vel[0], vel[1], vel[2]
        code = rebound(vel, spin, n, e, fr, RADIUS)
        if code == NO_IMPACT:
            # touching but separating: the segment's end stands (the push-out removes overlap)
            for i in range(3):
                pos[i], vel[i], spin[i] = end[i], end[3 + i], end[6 + i]
            break
        hits += 1
        st.impacts[p] += 1
        t_hit = t_seg + s * h
        if hits == 1:
            if last_contact[p] < step - 1:
                # airborne since an earlier step: a jump ends here (SPEC §6)
                end_jump(st, p, pos[0] - st.jump_x0[p], st.jump_ymax[p] - RADIUS, t_hit, coef_bed)
            st.jump_t0[p] = t_hit
            st.jump_x0[p] = pos[0]
        # the slip step dated at the impact; the rest of the step flown with the fluid forces
        history_mark_impact_at(st.hist_meta[p], (t + dt - t_hit) / dt)
        if s < 1.0:
            flight_remainder(f, coef, hc, st, w, p, t_hit, (1.0 - s) * h, vel[0] - du0, vel[1] - du1, vel[2] - du2)
            if st.status[p] != OK:
                return hits
        t_seg = t_hit
        if s >= 1.0:
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
