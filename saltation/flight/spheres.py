"""Classic RK4 for saltating grains, parallel over particles (SPEC §2, paper §2.2).

One step of one grain:

1. RK4 on (x, u_p, ϖ_p) with dx/dt = u_p, du_p/dt = Σ forces − P·I_n, dϖ/dt = spin law;
   the Basset integral I_n is held over the four stages (SPEC §2: the history term is
   not part of the RK4 right-hand side);
2. sample the fluid at the new position and time (kept as the next step's stage 1),
   then close the history term implicitly by the trapezoidal rule and push the new slip
   (``history.history_end_step``: second order and stable for any P√Δt);
3. if the grain's centre crossed y = 1/2 (its bottom reached the bed top) while
   descending: locate the contact on the step's cubic Hermite path (flight/path.py),
   rebound on a virtual bed grain (bed/virtual.py), fly on with the fluid forces for the
   rest of the step (one RK4 step), close the jump and open the next one; the Basset
   history takes the slip step dated at the impact (physics/history.py). Second order
   in Δt (``_bed_impact``).

State is a structure of arrays (``GrainState``); per-particle scratch space is
preallocated (``Workspace``) so the hot loop allocates nothing. Random contact angles
come from a counter-based generator keyed on (seed, particle, impact count): a run is
bit-for-bit reproducible for a given seed and thread count.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..bed.jumps import BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT, close_jump
from ..bed.virtual import bed_rebound, virtual_bed_normal
from ..grains.refs import struct_ref
from ..grains.status import JUMP_FIELDS, NOT_FINITE, OK
from ..physics import history
from ..physics.fluid import fluid_at_grain, gather_at, grain_velocity, locate_grain, same_cell
from ..physics.forces import (
    BASSET_PREFACTOR,
    ON_ADDED_MASS,
    ON_BASSET,
    ON_FLUID_ACC,
    ON_LIFT,
    ON_MAGNUS,
    ON_SPIN,
    R_SUBMERGED,
    RE_STAR,
    fluid_acceleration,
    weight_and_drag,
)
from ..physics.history import (
    META_COUNT,
    add_basset_acceleration,
    history_end_step,
    history_mark_impact_at,
    history_start_step,
)
from ..physics.rng import uniform2
from ..physics.spin import spin_rate
from .path import first_below, hermite_point

RADIUS = 0.5  # grain radius in particle units



class GrainState(NamedTuple):
    pos: np.ndarray  # (N,3) x, z unwrapped; y of the centre above the bed top (d)
    vel: np.ndarray  # (N,3) u*
    spin: np.ndarray  # (N,3) u*/d
    jump_t0: np.ndarray  # (N,) start time of the current jump (d/u*)
    jump_x0: np.ndarray  # (N,) streamwise position where it started
    jump_ymax: np.ndarray  # (N,) highest centre elevation so far in this jump
    jump_count: np.ndarray  # (N,) int64 completed jumps
    impacts: np.ndarray  # (N,) int64 bed impacts (random-number counter)
    jump_buf: np.ndarray  # (N, cap, 4) completed jumps not yet collected
    jump_buf_n: np.ndarray  # (N,) int64
    status: np.ndarray  # (N,) int64
    above_top: np.ndarray  # (N,) int64 steps spent above the stored flow
    hist_slip: np.ndarray  # (N, N_w+2, 3) Basset window of slip samples (physics/history.py)
    hist_meta: np.ndarray  # (N, 2) int64 ring-buffer head, samples since reset (0: reset due)
    hist_tail: np.ndarray  # (N, 10, 3) exponential tail modes
    hist_i: np.ndarray  # (N, 3) history integral I_n carried between steps
    fresh: np.ndarray  # (N,) int64: 1 when the workspace holds the fluid at the grain now


class Workspace(NamedTuple):
    # the fluid at the grain (particle units), kept between steps: stage 1 of the next step
    uf: np.ndarray  # (N,3) velocity at the centre
    grad: np.ndarray  # (N,3,3) ∂u_i/∂x_j
    dudt: np.ndarray  # (N,3) ∂u/∂t
    vort: np.ndarray  # (N,3) vorticity
    uf_top: np.ndarray  # (N,3) velocity at y + 1/2 (lift)
    uf_bot: np.ndarray  # (N,3) velocity at y - 1/2 (lift)
    # scratch within a step
    acc: np.ndarray  # (N,3) fluid-force acceleration of a stage
    dspin: np.ndarray  # (N,3) spin rate of a stage
    x0: np.ndarray  # (N, 9) state at the start of the step
    x: np.ndarray  # (N, 9) stage state
    k: np.ndarray  # (N, 4, 9) stage derivatives
    normal: np.ndarray  # (N,3) bed contact normal
    basset: np.ndarray  # (N,3) history acceleration −P·I_n held over the step
    slip: np.ndarray  # (N,3) slip velocity at a history reset


# The two tuples above as one pointer each, for kernels that hand them to parallel loops
# (grains/refs.py): ``GrainStateRef(*st)``, ``WorkspaceRef(*w)``.
GrainStateRefType, GrainStateRef = struct_ref(GrainState, __name__)
WorkspaceRefType, WorkspaceRef = struct_ref(Workspace, __name__)


def make_workspace(n: int) -> Workspace:
    e3 = lambda: np.zeros((n, 3))  # noqa: E731
    return Workspace(
        e3(), np.zeros((n, 3, 3)), e3(), e3(), e3(), e3(), e3(), e3(),
        np.zeros((n, 9)), np.zeros((n, 9)), np.zeros((n, 4, 9)), e3(), e3(), e3(),
    )


def make_state(pos, vel, spin, t0, n_window, jump_capacity=16) -> GrainState:
    n = len(pos)
    hs = history.allocate_history_state(n, n_window)
    return GrainState(
        np.array(pos, dtype=np.float64),
        np.array(vel, dtype=np.float64),
        np.array(spin, dtype=np.float64),
        np.full(n, float(t0)),
        np.array(pos, dtype=np.float64)[:, 0].copy(),
        np.array(pos, dtype=np.float64)[:, 1].copy(),
        np.zeros(n, dtype=np.int64),
        np.zeros(n, dtype=np.int64),
        np.zeros((n, jump_capacity, JUMP_FIELDS)),
        np.zeros(n, dtype=np.int64),
        np.zeros(n, dtype=np.int64),
        np.zeros(n, dtype=np.int64),
        hs.slip_hist,
        hs.meta,
        hs.tail,
        np.zeros((n, 3)),
        np.zeros(n, dtype=np.int64),
    )


# Speed. Every call of a compiled function that takes arrays, and every view of an array
# row, costs Numba an atomic reference-count increment and decrement per array: with ~40
# arrays in play per grain and stage that was more than the arithmetic. The chunk
# functions (free_flight_particles, below) and the flow kernels are therefore compiled
# without reference counting (_nrt=False; they allocate nothing, every array they touch is
# owned by the caller of the step, engine/stepping.py), and the per-stage helper is inlined
# into them. A chunk function is a call per chunk of grains (CHUNK, below), not inlined into
# the prange body of engine/stepping.py: Numba 0.68 drops writes made by parfor-inlined code
# through a named tuple's arrays (st.status[p] = ...).
# Two Numba facts follow. (1) The kernels the step calls (forces, spin, history, bed,
# rng) are marked _nrt=False in their own modules, so they are refcount-free whichever
# caller compiles them first (a test calling one from Python used to leave a counting
# version in the cache: ~0.45 us more per grain, benchmarks/bench_saltation.py). (2) Nothing called from the step may allocate (np.empty,
# np.zeros, array-returning functions): compiled from here it fails to type. Allocate in
# make_state / make_workspace.


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _rhs(coef, x, basset, uf, grad, dudt, vort, uf_top, uf_bot, acc, dspin, k):
    """Right-hand side at stage state x (9,) -> k (9,) with the fluid already sampled;
    basset: the history acceleration −P·I_n held over the step (zeros when off)."""
    up = x[3:6]
    spin = x[6:9]
    fluid_acceleration(up, uf, grad, dudt, vort, spin, uf_top, uf_bot, coef, acc)
    if coef[ON_SPIN] != 0.0:
        spin_rate(spin, vort, coef[R_SUBMERGED], coef[RE_STAR], dspin)
    else:
        for i in range(3):
            dspin[i] = 0.0
    for i in range(3):
        k[i] = x[3 + i]
        k[3 + i] = acc[i] + basset[i]
        k[6 + i] = dspin[i]


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def _stage_point(f, re_star, p0, v0, dp, dv, h, t):
    """RK4 stage state x0 + h·k (position p0 + h·dp, velocity v0 + h·dv) and where its
    position lies in the flow at time t: (velocity, physics.fluid.locate_grain result)."""
    v = (v0[0] + h * dv[0], v0[1] + h * dv[1], v0[2] + h * dv[2])
    loc = locate_grain(f, re_star, p0[0] + h * dp[0], p0[1] + h * dp[1], p0[2] + h * dp[2], t)
    return v, loc


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def _stage_acceleration(f, coef, loc, cell, v):
    """Weight and drag at a located stage point whose fluid cell is gathered."""
    u0, u1, u2 = grain_velocity(f, loc, cell)
    return weight_and_drag(coef, v[0], v[1], v[2], u0, u1, u2)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def _weight_drag_flight(f, coef, st, w, p, t, dt):
    """``_free_flight_body`` when weight and drag are the only forces switched on (no lift,
    Magnus, added mass, fluid acceleration, Basset or spin law: the fluid velocity alone
    is needed; the spin stays as it is). The same RK4 stages, fluid samples and
    arithmetic, on scalars instead of the workspace rows, and one fluid cell gathered
    per time level: the stages at t + dt/2 share it, and so do the last stage and the
    end-of-step sample at t + dt, whenever their points lie in the same cell
    (sampler.gather_cell). Measured on one thread, 10 000 grains on the shipped LES,
    with the per-chunk calls: 0.58-0.65 us per grain-step against 0.93-1.0 us for the
    general body on the same physics."""
    re_star = coef[RE_STAR]
    pos = st.pos[p]
    vel = st.vel[p]
    x0 = w.x0[p]
    uf = w.uf[p]
    px, py, pz = pos[0], pos[1], pos[2]
    vx, vy, vz = vel[0], vel[1], vel[2]
    for i in range(3):
        x0[i] = pos[i]
        x0[3 + i] = vel[i]
        x0[6 + i] = st.spin[p, i]
    if st.fresh[p] == 0:
        loc = locate_grain(f, re_star, px, py, pz, t)
        uf[0], uf[1], uf[2] = grain_velocity(f, loc, gather_at(f, loc))
    p0 = (px, py, pz)
    v0 = (vx, vy, vz)
    k1 = weight_and_drag(coef, vx, vy, vz, uf[0], uf[1], uf[2])
    h = 0.5 * dt
    v2, loc_h = _stage_point(f, re_star, p0, v0, v0, k1, h, t + h)  # t + dt/2
    cell_h = gather_at(f, loc_h)
    k2 = _stage_acceleration(f, coef, loc_h, cell_h, v2)
    v3, loc = _stage_point(f, re_star, p0, v0, v2, k2, h, t + h)  # t + dt/2 again
    if not same_cell(loc, loc_h):
        cell_h = gather_at(f, loc)
    k3 = _stage_acceleration(f, coef, loc, cell_h, v3)
    v4, loc_1 = _stage_point(f, re_star, p0, v0, v3, k3, dt, t + dt)  # t + dt
    cell_1 = gather_at(f, loc_1)
    k4 = _stage_acceleration(f, coef, loc_1, cell_1, v4)
    c = dt / 6.0
    px += c * (vx + 2.0 * v2[0] + 2.0 * v3[0] + v4[0])
    py += c * (vy + 2.0 * v2[1] + 2.0 * v3[1] + v4[1])
    pz += c * (vz + 2.0 * v2[2] + 2.0 * v3[2] + v4[2])
    vx += c * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
    vy += c * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
    vz += c * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
    pos[0], pos[1], pos[2] = px, py, pz
    vel[0], vel[1], vel[2] = vx, vy, vz
    for i in range(3):
        if not (np.isfinite(pos[i]) and np.isfinite(vel[i])):
            st.status[p] = NOT_FINITE
            return
    # fluid at the new position: the next step's stage 1
    loc = locate_grain(f, re_star, px, py, pz, t + dt)
    if not same_cell(loc, loc_1):
        cell_1 = gather_at(f, loc)
    uf[0], uf[1], uf[2] = grain_velocity(f, loc, cell_1)
    st.fresh[p] = 1


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _samples_needed(coef):
    """(lift, gradient): which fluid samples the forces switched on need. The velocity
    gradient serves Magnus (vorticity), added mass and fluid acceleration (material
    derivatives) and the spin law (vorticity); drag, weight and lift need the velocity
    alone, a cheaper sample."""
    return coef[ON_LIFT] != 0.0, (coef[ON_MAGNUS] != 0.0 or coef[ON_ADDED_MASS] != 0.0
                                  or coef[ON_FLUID_ACC] != 0.0 or coef[ON_SPIN] != 0.0)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _fluid_rows(w, p):
    """Grain p's rows of the fluid at the grain (``Workspace``): uf, grad, dudt, vort, uf_top, uf_bot."""
    return w.uf[p], w.grad[p], w.dudt[p], w.vort[p], w.uf_top[p], w.uf_bot[p]


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _save_start(st, w, p):
    """Grain p's state (x, u, ϖ) into ``w.x0[p]``, the start of an RK4 step; returns that row."""
    x0 = w.x0[p]
    for i in range(3):
        x0[i] = st.pos[p, i]
        x0[3 + i] = st.vel[p, i]
        x0[6 + i] = st.spin[p, i]
    return x0


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def _rk4_move(f, coef, w, p, pos, vel, spin, t, dt, with_lift, with_gradient):
    """Classic RK4 over dt from t, from the state in ``w.x0[p]`` (which ``pos``, ``vel``,
    ``spin`` hold too, and receive the result), with the fluid at the start already in the
    workspace and the history acceleration ``w.basset[p]`` held over the step."""
    re_star = coef[RE_STAR]
    x0 = w.x0[p]
    x = w.x[p]
    k = w.k[p]
    uf, grad, dudt, vort, uf_top, uf_bot = _fluid_rows(w, p)
    acc = w.acc[p]
    dspin = w.dspin[p]
    basset = w.basset[p]
    _rhs(coef, x0, basset, uf, grad, dudt, vort, uf_top, uf_bot, acc, dspin, k[0])
    for stage in range(1, 4):
        h = 0.5 * dt if stage < 3 else dt
        for i in range(9):
            x[i] = x0[i] + h * k[stage - 1, i]
        fluid_at_grain(f, re_star, x[0], x[1], x[2], t + h, with_lift, uf, grad, dudt, vort, uf_top, uf_bot,
                      with_gradient)
        _rhs(coef, x, basset, uf, grad, dudt, vort, uf_top, uf_bot, acc, dspin, k[stage])
    for i in range(3):
        pos[i] += dt / 6.0 * (k[0, i] + 2.0 * k[1, i] + 2.0 * k[2, i] + k[3, i])
        vel[i] += dt / 6.0 * (k[0, 3 + i] + 2.0 * k[1, 3 + i] + 2.0 * k[2, 3 + i] + k[3, 3 + i])
        spin[i] += dt / 6.0 * (k[0, 6 + i] + 2.0 * k[1, 6 + i] + 2.0 * k[2, 6 + i] + k[3, 6 + i])


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def _free_flight_body(f, coef, st, w, hc, p, t, dt):
    """Steps 1-2 of the module docstring for particle p: RK4 from t to t + dt with the
    fluid forces, then the fluid sample at the new position and the history closure.
    Leaves the start-of-step state (x, u, ϖ) in ``w.x0[p]``; no bed. hc:
    history.HistoryCoefficients."""
    re_star = coef[RE_STAR]
    with_lift, with_gradient = _samples_needed(coef)
    with_basset = coef[ON_BASSET] != 0.0
    pos = st.pos[p]
    vel = st.vel[p]
    spin = st.spin[p]
    x0 = _save_start(st, w, p)
    uf, grad, dudt, vort, uf_top, uf_bot = _fluid_rows(w, p)
    basset = w.basset[p]
    if st.fresh[p] == 0:
        fluid_at_grain(f, re_star, x0[0], x0[1], x0[2], t, with_lift, uf, grad, dudt, vort, uf_top, uf_bot,
                      with_gradient)
    i_hist = st.hist_i[p]
    for i in range(3):
        basset[i] = 0.0
    if with_basset:
        if st.hist_meta[p, META_COUNT] <= 0:
            # release, or the step after an impact: the slip step kept, or a restart (physics/history.py)
            slip = w.slip[p]
            for i in range(3):
                slip[i] = vel[i] - uf[i]
            history_start_step(slip, st.hist_slip[p], st.hist_meta[p], st.hist_tail[p], i_hist, dt,
                               hc.keep_impacts, hc.tail_time, hc.tail_weight)
        add_basset_acceleration(coef[BASSET_PREFACTOR], i_hist, basset)
    _rk4_move(f, coef, w, p, pos, vel, spin, t, dt, with_lift, with_gradient)
    for i in range(3):
        if not (np.isfinite(pos[i]) and np.isfinite(vel[i]) and np.isfinite(spin[i])):
            st.status[p] = NOT_FINITE
            return
    # fluid at the new position: closes the history step and serves as the next stage 1
    fluid_at_grain(f, re_star, pos[0], pos[1], pos[2], t + dt, with_lift, uf, grad, dudt, vort, uf_top, uf_bot,
                      with_gradient)
    st.fresh[p] = 1
    if with_basset:
        history_end_step(
            vel, uf, i_hist, coef[BASSET_PREFACTOR], dt, st.hist_slip[p], st.hist_meta[p],
            st.hist_tail[p], hc.window_weights, hc.tail_weight, hc.tail_decay, hc.tail_c_old, hc.tail_c_new, i_hist,
            hc.tail_time,
        )


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def _bed_check_body(f, coef, hc, st, w, p, t, dt, bed, seed):
    """Step 3 of the module docstring for particle p after its move from ``w.x0[p]`` to
    ``st.pos[p]``: virtual-bed impact, grazing contact, highest point of the jump."""
    pos = st.pos[p]
    vel = st.vel[p]
    y_old = w.x0[p, 1]
    y_new = pos[1]
    if y_new < RADIUS:
        if vel[1] < 0.0 and y_old >= RADIUS:
            _bed_impact(f, coef, hc, st, w, p, t, dt, True, bed, seed)
        else:
            # grazing contact without a descending crossing: keep the grain on the bed
            pos[1] = RADIUS
            st.fresh[p] = 0
            if vel[1] < 0.0:
                _bed_impact(f, coef, hc, st, w, p, t, dt, False, bed, seed)
    if pos[1] > st.jump_ymax[p]:
        st.jump_ymax[p] = pos[1]


# Grains per compiled call in the parallel loops. A call passes the state and workspace
# (~30 arrays) by value: once per grain it cost ~0.3 us, as much as a drag-and-weight
# step (measured with the weight-and-drag body inlined: 0.63 -> 0.35 us per grain-step),
# once per chunk it is noise. The bodies are inlined into the chunk functions (not into a prange
# body: Numba 0.68 drops writes made by parfor-inlined code through a named tuple's arrays).
CHUNK = 64


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _weight_and_drag_only(coef):
    """True when weight and drag are the only forces switched on (``_weight_drag_flight``)."""
    return (coef[ON_LIFT] == 0.0 and coef[ON_BASSET] == 0.0 and coef[ON_MAGNUS] == 0.0
            and coef[ON_ADDED_MASS] == 0.0 and coef[ON_FLUID_ACC] == 0.0 and coef[ON_SPIN] == 0.0)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def weight_drag_particles(f, coef, st, w, lo, hi, t, dt):
    """``_weight_drag_flight`` for grains lo..hi-1 that are OK (one compiled function for
    both callers: the body is large and inlining it twice doubled the compile time)."""
    for p in range(lo, hi):
        if st.status[p] == OK:
            _weight_drag_flight(f, coef, st, w, p, t, dt)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def free_flight_particles(f, coef, st, w, hc, lo, hi, t, dt):
    """Steps 1-2 of the module docstring (``_free_flight_body``) for grains lo..hi-1 that are OK."""
    if _weight_and_drag_only(coef):
        weight_drag_particles(f, coef, st, w, lo, hi, t, dt)
        return
    for p in range(lo, hi):
        if st.status[p] == OK:
            _free_flight_body(f, coef, st, w, hc, p, t, dt)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _bed_impact(f, coef, hc, st, w, p, t, dt, crossed, bed, seed):
    """Rebound on the virtual rough bed; close the jump; reset the history. ``crossed``: the
    grain came down through the bed top in this step (from ``w.x0[p]`` to ``st.pos[p]``),
    else it touches it at the step's end (grazing).

    Where and when it hit (second order): the first time the step's path, the cubic
    Hermite through the start and end states (flight/path.py), reaches the bed top; the
    position and velocity there are the path's, the spin linear between the ends. After
    the rebound the grain flies on for the rest of the step by one RK4 step with its fluid
    forces (``flight_remainder``), and the Basset history dates the slip step at the
    impact (physics/history.py, "Impacts and contacts keep the history"). (Before: the
    contact by running the move back along the end-of-step velocity, that velocity
    rebounded, the rest of the step in a straight line without forces, the slip step dated
    at the step's end: first order, H +4 % and U +2.6 % at Δt = 0.02 d/u* in free flight.)"""
    pos = st.pos[p]
    vel = st.vel[p]
    spin = st.spin[p]
    s = 1.0
    if crossed:
        x0 = w.x0[p]
        s = first_below(x0[1], pos[1], x0[4], vel[1], dt, RADIUS)
        for i in range(3):
            x_hit, u_hit = hermite_point(x0[i], pos[i], x0[3 + i], vel[i], s, dt)
            pos[i] = x_hit
            vel[i] = u_hit
            spin[i] = (1.0 - s) * x0[6 + i] + s * spin[i]
        pos[1] = RADIUS
    t_hit = t + s * dt
    # close the jump (SPEC §6, bed/jumps.py): length, height of the grain bottom above the bed top
    close_jump(st, p, st.jump_t0[p], pos[0] - st.jump_x0[p], st.jump_ymax[p] - RADIUS, t_hit,
               bed[BED_MIN_JUMP_DURATION], bed[BED_MIN_JUMP_HEIGHT])
    # open the next jump here
    st.jump_t0[p] = t_hit
    st.jump_x0[p] = pos[0]
    # rebound on a randomly tilted bed grain (bed/virtual.py), then fly on for the rest of the step
    n = w.normal[p]
    c = st.impacts[p]
    xi1, xi2 = uniform2(seed, p, c)
    du0, du1, du2 = vel[0], vel[1], vel[2]
    virtual_bed_normal(vel, xi1, xi2, bed[2], n)
    bed_rebound(vel, spin, n, bed[0], bed[1], RADIUS)
    st.impacts[p] += 1
    if s < 1.0:
        flight_remainder(f, coef, hc, st, w, p, t_hit, (1.0 - s) * dt, vel[0] - du0, vel[1] - du1, vel[2] - du2)
        if pos[1] < RADIUS:
            pos[1] = RADIUS  # a weak rebound under gravity: the next step's bed check takes it from there
    st.jump_ymax[p] = pos[1]
    st.fresh[p] = 0  # moved: the fluid must be sampled again
    # the next step takes the slip step, dated at the impact (physics/history.py)
    history_mark_impact_at(st.hist_meta[p], 1.0 - s)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def flight_remainder(f, coef, hc, st, w, p, t, h, du0, du1, du2):
    """Grain p from its rebound at t to the step's end, t + h (h < Δt), by one RK4 step with
    its fluid forces (``_rk4_move``). The history force: with ``forces.basset_impacts =
    "keep"`` the flight's part held at its value at the step's end (−P I_{n+1}, the
    history closed before the bed pass) and the impulse of
    the rebound's own slip step Δu over the rest of the step, −P Δu · 2√h (its exact
    integral of Δu/√(t − t_c), physics/history.py); with "restart" none (the memory starts
    afresh at the impact). Leaves the rebound's state in ``w.x0[p]`` (the start of the
    path it flew: the packed bed looks for a further impact on it); the step's start is
    not read after the bed check."""
    re_star = coef[RE_STAR]
    with_lift, with_gradient = _samples_needed(coef)
    pos = st.pos[p]
    vel = st.vel[p]
    spin = st.spin[p]
    _save_start(st, w, p)
    keep = coef[ON_BASSET] != 0.0 and hc.keep_impacts
    for i in range(3):
        w.basset[p, i] = 0.0
    if keep:
        add_basset_acceleration(coef[BASSET_PREFACTOR], st.hist_i[p], w.basset[p])
    uf, grad, dudt, vort, uf_top, uf_bot = _fluid_rows(w, p)
    fluid_at_grain(f, re_star, pos[0], pos[1], pos[2], t, with_lift, uf, grad, dudt, vort, uf_top, uf_bot,
                   with_gradient)
    _rk4_move(f, coef, w, p, pos, vel, spin, t, h, with_lift, with_gradient)
    if keep:
        kick = coef[BASSET_PREFACTOR] * 2.0 * np.sqrt(h)
        vel[0] -= kick * du0
        vel[1] -= kick * du1
        vel[2] -= kick * du2
    for i in range(3):
        if not (np.isfinite(pos[i]) and np.isfinite(vel[i]) and np.isfinite(spin[i])):
            st.status[p] = NOT_FINITE
            return
