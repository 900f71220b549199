"""Bonded-sphere grains on the packed bed (SPEC §4 option 2; seed 000 §2.4).

The bed is bed/packed.py's hexagonal layer of fixed spheres of diameter Dn (the length
unit of composite runs), centres at y = −½, tops at y = 0, found through the same cells
(``make_packed_bed(lx, lz, cut)`` with cells ≥ the largest centre-to-centre contact
distance ½ + d_k/2 of a component). Each component sphere k of a grain meets the bed
spheres with its own radius; the impulse acts on the rigid body at the real contact
point along the real normal, with the rigid-body collision matrix of flight/composites.py
(``flight.composites._impulse``: Newton restitution e and Coulomb friction f on the contact-point
velocity, sticking and sliding branches — SPEC §4's rebound for a sphere).

After a grain's move in a step (free flight, then grain–grain contacts) from its start
to (x₁, q₁) with end velocities (v, Ω):
1. every component whose centre is within reach of a bed sphere is run back along its
   own velocity u_k = v + Ω × r_k (linear, as for spheres) to the time of entry τ (the
   positive root of |a − τ u_k| = ½ + d_k/2); the component entered first (largest τ)
   is the contact;
2. the whole grain is moved back by τ (x − τ v, q turned by −τ Ω), the normal is
   n = (x_k − c)/|x_k − c| there, the impulse is applied at r_c = R r_k − (d_k/2) n,
   and the grain moves on for τ with its new (v, Ω); repeated for a second contact in
   the remaining τ, at most ``MAX_BOUNCES`` times per step;
3. residual overlaps (a grain that started the step in reach, a resting grain pressed
   down) are removed by translating the grain along the normal of each overlapped
   component–bed pair in turn (a few Gauss–Seidel sweeps): velocities unchanged, and no
   component ends a step inside a bed sphere.

Jumps as on the packed bed for spheres: only an impact after at least one step without
bed contact ends a jump; a resting or rolling grain moves its next jump's start along.
The jump height is the highest elevation of the grain's lowest point above the bed top
(y = 0), as on the virtual bed. Every impulse restarts the Basset history of all
components (physics/history.py). Known gap: a contact that begins and ends within one step
without the end position overlapping a bed sphere is not seen (grains move ≲ 0.2 Dn
per step at the runs' time steps, so only grazing contacts can pass).
"""
from __future__ import annotations

import math

from numba import njit, prange

from ..contacts.cells import min_image
from ..flight.composites import (
    CHUNK,
    OK,
    ClusterState,
    ClusterStateRef,
    ClusterWork,
    ClusterWorkRef,
    _impulse,
    _lowest,
    _quat_to_matrix,
    _rotate_quat,
    _world_inverse_inertia,
    chunk_range,
)
from ..grains.refs import as_tuple
from ..physics.history import history_mark_impact
from .packed import BED_CENTRE_Y, _nearest_entry, bed_cell, bed_offset, bed_stencil_cell, end_jump

MAX_BOUNCES = 4  # impulses per grain and step at most
PUSH_SWEEPS = 8  # Gauss–Seidel sweeps that remove residual overlaps
BED_RADIUS = 0.5  # bed spheres have the nominal diameter


def cut_for(st) -> float:
    """Cell size of the bed grid: the largest component–bed contact distance (≥ 1)."""
    return max(1.0, BED_RADIUS + 0.5 * float(st.d_comp.max()))


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _component_world(st, w, p, k):
    rot = w.rot[p]
    rx = rot[0, 0] * st.r_body[k, 0] + rot[0, 1] * st.r_body[k, 1] + rot[0, 2] * st.r_body[k, 2]
    ry = rot[1, 0] * st.r_body[k, 0] + rot[1, 1] * st.r_body[k, 1] + rot[1, 2] * st.r_body[k, 2]
    rz = rot[2, 0] * st.r_body[k, 0] + rot[2, 1] * st.r_body[k, 1] + rot[2, 2] * st.r_body[k, 2]
    return rx, ry, rz


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _first_entry(st, w, p, pb, limit):
    """(component, bed sphere, τ) of the contact entered first within ``limit`` for grain
    p at its current state (w.rot[p] must hold its orientation); bed sphere −1: none."""
    v = st.vel[p]
    o = st.omega[p]
    best_k = -1
    best_j = -1
    best_tau = -1.0
    for k in range(st.cstart[p], st.cstart[p + 1]):
        rx, ry, rz = _component_world(st, w, p, k)
        reach = BED_RADIUS + 0.5 * st.d_comp[k]
        y = st.pos[p, 1] + ry
        if y - BED_CENTRE_Y >= reach:
            continue
        j, tau = _nearest_entry(pb, st.pos[p, 0] + rx, y, st.pos[p, 2] + rz,
                                v[0] + o[1] * rz - o[2] * ry, v[1] + o[2] * rx - o[0] * rz,
                                v[2] + o[0] * ry - o[1] * rx, limit, reach)
        if j >= 0 and tau > best_tau:
            best_tau = tau
            best_j = j
            best_k = k
    return best_k, best_j, best_tau


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _move(st, w, p, h):
    """Rigid motion of grain p over time h (negative: back) with its current (v, Ω)."""
    x = w.x[p]
    for i in range(4):
        x[6 + i] = st.quat[p, i]
    _rotate_quat(x, st.omega[p], h)
    nq = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
    for i in range(4):
        st.quat[p, i] = x[6 + i] / nq
    for i in range(3):
        st.pos[p, i] += h * st.vel[p, i]
    q = st.quat[p]
    _quat_to_matrix(q[0], q[1], q[2], q[3], w.rot[p])


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _push_out(st, w, p, pb):
    """Translate grain p out of every bed sphere a component overlaps; True if any did."""
    touched = False
    for _sweep in range(PUSH_SWEEPS):
        moved = False
        for k in range(st.cstart[p], st.cstart[p + 1]):
            rx, ry, rz = _component_world(st, w, p, k)
            reach = BED_RADIUS + 0.5 * st.d_comp[k]
            cx = st.pos[p, 0] + rx
            cy = st.pos[p, 1] + ry
            cz = st.pos[p, 2] + rz
            if cy - BED_CENTRE_Y >= reach:
                continue
            ix, iz = bed_cell(pb, cx, cz)
            for s in range(9):
                c = bed_stencil_cell(pb, ix, iz, s)
                for q in range(pb.cell_start[c], pb.cell_start[c] + pb.cell_count[c]):
                    ax, ay, az = bed_offset(pb, pb.order[q], cx, cy, cz)
                    r2 = ax * ax + ay * ay + az * az
                    if r2 >= reach * reach:
                        continue
                    r = math.sqrt(r2)
                    if r > 0.0:
                        f = (reach - r) / r * (1.0 + 1e-12)
                        dx, dy, dz = f * ax, f * ay, f * az
                    else:
                        dx, dy, dz = 0.0, reach, 0.0
                    st.pos[p, 0] += dx
                    st.pos[p, 1] += dy
                    st.pos[p, 2] += dz
                    cx += dx
                    cy += dy
                    cz += dz
                    moved = True
                    touched = True
        if not moved:
            break
    return touched


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def packed_bed_check_cluster(st, w, p, t, dt, step, bed, pb, last_contact):
    """Impacts of composite p on the packed bed after its move in step ``step``
    (t → t + dt); module docstring. bed = (e, f, ...). last_contact (N,) int64: the last
    step in which the grain touched the bed. Returns the number of impulses applied."""
    q = st.quat[p]
    low, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], q[0], q[1], q[2], q[3])
    if low >= 0.0:  # lowest point above the bed spheres' tops: out of reach
        if low > st.jump_ymax[p]:
            st.jump_ymax[p] = low
        return 0
    e = bed[0]
    fr = bed[1]
    iw = w.aug[p, 0:3, 0:3]
    remaining = dt
    hits = 0
    for _it in range(MAX_BOUNCES):
        k, j, tau = _first_entry(st, w, p, pb, remaining)
        if j < 0:
            break
        _move(st, w, p, -tau)  # back to the contact
        rx, ry, rz = _component_world(st, w, p, k)
        reach = BED_RADIUS + 0.5 * st.d_comp[k]
        ax, ay, az = bed_offset(pb, j, st.pos[p, 0] + rx, st.pos[p, 1] + ry, st.pos[p, 2] + rz)
        r = math.sqrt(ax * ax + ay * ay + az * az)
        if r == 0.0:
            ax, ay, az, r = 0.0, 1.0, 0.0, 1.0
        n0, n1, n2 = ax / r, ay / r, az / r
        if r < reach:  # entered before the step began (clipped τ): onto the surface
            s = reach - r
            st.pos[p, 0] += s * n0
            st.pos[p, 1] += s * n1
            st.pos[p, 2] += s * n2
        _world_inverse_inertia(st, w, p, iw)
        rad = 0.5 * st.d_comp[k]
        if _impulse(st, p, rx - rad * n0, ry - rad * n1, rz - rad * n2, n0, n1, n2, e, fr, iw) == 0:
            _move(st, w, p, tau)  # touching but separating: on to the end of the step
            break
        hits += 1
        st.impacts[p] += 1
        t_hit = t + dt - tau
        if hits == 1:
            if last_contact[p] < step - 1:
                # airborne since an earlier step: a jump ends here (SPEC §6)
                end_jump(st, p, st.pos[p, 0] - st.jump_x0[p], st.jump_ymax[p], t_hit, bed)
            st.jump_t0[p] = t_hit
            st.jump_x0[p] = st.pos[p, 0]
        for kk in range(st.cstart[p], st.cstart[p + 1]):
            history_mark_impact(st.hist_meta[kk])  # the next step takes the slip step (physics/history.py)
        _move(st, w, p, tau)
        remaining = tau
        if remaining <= 0.0:
            break
    touched = _push_out(st, w, p, pb)
    q = st.quat[p]
    low, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], q[0], q[1], q[2], q[3])
    if hits > 0 or touched:
        last_contact[p] = step
        st.fresh[p] = 0  # moved or new velocity: the fluid must be sampled again
        if hits == 0:
            # resting or rolling contact without an impulse: the next jump starts here
            st.jump_t0[p] = t + dt
            st.jump_x0[p] = st.pos[p, 0]
        st.jump_ymax[p] = max(low, 0.0)
    elif low > st.jump_ymax[p]:
        st.jump_ymax[p] = low
    return hits


@njit(cache=True, no_cfunc_wrapper=True, parallel=True, error_model="numpy")
def packed_bed_pass(st, w, t, dt, step, bed, pb, last_contact, skip):
    """packed_bed_check_cluster for every grain (in parallel) but those with skip[p] ≠ 0
    (the contact phase's sub-stepped grains, which had their bed contacts there as soft
    contacts: contacts/composites.py); returns the impulses."""
    n = st.pos.shape[0]
    sr, wr = ClusterStateRef(*st), ClusterWorkRef(*w)  # one pointer each into the loop (grains/refs.py)
    total = 0
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, wv = as_tuple(sr, ClusterState), as_tuple(wr, ClusterWork)
        hits = 0
        for p in range(*chunk_range(c, n)):
            if sv.status[p] == OK and skip[p] == 0:
                hits += packed_bed_check_cluster(sv, wv, p, t, dt, step, bed, pb, last_contact)
        total += hits
    return total


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy")
def min_bed_gap(st, pb):
    """Smallest (distance − contact distance) of any component to any bed sphere (Dn);
    negative: an overlap. For tests and checks."""
    n = st.pos.shape[0]
    lx, lz = pb.box[0], pb.box[2]
    out = 1e300
    for p in range(n):
        q = st.quat[p]
        m00 = 1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3])
        m01 = 2.0 * (q[1] * q[2] - q[0] * q[3])
        m02 = 2.0 * (q[1] * q[3] + q[0] * q[2])
        m10 = 2.0 * (q[1] * q[2] + q[0] * q[3])
        m11 = 1.0 - 2.0 * (q[1] * q[1] + q[3] * q[3])
        m12 = 2.0 * (q[2] * q[3] - q[0] * q[1])
        m20 = 2.0 * (q[1] * q[3] - q[0] * q[2])
        m21 = 2.0 * (q[2] * q[3] + q[0] * q[1])
        m22 = 1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2])
        for k in range(st.cstart[p], st.cstart[p + 1]):
            b = st.r_body[k]
            cx = st.pos[p, 0] + m00 * b[0] + m01 * b[1] + m02 * b[2]
            cy = st.pos[p, 1] + m10 * b[0] + m11 * b[1] + m12 * b[2]
            cz = st.pos[p, 2] + m20 * b[0] + m21 * b[1] + m22 * b[2]
            reach = BED_RADIUS + 0.5 * st.d_comp[k]
            for j in range(pb.centres.shape[0]):
                ax = min_image(cx - pb.centres[j, 0], lx, 1)
                ay = cy - pb.centres[j, 1]
                az = min_image(cz - pb.centres[j, 2], lz, 1)
                g = math.sqrt(ax * ax + ay * ay + az * az) - reach
                if g < out:
                    out = g
    return out
