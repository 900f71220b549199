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
(x₀, v₀, q₀, Ω₀) to (x₁, v₁, q₁, Ω₁):
1. every component whose centre ends within reach (½ + d_k/2) of a bed sphere is followed
   on its path in the step, the cubic Hermite through its centre x + R r_k and velocity
   u_k = v + Ω × R r_k at both ends (flight/path.py), to where it first came within reach
   (``bed.packed.path_entry``); the component that did so first is the contact;
2. the grain is put where it was then, as on the virtual bed (flight.composites._bed_impact):
   its centre's position and velocity on its Hermite path, Ω linear between the ends, q
   turned back from q₁ by Ω₁ over the rest of the step, then moved along the normal so that
   the component just touches; the normal is n = (x_k − c)/|x_k − c|, the impulse acts at
   r_c = R r_k − (d_k/2) n, and the rest of the step is flown with the fluid forces
   (flight.composites.flight_remainder, the slip steps dated at the impact); repeated on
   the rest of the step's path for a second contact, at most ``MAX_BOUNCES`` times per step.
   (Before: the contact by running the grain back linearly along its end velocities, the
   rest of the step in a straight line without forces: first order in Δt; 500 grains of
   the natural mixture, Δt = 0.02 against 0.0025: L −5.3 ± 1.3 %, 11 % more jumps.)
3. residual overlaps (a grain that started the step in reach, a resting grain pressed
   down) are removed by translating the grain along the normal of each overlapped
   component–bed pair in turn (a few Gauss–Seidel sweeps): velocities unchanged, and no
   component ends a step inside a bed sphere.

Jumps as on the packed bed for spheres: only an impact after at least one step without
bed contact ends a jump; a resting or rolling grain moves its next jump's start along.
The jump height is the highest elevation of the grain's lowest point above the bed top
(y = 0), as on the virtual bed, sampled inside the steps too
(flight.composites.highest_on_path). Every impulse gives each component's Basset history
a slip step dated at the impact (physics/history.py). Known gap: a contact that begins and ends within one step
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
    _set_state,
    _turned,
    _world_inverse_inertia,
    chunk_range,
    component_at,
    flight_remainder,
    highest_on_path,
    state_row,
)
from ..flight.path import hermite_point
from ..grains.refs import as_tuple
from ..physics.history import history_mark_impact_at
from .packed import BED_CENTRE_Y, bed_cell, bed_offset, bed_stencil_cell, end_jump, path_entry

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
def _first_entry(st, w, p, pb, h):
    """(component, bed sphere, s, the sphere centre's image) of the contact that grain p's
    segment (from the row ``w.x0[p]`` to the row ``w.x[p]``, over h) entered first;
    bed sphere −1: none (module docstring, 1)."""
    best_k = -1
    best_j = -1
    best_s = 2.0
    c0 = c1 = c2 = 0.0
    for k in range(st.cstart[p], st.cstart[p + 1]):
        reach = BED_RADIUS + 0.5 * st.d_comp[k]
        x1, u1 = component_at(st, k, w.x[p])
        if x1[1] - BED_CENTRE_Y >= reach:
            continue
        x0, u0 = component_at(st, k, w.x0[p])
        j, s, b0, b1, b2 = path_entry(pb, x0, x1, u0, u1, h, reach)
        if j >= 0 and s < best_s:
            best_s = s
            best_j = j
            best_k = k
            c0, c1, c2 = b0, b1, b2
    return best_k, best_j, best_s, c0, c1, c2


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
def packed_bed_check_cluster(f, coef, hc, st, w, p, t, dt, step, bed, pb, last_contact):
    """Impacts of composite p on the packed bed after its move in step ``step`` (t → t + dt)
    from ``w.x0[p]``; module docstring. f, coef, hc: the flow, force and history
    coefficients of the free flight (the rest of the step after an impact is flown with
    them). bed = (e, f, ...). last_contact (N,) int64: the last step in which the grain
    touched the bed. Returns the number of impulses applied."""
    q = st.quat[p]
    low, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], q[0], q[1], q[2], q[3])
    if low >= 0.0:  # lowest point above the bed spheres' tops: out of reach
        st.jump_ymax[p] = max(st.jump_ymax[p], low, highest_on_path(st, w, p, dt))
        return 0
    e = bed[0]
    fr = bed[1]
    iw = w.aug[p, 0:3, 0:3]
    x = w.x[p]
    t_seg = t  # the segment flown last: from the row w.x0[p] at t_seg to the step's end
    hits = 0
    for _it in range(MAX_BOUNCES):
        h = t + dt - t_seg
        state_row(st, p, x)  # the segment's end
        k, j, s, c0, c1, c2 = _first_entry(st, w, p, pb, h)
        if j < 0:
            break
        # the grain where the contact began (module docstring, 2); x keeps the end
        x0 = w.x0[p]
        for i in range(3):
            st.pos[p, i], st.vel[p, i] = hermite_point(x0[i], x[i], x0[3 + i], x[3 + i], s, h)
            st.omega[p, i] = (1.0 - s) * x0[10 + i] + s * x[10 + i]
        back = (1.0 - s) * h
        q0, q1, q2, q3 = _turned(x[6], x[7], x[8], x[9], x[10], x[11], x[12], -back)
        nq = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        st.quat[p, 0], st.quat[p, 1], st.quat[p, 2], st.quat[p, 3] = q0 / nq, q1 / nq, q2 / nq, q3 / nq
        _quat_to_matrix(st.quat[p, 0], st.quat[p, 1], st.quat[p, 2], st.quat[p, 3], w.rot[p])
        rx, ry, rz = _component_world(st, w, p, k)
        reach = BED_RADIUS + 0.5 * st.d_comp[k]
        ax, ay, az = st.pos[p, 0] + rx - c0, st.pos[p, 1] + ry - c1, st.pos[p, 2] + rz - c2
        r = math.sqrt(ax * ax + ay * ay + az * az)
        if r == 0.0:
            ax, ay, az, r = 0.0, 1.0, 0.0, 1.0
        n0, n1, n2 = ax / r, ay / r, az / r
        gap = reach - r  # onto the surface (the grain's and the component's paths differ at O(h³))
        st.pos[p, 0] += gap * n0
        st.pos[p, 1] += gap * n1
        st.pos[p, 2] += gap * n2
        _world_inverse_inertia(st, w, p, iw)
        rad = 0.5 * st.d_comp[k]
        v0, v1, v2 = st.vel[p, 0], st.vel[p, 1], st.vel[p, 2]
        w0, w1, w2 = st.omega[p, 0], st.omega[p, 1], st.omega[p, 2]
        if _impulse(st, p, rx - rad * n0, ry - rad * n1, rz - rad * n2, n0, n1, n2, e, fr, iw) == 0:
            _set_state(st, p, x)  # touching but separating: the segment's end stands
            break
        hits += 1
        st.impacts[p] += 1
        t_hit = t_seg + s * h
        if hits == 1:
            if last_contact[p] < step - 1:
                # airborne since an earlier step: a jump ends here (SPEC §6)
                end_jump(st, p, st.pos[p, 0] - st.jump_x0[p], st.jump_ymax[p], t_hit, bed)
            st.jump_t0[p] = t_hit
            st.jump_x0[p] = st.pos[p, 0]
        for kk in range(st.cstart[p], st.cstart[p + 1]):
            # the slip steps dated at the impact (physics/history.py)
            history_mark_impact_at(st.hist_meta[kk], (t + dt - t_hit) / dt)
        if s < 1.0:
            flight_remainder(f, coef, hc, st, w, p, t_hit, back, st.vel[p, 0] - v0, st.vel[p, 1] - v1,
                             st.vel[p, 2] - v2, st.omega[p, 0] - w0, st.omega[p, 1] - w1, st.omega[p, 2] - w2)
            if st.status[p] != OK:
                return hits
        t_seg = t_hit
        if s >= 1.0:
            break
    q = st.quat[p]
    _quat_to_matrix(q[0], q[1], q[2], q[3], w.rot[p])
    touched = _push_out(st, w, p, pb)
    low, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], q[0], q[1], q[2], q[3])
    if hits > 0 or touched:
        last_contact[p] = step
        st.fresh[p] = 0  # moved or new velocity: the fluid must be sampled again
        if hits == 0:
            # resting or rolling contact without an impulse: the next jump starts here
            st.jump_t0[p] = t + dt
            st.jump_x0[p] = st.pos[p, 0]
        st.jump_ymax[p] = max(low, 0.0)
    else:
        st.jump_ymax[p] = max(st.jump_ymax[p], low, highest_on_path(st, w, p, dt))
    return hits


@njit(cache=True, no_cfunc_wrapper=True, parallel=True, error_model="numpy")
def packed_bed_pass(f, coef, hc, st, w, t, dt, step, bed, pb, last_contact, skip):
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
                hits += packed_bed_check_cluster(f, coef, hc, sv, wv, p, t, dt, step, bed, pb, last_contact)
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
