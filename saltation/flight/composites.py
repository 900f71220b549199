"""Rigid bonded-sphere grains in free flight and on the bed (seed 000 §2.4, SPEC §2, §4).

Units. Particle units as everywhere (SPEC §1) with the length scale d = the case's
particle diameter, here the *nominal* diameter Dn = (Dl Di Ds)^{1/3} of the grains:
length Dn, velocity u*, time Dn/u*; in addition mass ρ Dn³ (ρ: fluid density), force
ρ u*² Dn², torque ρ u*² Dn³. A component sphere k has diameter d_k (in Dn), volume weight
w_k (its volume, scaled so that Σ w_k is the volume V of the union; = π d_k³/6 when the
spheres do not overlap) and body-frame offset r_k from the centre of mass.

State of a grain: centre of mass x, velocity v, orientation quaternion q (body → world,
scalar first), angular velocity Ω (world frame; the body-frame ω_b = Rᵀ Ω).

Forces, per component sphere at its own position x_k = x + R r_k, moving with
u_k = v + Ω × (R r_k), fluid sampled there (``flowfields.sampler.sample_column``) —
the sphere terms of SPEC §2 written as forces with the sphere's own diameter:

=====================  ===========================================================
drag                   F = −(π/8) d_k² C_D(Re_k) |u_r| u_r,  Re_k = |u_r| d_k Re*,
                       Yen (1992) (``forces.drag_factor``)
lift (y)               F_y = (π/8) C_L d_k² (|u_r|²(y_k + d_k/2) − |u_r|²(y_k − d_k/2))
Magnus                 F = (π/8) C_Ω d_k³ (Ω − ½ω_f) × u_r
added mass (fluid)     F = Cm w_k (∂u_f/∂t + (u_k·∇) u_f)
fluid acceleration     F = w_k (∂u_f/∂t + (u_f·∇) u_f)
Basset                 F = −(3/2)√π d_k²/√Re* · I_k,  I_k the history integral of
                       the component's own slip (physics/history.py, window + tail)
rotational drag        T = −(d_k⁵/64) C_ω(Re_r) |ω_r| ω_r, ω_r = Ω − ½ω_f,
                       Re_r = d_k² |ω_r| Re*/4 (``physics/spin.py`` table)
submerged weight       F = (V/τ*)(sin θ, −cos θ, 0) at the centre of mass
=====================  ===========================================================

summed into the force F and the torque T = Σ (R r_k) × F_k + Σ T_k: a sheared flow
exerts a torque through the different drag on the components. For d_k = 1, r_k = 0
every line divided by the virtual mass (1+R+Cm)π/6 is the sphere's per-mass term of
physics/forces.py / physics/spin.py, so the one-sphere grain is the sphere integrator.

Wake shielding (``[forces] wake_shielding``, default on). A component in the wake of
another component of the same grain feels less drag than an isolated sphere (tandem
spheres: the trailing sphere's drag is about half the isolated value when they touch
at Re = O(10–100), recovering over several diameters; Tsuji et al. 1982, Zhu et al.
1994, Liang et al. 1996). Its drag is multiplied by ``wake_factor``:
Π_j [1 − A φ_jk c_jk exp(−max(L_jk/d_j − 1, 0)/λ)] over the upstream components j, with
A = 0.5, λ = 6 (the round values of those measurements, not a fit), L the distance
along the slip, φ the lateral overlap of the frontal disks and c the covered fraction of
k's frontal area. Without it, equal spheres on a lattice feel equal drag in every
orientation and a falling rod or disk keeps whatever tilt it starts with; with it the
leading end carries more drag and the grain turns its largest projection across the
fall, as the seed's CFD–DEM grains do (seed 000 §3, where the two-way coupling supplies
the wake). Broadside, no component is behind another and the factor is 1. One-sphere
grains are unaffected.

Equations of motion. The added-mass reaction −Cm w_k du_k/dt of every component is
moved to the left side with du_k/dt = a + α × r + Ω × (Ω × r): a constant 6×6
generalized mass matrix in the body frame

    M_b = [[(m + m_a) 1, −[S]×], [[S]×, I_b + I_a]],
    m = (1+R) V,  m_a = Cm V,  S = Cm Σ w_k r_k,  I_a = Cm Σ w_k (|r_k|² 1 − r_k r_kᵀ),

(I_b = (1+R) × the union's second moment, grains/shapes.py) with the right side
[F_b − ω_b × (ω_b × S); T_b − ω_b × ((I_b + I_a) ω_b)] (Euler's equations with the
gyroscopic and centripetal terms; the inertia need not be diagonal). S = 0 unless
the spheres overlap. dq/dt = ½ (0, Ω) ⊗ q, dΩ/dt = R α_b, dv/dt = R a_b. Classic RK4
on (x, v, q, Ω), q renormalized after each step.

Basset closure (as physics/history.py for spheres): the history force is held at I_n over the
stages; at the end of the step the newest sample is implicit, which for a rigid body
couples the components: (M_b + (Δt/2) γ₀ C_b) q_{n+1} = M_b q* − (Δt/2) Σ_k J_kᵀ c_k
(I*_k − γ₀ u_f,k − I_k,n), with J_k q = v + ω × r_k, c_k = (3/2)√π d_k²/√Re* and
C_b = Σ c_k J_kᵀ J_k; one 6×6 solve per grain and step. All components restart their
memory together at release and at every bed impact (physics/history.py explains why).

Bed (virtual rough bed, bed/virtual.py). The grain touches the bed when its lowest component
sphere's bottom reaches y = 0. The crossing is located on the step's path, second order in
Δt as for spheres (``_bed_impact``: the lowest component's bottom as a cubic Hermite in
time; the centre's Hermite path, Ω linear, the orientation turned back by Ω; the rest of
the step flown with the fluid forces), the contact normal n is drawn by ``bed.virtual.virtual_bed_normal`` from the
velocity of that component's centre, and the impulse acts at the contact point
r_c = R r_k − (d_k/2) n with the rigid-body collision matrix
K = 1/m − [r_c]× I_w⁻¹ [r_c]× (rigid mass and inertia, no added mass — as the sphere
rebound of SPEC §4): Newton restitution e on the normal contact-point velocity, and
Coulomb friction f — sticking (J = K⁻¹ Δc, tangential contact velocity brought to
zero) if |J_t| ≤ f J_n, else sliding opposite to the initial tangential slip. For a
sphere this is exactly SPEC §4. With sliding on a non-spherical body the fixed slip
direction can in rare configurations add energy; the impulse is then replaced by the
frictionless one (checked each time). If the contact point still descends afterwards,
a second impact on the horizontal bed follows (as ``bed.virtual.bed_rebound``). Jump height
is the highest elevation of the grain's lowest point above the bed top.

With bed.model = "packed" (``bed[BED_MODEL] = BED_PACKED``) step_grain leaves the bed
alone and bed/packed_composites.py applies the hexagonal layer of fixed spheres after the move.
With grain–grain contacts on the virtual bed (``BED_VIRTUAL_AFTER``) it leaves it alone too:
the grains whose path can reach the bed top have soft bed contacts in the contact phase,
and ``virtual_bed_pass`` runs the check above (``virtual_bed_check``) for the others after it.

Grain–grain contacts between composites are not in this module: contacts/composites.py
acts on the component spheres of different grains after each free-flight step
(``advance_clusters_contacts``; ``advance_clusters`` here is the run without them).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from flowfields.sampler import ABOVE_TOP, sample_column, sample_point, vorticity_from_gradient

from ..bed.jumps import BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT, close_jump
from ..bed.virtual import BED_MODEL, virtual_bed_normal
from ..grains.refs import as_tuple, struct_ref
from ..grains.status import JUMP_FIELDS, NOT_FINITE, OK
from ..physics import history
from ..physics.forces import (
    C_OMEGA,
    CL,
    CM,
    COS_SLOPE,
    ON_ADDED_MASS,
    ON_BASSET,
    ON_DRAG,
    ON_FLUID_ACC,
    ON_LIFT,
    ON_MAGNUS,
    ON_WEIGHT,
    RE_STAR,
    SIN_SLOPE,
    TAU_STAR,
    drag_factor,
)
from ..physics.history import (
    META_COUNT,
    _advance,
    _integral3,
    age_jumps,
    history_mark_impact_at,
    history_start_step,
    jump_impulse,
)
from ..physics.rng import uniform2
from ..physics.spin import SPIN_TABLE_C, _spin_row
from .path import first_below, hermite_point

NX = 13  # x(3) v(3) q(4) Ω(3)
SQRT_PI = math.sqrt(math.pi)
# bed[BED_MODEL] (bed/virtual.py): 0 → the virtual bed here, in step_grain; BED_PACKED →
# bed/packed_composites.py; BED_VIRTUAL_AFTER → the virtual bed after the contact phase
# (virtual_bed_pass, for the grains that phase did not move: contacts/composites.py)
BED_PACKED = 1.0
BED_VIRTUAL_AFTER = 2.0
# wake shielding of a component by an upstream component of the same grain (docstring)
WAKE_A = 0.5  # drag deficit of a trailing sphere touching its leader, on the axis
WAKE_LENGTH = 6.0  # recovery length of the deficit, in the leader's diameters


class ClusterState(NamedTuple):
    pos: np.ndarray  # (N,3) centre of mass; x, z unwrapped; y above the bed top (Dn)
    vel: np.ndarray  # (N,3) u*
    quat: np.ndarray  # (N,4) body → world, scalar first
    omega: np.ndarray  # (N,3) world frame, u*/Dn
    mass: np.ndarray  # (N,) rigid mass (1+R)V, ρDn³
    volume: np.ndarray  # (N,) V (Dn³)
    inertia: np.ndarray  # (N,3,3) rigid inertia, body frame
    inertia_inv: np.ndarray  # (N,3,3)
    mmat: np.ndarray  # (N,6,6) generalized mass M_b incl. added mass
    mmat_inv: np.ndarray  # (N,6,6)
    cbas: np.ndarray  # (N,6,6) Basset coupling C_b = Σ c_k J_kᵀ J_k
    s_am: np.ndarray  # (N,3) added-mass first moment S (body)
    i_total: np.ndarray  # (N,3,3) I_b + I_a (body)
    cstart: np.ndarray  # (N+1,) int64 first component of each grain
    r_body: np.ndarray  # (K,3)
    d_comp: np.ndarray  # (K,)
    w_comp: np.ndarray  # (K,)
    jump_t0: np.ndarray
    jump_x0: np.ndarray
    jump_ymax: np.ndarray  # highest elevation of the grain's lowest point this jump
    jump_count: np.ndarray
    impacts: np.ndarray
    jump_buf: np.ndarray  # (N, cap, 4)
    jump_buf_n: np.ndarray
    status: np.ndarray
    above_top: np.ndarray
    hist_slip: np.ndarray  # (K, N_w+2, 3)
    hist_meta: np.ndarray  # (K, 2 + history.N_JUMPS) int64
    hist_tail: np.ndarray  # (K, 10 + history.N_JUMPS, 3)
    hist_i: np.ndarray  # (K, 3)
    fresh: np.ndarray  # (N,) 1 when the component samples hold the fluid now
    spin_drag: np.ndarray  # (1,) 1.0: rotational drag of the components on (0.0: vacuum)
    wake: np.ndarray  # (3,) wake shielding [on, A, λ] (module docstring)


class ClusterWork(NamedTuple):
    uf: np.ndarray  # (K,3)
    grad: np.ndarray  # (K,3,3)
    dudt: np.ndarray  # (K,3)
    vort: np.ndarray  # (K,3)
    uf_top: np.ndarray  # (K,3)
    uf_bot: np.ndarray  # (K,3)
    rw: np.ndarray  # (K,3) world offsets of the components at the stage
    x0: np.ndarray  # (N,13)
    x: np.ndarray  # (N,13)
    k: np.ndarray  # (N,4,13)
    rot: np.ndarray  # (N,3,3)
    ft: np.ndarray  # (N,6) force, torque (world), then body, then accelerations
    aug: np.ndarray  # (N,6,7) 6×6 solve
    vec: np.ndarray  # (N,12) scratch vectors


# The two tuples above as one pointer each, for kernels that hand them to parallel loops
# (grains/refs.py): ``ClusterStateRef(*st)``, ``ClusterWorkRef(*w)``.
ClusterStateRefType, ClusterStateRef = struct_ref(ClusterState, __name__)
ClusterWorkRefType, ClusterWorkRef = struct_ref(ClusterWork, __name__)


# --------------------------------------------------------------------- set-up (Python)
def grain_matrices(centres, diameters, volume, second_moment, R, Cm, re_star):
    """Body-frame mass properties of one grain in particle units (lengths in Dn).

    Returns dict(mass, inertia, mmat, cbas, s_am, i_total, w) — see module docstring."""
    r = np.asarray(centres, float)
    d = np.asarray(diameters, float)
    vk = math.pi / 6.0 * d**3
    w = vk * (volume / vk.sum())
    m = (1.0 + R) * volume
    inertia = (1.0 + R) * np.asarray(second_moment, float)
    s = Cm * (w[:, None] * r).sum(axis=0)
    ia = Cm * sum(wk * ((rk @ rk) * np.eye(3) - np.outer(rk, rk)) for wk, rk in zip(w, r))
    it = inertia + ia

    def cross(v):
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])

    mm = np.zeros((6, 6))
    mm[:3, :3] = (m + Cm * volume) * np.eye(3)
    mm[:3, 3:] = -cross(s)
    mm[3:, :3] = cross(s)
    mm[3:, 3:] = it
    cb = np.zeros((6, 6))
    for dk, rk in zip(d, r):
        ck = 1.5 * SQRT_PI * dk * dk / math.sqrt(re_star)
        jk = np.hstack([np.eye(3), -cross(rk)])  # u_k = v + ω × r = v − [r]× ω
        cb += ck * jk.T @ jk
    return dict(mass=m, inertia=inertia, mmat=mm, cbas=cb, s_am=s, i_total=it, w=w)


def make_cluster_state(composites, pos, vel, quat, omega, t0, n_window, *, R, Cm, re_star,
                       jump_capacity=16, spin_drag=True, wake_shielding=True) -> ClusterState:
    """State for grains given as shapes.Composite in particle units (lengths in Dn; use
    ``composite.scaled(1/Dn)``). pos/vel/omega (N,3), quat (N,4). Cm: added-mass
    coefficient of the inertia (pass coef[CM]); spin_drag=False switches off the
    components' rotational drag (with every force off and Cm = 0: a grain in vacuum, for
    the rigid-body checks; the sphere model has no such switch); wake_shielding=False
    gives every component the drag of an isolated sphere."""
    n = len(composites)
    counts = np.array([c.n_spheres for c in composites], dtype=np.int64)
    cstart = np.zeros(n + 1, dtype=np.int64)
    cstart[1:] = np.cumsum(counts)
    kt = int(cstart[-1])
    r_body = np.zeros((kt, 3))
    d_comp = np.zeros(kt)
    w_comp = np.zeros(kt)
    mass = np.zeros(n)
    volume = np.zeros(n)
    inertia = np.zeros((n, 3, 3))
    mm = np.zeros((n, 6, 6))
    cb = np.zeros((n, 6, 6))
    s_am = np.zeros((n, 3))
    it = np.zeros((n, 3, 3))
    for i, c in enumerate(composites):
        g = grain_matrices(c.centres, c.diameters, c.volume, c.second_moment, R, Cm, re_star)
        a, b = cstart[i], cstart[i + 1]
        r_body[a:b] = c.centres
        d_comp[a:b] = c.diameters
        w_comp[a:b] = g["w"]
        mass[i] = g["mass"]
        volume[i] = c.volume
        inertia[i] = g["inertia"]
        mm[i] = g["mmat"]
        cb[i] = g["cbas"]
        s_am[i] = g["s_am"]
        it[i] = g["i_total"]
    q = np.array(quat, dtype=np.float64)
    q /= np.linalg.norm(q, axis=1)[:, None]
    hs = history.allocate_history_state(kt, n_window)
    p = np.array(pos, dtype=np.float64)
    st = ClusterState(
        p, np.array(vel, dtype=np.float64), q, np.array(omega, dtype=np.float64), mass, volume,
        inertia, np.linalg.inv(inertia), mm, np.linalg.inv(mm), cb, s_am, it, cstart, r_body,
        d_comp, w_comp, np.full(n, float(t0)), p[:, 0].copy(), np.zeros(n),
        np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64),
        np.zeros((n, jump_capacity, JUMP_FIELDS)), np.zeros(n, dtype=np.int64),
        np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), hs.slip_hist, hs.meta,
        hs.tail, np.zeros((kt, 3)), np.zeros(n, dtype=np.int64),
        np.array([1.0 if spin_drag else 0.0]),
        np.array([1.0 if wake_shielding else 0.0, WAKE_A, WAKE_LENGTH]))
    low = lowest_points(st)
    st.jump_ymax[:] = low
    return st


def make_cluster_work(st: ClusterState) -> ClusterWork:
    n = st.pos.shape[0]
    kt = st.r_body.shape[0]
    e = lambda: np.zeros((kt, 3))  # noqa: E731
    return ClusterWork(e(), np.zeros((kt, 3, 3)), e(), e(), e(), e(), e(), np.zeros((n, NX)),
                       np.zeros((n, NX)), np.zeros((n, 4, NX)), np.zeros((n, 3, 3)),
                       np.zeros((n, 24)), np.zeros((n, 6, 7)), np.zeros((n, 12)))


def lowest_points(st: ClusterState) -> np.ndarray:
    """Elevation of each grain's lowest point above the bed top (Dn)."""
    out = np.zeros(st.pos.shape[0])
    for p in range(st.pos.shape[0]):
        rot = quat_to_matrix_py(st.quat[p])
        a, b = st.cstart[p], st.cstart[p + 1]
        y = st.pos[p, 1] + st.r_body[a:b] @ rot[1] - 0.5 * st.d_comp[a:b]
        out[p] = y.min()
    return out


def quat_to_matrix_py(q):
    m = np.zeros((3, 3))
    _quat_to_matrix(q[0], q[1], q[2], q[3], m)
    return m


def world_centres(st: ClusterState, p: int) -> np.ndarray:
    """World positions (Dn) of grain p's component spheres."""
    rot = quat_to_matrix_py(st.quat[p])
    a, b = st.cstart[p], st.cstart[p + 1]
    return st.pos[p] + st.r_body[a:b] @ rot.T


# --------------------------------------------------------------------- small kernels
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _second_row(w, x, y, z):
    """The second (vertical) row of the rotation matrix of the unit quaternion (w, x, y, z)."""
    return 2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _quat_to_matrix(w, x, y, z, m):
    m[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[0, 1] = 2.0 * (x * y - w * z)
    m[0, 2] = 2.0 * (x * z + w * y)
    m[1, 0], m[1, 1], m[1, 2] = _second_row(w, x, y, z)
    m[2, 0] = 2.0 * (x * z - w * y)
    m[2, 1] = 2.0 * (y * z + w * x)
    m[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _turned(w, xx, y, z, o0, o1, o2, h):
    """exp(h Ω/2 as a rotation vector) ⊗ q for q = (w, xx, y, z), Ω = (o0, o1, o2) (world), exact."""
    ang = h * math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    if ang == 0.0:
        return w, xx, y, z
    s = math.sin(0.5 * ang) / (ang / h)
    c = math.cos(0.5 * ang)
    a0, a1, a2, a3 = c, s * o0, s * o1, s * o2
    return (a0 * w - a1 * xx - a2 * y - a3 * z, a0 * xx + a1 * w + a2 * z - a3 * y,
            a0 * y - a1 * z + a2 * w + a3 * xx, a0 * z + a1 * y - a2 * xx + a3 * w)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _rotate_quat(x, o, h):
    """q ← exp(h Ω/2 as a rotation vector) ⊗ q for q = x[6:10], Ω = o (world), exact."""
    x[6], x[7], x[8], x[9] = _turned(x[6], x[7], x[8], x[9], o[0], o[1], o[2], h)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _solve6(aug, out):
    """Gaussian elimination with partial pivoting on the augmented (6, 7) matrix."""
    for c in range(6):
        piv = c
        big = abs(aug[c, c])
        for r in range(c + 1, 6):
            if abs(aug[r, c]) > big:
                big = abs(aug[r, c])
                piv = r
        if piv != c:
            for j in range(7):
                tmp = aug[c, j]
                aug[c, j] = aug[piv, j]
                aug[piv, j] = tmp
        inv = 1.0 / aug[c, c]
        for r in range(c + 1, 6):
            f = aug[r, c] * inv
            if f != 0.0:
                for j in range(c, 7):
                    aug[r, j] -= f * aug[c, j]
    for c in range(5, -1, -1):
        s = aug[c, 6]
        for j in range(c + 1, 6):
            s -= aug[c, j] * out[j]
        out[c] = s / aug[c, c]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _sample_component(f, re_star, x, y, z, t, radius, with_lift, uf, grad, dudt, vort, uf_top, uf_bot):
    # physics.fluid.fluid_at_grain with the component's own radius for the lift heights;
    # the gradient is always sampled (the rotational drag needs the vorticity). The flag
    # is passed as a run-time bool (np.bool_), as spheres pass theirs: a default or a
    # literal True would be another signature, and the sampler would compile twice
    xp = x * re_star
    yp = y * re_star
    zp = z * re_star
    tp = t * re_star
    if with_lift:
        status = sample_column(f, xp, yp, zp, tp, (y + radius) * re_star, (y - radius) * re_star,
                               uf, grad, dudt, uf_top, uf_bot, np.bool_(True))
    else:
        status = sample_point(f, xp, yp, zp, tp, uf, grad, dudt, np.bool_(True))
    for i in range(3):
        dudt[i] *= re_star
        for j in range(3):
            grad[i, j] *= re_star
    vorticity_from_gradient(grad, vort)
    return 1 if status == ABOVE_TOP else 0


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _sample_grain(f, coef, st, w, p, x, t):
    """Fluid at every component of grain p for the stage state x; fills w.rw."""
    rot = w.rot[p]
    _quat_to_matrix(x[6], x[7], x[8], x[9], rot)
    with_lift = coef[ON_LIFT] != 0.0
    above = 0
    for k in range(st.cstart[p], st.cstart[p + 1]):
        for i in range(3):
            w.rw[k, i] = rot[i, 0] * st.r_body[k, 0] + rot[i, 1] * st.r_body[k, 1] + rot[i, 2] * st.r_body[k, 2]
        above |= _sample_component(f, coef[RE_STAR], x[0] + w.rw[k, 0], x[1] + w.rw[k, 1], x[2] + w.rw[k, 2], t,
                                   0.5 * st.d_comp[k], with_lift, w.uf[k], w.grad[k], w.dudt[k], w.vort[k],
                                   w.uf_top[k], w.uf_bot[k])
    return above


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def wake_factor(a, b, k, rw, d, r0, r1, r2, ur, amp, length):
    """Drag factor of component k of the grain whose components are a..b-1: the
    product over the components j upstream of k (the fluid, moving at −u_r relative to
    k, reaches j first) of 1 − A·φ·c·exp(−max(L/d_j − 1, 0)/λ), with L the distance
    along the flow, φ = 1 − h²/(½(d_j+d_k))² the lateral overlap of the two frontal
    disks (h: lateral offset; 0 when they do not overlap) and c = min(1, (d_j/d_k)²)
    the covered fraction of k's frontal area. rw: world offsets of the components."""
    if ur <= 0.0:
        return 1.0
    e0 = -r0 / ur
    e1 = -r1 / ur
    e2 = -r2 / ur
    out = 1.0
    for j in range(a, b):
        if j == k:
            continue
        dx0 = rw[k, 0] - rw[j, 0]
        dx1 = rw[k, 1] - rw[j, 1]
        dx2 = rw[k, 2] - rw[j, 2]
        along = dx0 * e0 + dx1 * e1 + dx2 * e2
        if along <= 0.0:
            continue
        h2 = dx0 * dx0 + dx1 * dx1 + dx2 * dx2 - along * along
        rad = 0.5 * (d[j] + d[k])
        if h2 >= rad * rad:
            continue
        phi = 1.0 - h2 / (rad * rad)
        cover = min(1.0, (d[j] / d[k]) ** 2)
        out *= 1.0 - amp * phi * cover * math.exp(-max(along / d[j] - 1.0, 0.0) / length)
    return out


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _rhs(coef, st, w, p, x, kout, with_basset):
    """Stage derivative kout (13) of grain p at state x; fluid already sampled there."""
    re_star = coef[RE_STAR]
    ft = w.ft[p]
    for i in range(6):
        ft[i] = 0.0
    ox, oy, oz = x[10], x[11], x[12]
    cm = coef[CM]
    for k in range(st.cstart[p], st.cstart[p + 1]):
        dk = st.d_comp[k]
        rx, ry, rz = w.rw[k, 0], w.rw[k, 1], w.rw[k, 2]
        # component velocity u_k = v + Ω × r
        u0 = x[3] + oy * rz - oz * ry
        u1 = x[4] + oz * rx - ox * rz
        u2 = x[5] + ox * ry - oy * rx
        uf = w.uf[k]
        r0 = u0 - uf[0]
        r1 = u1 - uf[1]
        r2 = u2 - uf[2]
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        a2 = math.pi / 8.0 * dk * dk
        if coef[ON_DRAG] != 0.0:
            ur = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            c = -a2 * drag_factor(ur, dk * re_star)
            if st.wake[0] != 0.0:
                c *= wake_factor(st.cstart[p], st.cstart[p + 1], k, w.rw, st.d_comp, r0, r1, r2, ur,
                                 st.wake[1], st.wake[2])
            f0 += c * r0
            f1 += c * r1
            f2 += c * r2
        if coef[ON_LIFT] != 0.0:
            t0 = u0 - w.uf_top[k, 0]
            t1 = u1 - w.uf_top[k, 1]
            t2 = u2 - w.uf_top[k, 2]
            b0 = u0 - w.uf_bot[k, 0]
            b1 = u1 - w.uf_bot[k, 1]
            b2 = u2 - w.uf_bot[k, 2]
            f1 += a2 * coef[CL] * ((t0 * t0 + t1 * t1 + t2 * t2) - (b0 * b0 + b1 * b1 + b2 * b2))
        vort = w.vort[k]
        s0 = ox - 0.5 * vort[0]
        s1 = oy - 0.5 * vort[1]
        s2 = oz - 0.5 * vort[2]
        if coef[ON_MAGNUS] != 0.0:
            c = a2 * dk * coef[C_OMEGA]
            f0 += c * (s1 * r2 - s2 * r1)
            f1 += c * (s2 * r0 - s0 * r2)
            f2 += c * (s0 * r1 - s1 * r0)
        g = w.grad[k]
        dt_ = w.dudt[k]
        wk = st.w_comp[k]
        if coef[ON_ADDED_MASS] != 0.0:
            c = cm * wk
            f0 += c * (dt_[0] + g[0, 0] * u0 + g[0, 1] * u1 + g[0, 2] * u2)
            f1 += c * (dt_[1] + g[1, 0] * u0 + g[1, 1] * u1 + g[1, 2] * u2)
            f2 += c * (dt_[2] + g[2, 0] * u0 + g[2, 1] * u1 + g[2, 2] * u2)
        if coef[ON_FLUID_ACC] != 0.0:
            f0 += wk * (dt_[0] + g[0, 0] * uf[0] + g[0, 1] * uf[1] + g[0, 2] * uf[2])
            f1 += wk * (dt_[1] + g[1, 0] * uf[0] + g[1, 1] * uf[1] + g[1, 2] * uf[2])
            f2 += wk * (dt_[2] + g[2, 0] * uf[0] + g[2, 1] * uf[1] + g[2, 2] * uf[2])
        if with_basset:
            c = -1.5 * SQRT_PI * dk * dk / math.sqrt(re_star)
            f0 += c * st.hist_i[k, 0]
            f1 += c * st.hist_i[k, 1]
            f2 += c * st.hist_i[k, 2]
        ft[0] += f0
        ft[1] += f1
        ft[2] += f2
        ft[3] += ry * f2 - rz * f1
        ft[4] += rz * f0 - rx * f2
        ft[5] += rx * f1 - ry * f0
        # rotational drag of the component spinning with the body (physics/spin.py, SPEC §2)
        wr = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        re_r = 0.25 * wr * re_star * dk * dk
        row = _spin_row(re_r)
        cw_wr = 4.0 / (re_star * dk * dk) * (SPIN_TABLE_C[row, 0] * math.sqrt(re_r) + SPIN_TABLE_C[row, 1]
                                             + SPIN_TABLE_C[row, 2] * re_r * re_r)
        c = -(dk ** 5) / 64.0 * cw_wr * st.spin_drag[0]
        ft[3] += c * s0
        ft[4] += c * s1
        ft[5] += c * s2
    if coef[ON_WEIGHT] != 0.0:
        gw = st.volume[p] / coef[TAU_STAR]
        ft[0] += gw * coef[SIN_SLOPE]
        ft[1] -= gw * coef[COS_SLOPE]
    _accelerations(st, w, p, x, ft)
    for i in range(3):
        kout[i] = x[3 + i]
        kout[3 + i] = ft[18 + i]
        kout[10 + i] = ft[21 + i]
    # dq/dt = ½ (0, Ω) ⊗ q
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    kout[6] = 0.5 * (-ox * qx - oy * qy - oz * qz)
    kout[7] = 0.5 * (ox * qw + oy * qz - oz * qy)
    kout[8] = 0.5 * (oy * qw + oz * qx - ox * qz)
    kout[9] = 0.5 * (oz * qw + ox * qy - oy * qx)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _accelerations(st, w, p, x, ft):
    """ft[0:6] = world force and torque → ft[18:24] = world (a, α) via the body-frame
    generalized mass (module docstring)."""
    rot = w.rot[p]
    ob = w.vec[p]
    # body-frame Ω and loads
    for i in range(3):
        ob[i] = rot[0, i] * x[10] + rot[1, i] * x[11] + rot[2, i] * x[12]
    body_loads(rot, ft)
    s = st.s_am[p]
    it = st.i_total[p]
    # − ω × (ω × S)
    c0 = ob[1] * s[2] - ob[2] * s[1]
    c1 = ob[2] * s[0] - ob[0] * s[2]
    c2 = ob[0] * s[1] - ob[1] * s[0]
    ft[6] -= ob[1] * c2 - ob[2] * c1
    ft[7] -= ob[2] * c0 - ob[0] * c2
    ft[8] -= ob[0] * c1 - ob[1] * c0
    # − ω × (I ω)
    l0 = it[0, 0] * ob[0] + it[0, 1] * ob[1] + it[0, 2] * ob[2]
    l1 = it[1, 0] * ob[0] + it[1, 1] * ob[1] + it[1, 2] * ob[2]
    l2 = it[2, 0] * ob[0] + it[2, 1] * ob[1] + it[2, 2] * ob[2]
    ft[9] -= ob[1] * l2 - ob[2] * l1
    ft[10] -= ob[2] * l0 - ob[0] * l2
    ft[11] -= ob[0] * l1 - ob[1] * l0
    solve_generalized_mass(st, p, rot, ft)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def body_loads(rot, ft):
    """ft[0:6] = world force and torque → ft[6:12] the same in the body frame (rot: R)."""
    for i in range(3):
        ft[6 + i] = rot[0, i] * ft[0] + rot[1, i] * ft[1] + rot[2, i] * ft[2]
        ft[9 + i] = rot[0, i] * ft[3] + rot[1, i] * ft[4] + rot[2, i] * ft[5]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def solve_generalized_mass(st, p, rot, ft):
    """ft[6:12] = body-frame loads of grain p → ft[12:18] its body (a, α) through the
    generalized mass (with added mass) → ft[18:24] the same in the world frame."""
    mi = st.mmat_inv[p]
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += mi[i, j] * ft[6 + j]
        ft[12 + i] = acc
    for i in range(3):
        ft[18 + i] = rot[i, 0] * ft[12] + rot[i, 1] * ft[13] + rot[i, 2] * ft[14]
        ft[21 + i] = rot[i, 0] * ft[15] + rot[i, 1] * ft[16] + rot[i, 2] * ft[17]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _subtract_wrench(rhs, rot, r, c, e0, e1, e2):
    """rhs[0:6] −= c J_kᵀ e in the body frame: the force c e (world) on a component at body
    offset r, as (e, r × e) with e turned into the body frame by rotᵀ."""
    eb0 = rot[0, 0] * e0 + rot[1, 0] * e1 + rot[2, 0] * e2
    eb1 = rot[0, 1] * e0 + rot[1, 1] * e1 + rot[2, 1] * e2
    eb2 = rot[0, 2] * e0 + rot[1, 2] * e1 + rot[2, 2] * e2
    rx, ry, rz = r[0], r[1], r[2]
    rhs[0] -= c * eb0
    rhs[1] -= c * eb1
    rhs[2] -= c * eb2
    rhs[3] -= c * (ry * eb2 - rz * eb1)
    rhs[4] -= c * (rz * eb0 - rx * eb2)
    rhs[5] -= c * (rx * eb1 - ry * eb0)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _basset_end_step(coef, st, w, hc, p, dt):
    """Implicit newest-sample closure of the history force for the rigid grain (module
    docstring); the fluid at the new positions is in w.uf. Updates vel, omega, history."""
    re_star = coef[RE_STAR]
    rot = w.rot[p]
    a = st.cstart[p]
    b = st.cstart[p + 1]
    h = 0.5 * dt
    aug = w.aug[p]
    mm = st.mmat[p]
    cb = st.cbas[p]
    g0 = 0.0
    rhs = w.ft[p]  # body-frame generalized rhs in ft[0:6]
    vb = w.vec[p]
    for i in range(3):
        vb[i] = rot[0, i] * st.vel[p, 0] + rot[1, i] * st.vel[p, 1] + rot[2, i] * st.vel[p, 2]
        vb[3 + i] = rot[0, i] * st.omega[p, 0] + rot[1, i] * st.omega[p, 1] + rot[2, i] * st.omega[p, 2]
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += mm[i, j] * vb[j]
        rhs[i] = acc
    for k in range(a, b):
        head = _advance(st.hist_slip[k], st.hist_meta[k], st.hist_tail[k], hc.tail_decay, hc.tail_c_old,
                        hc.tail_c_new)
        for c in range(3):
            st.hist_slip[k, head, c] = 0.0
        i0, i1, i2 = _integral3(st.hist_slip[k], st.hist_meta[k], st.hist_tail[k], hc.window_weights,
                                hc.tail_weight)
        row = min(st.hist_meta[k, META_COUNT], hc.window_weights.shape[0] - 1)
        g0 = hc.window_weights[row, 0]
        ck = 1.5 * SQRT_PI * st.d_comp[k] ** 2 / math.sqrt(re_star)
        # world vector e = I* − γ₀ u_f − I_n (+ the exact impulse Q of kept slip steps over
        # the step, as Q/h: physics/history.py), kept in ft[6:9] for the push below
        q0, q1, q2 = jump_impulse(st.hist_meta[k], st.hist_tail[k], dt)
        e0 = i0 - g0 * w.uf[k, 0] - st.hist_i[k, 0] + q0 / h
        e1 = i1 - g0 * w.uf[k, 1] - st.hist_i[k, 1] + q1 / h
        e2 = i2 - g0 * w.uf[k, 2] - st.hist_i[k, 2] + q2 / h
        # keep I* (and what kept slip steps passing into the tail add) for I_{n+1}
        f0, f1, f2 = age_jumps(st.hist_meta[k], st.hist_tail[k], dt, st.hist_slip.shape[1] - 2, hc.tail_time,
                               hc.tail_weight)
        st.hist_i[k, 0] = i0 + f0
        st.hist_i[k, 1] = i1 + f1
        st.hist_i[k, 2] = i2 + f2
        _subtract_wrench(rhs, rot, st.r_body[k], h * ck, e0, e1, e2)
    for i in range(6):
        for j in range(6):
            aug[i, j] = mm[i, j] + h * g0 * cb[i, j]
        aug[i, 6] = rhs[i]
    _solve6(aug, vb)
    for i in range(3):
        st.vel[p, i] = rot[i, 0] * vb[0] + rot[i, 1] * vb[1] + rot[i, 2] * vb[2]
        st.omega[p, i] = rot[i, 0] * vb[3] + rot[i, 1] * vb[4] + rot[i, 2] * vb[5]
    ox, oy, oz = st.omega[p, 0], st.omega[p, 1], st.omega[p, 2]
    for k in range(a, b):
        rx, ry, rz = w.rw[k, 0], w.rw[k, 1], w.rw[k, 2]
        s0 = st.vel[p, 0] + oy * rz - oz * ry - w.uf[k, 0]
        s1 = st.vel[p, 1] + oz * rx - ox * rz - w.uf[k, 1]
        s2 = st.vel[p, 2] + ox * ry - oy * rx - w.uf[k, 2]
        head = st.hist_meta[k, 0]
        st.hist_slip[k, head, 0] = s0
        st.hist_slip[k, head, 1] = s1
        st.hist_slip[k, head, 2] = s2
        st.hist_i[k, 0] += g0 * s0
        st.hist_i[k, 1] += g0 * s1
        st.hist_i[k, 2] += g0 * s2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy", inline="always")
def _lowest_of_row(st, p, py, m10, m11, m12):
    """(lowest bottom elevation, its component) for the grain with centre height py and the
    rotation matrix's second row (m10, m11, m12)."""
    best = 1e300
    kb = st.cstart[p]
    for k in range(st.cstart[p], st.cstart[p + 1]):
        y = py + m10 * st.r_body[k, 0] + m11 * st.r_body[k, 1] + m12 * st.r_body[k, 2] - 0.5 * st.d_comp[k]
        if y < best:
            best = y
            kb = k
    return best, kb


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _lowest(st, w, p, px, py, pz, q0, q1, q2, q3):
    """(lowest bottom elevation, its component) for the grain at (p·, q·); the rotation
    matrix into ``w.rot[p]``."""
    rot = w.rot[p]
    _quat_to_matrix(q0, q1, q2, q3, rot)
    return _lowest_of_row(st, p, py, rot[1, 0], rot[1, 1], rot[1, 2])


# points of a step at which the jump height is sampled: s = j/JUMP_HEIGHT_SAMPLES, j = 1..
JUMP_HEIGHT_SAMPLES = 8


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def highest_on_path(st, w, p, dt):
    """The highest elevation of grain p's lowest point inside its step, on its free path from
    the row ``w.x0[p]`` to its state: at s = 1/8, 2/8, ..., 7/8 (JUMP_HEIGHT_SAMPLES), the centre
    on its Hermite path, the orientation turned back from the end by Ω over the rest of the
    step (as at an impact, ``_bed_impact``). A tumbling grain's lowest point swings up and
    down within a step; sampled at the steps' ends only, the height of a rod's first jump
    came out 3.7 % low on average at Δt = 0.02 Dn/u* (0.6 % at 0.005) against 0.00125;
    with the seven interior samples 0.5 % (tests/test_impact_order.py)."""
    x0 = w.x0[p]
    q = st.quat[p]
    o = st.omega[p]
    best = -1e300
    for j in range(1, JUMP_HEIGHT_SAMPLES):
        s = j / JUMP_HEIGHT_SAMPLES
        py = hermite_point(x0[1], st.pos[p, 1], x0[4], st.vel[p, 1], s, dt)[0]
        q0, q1, q2, q3 = _turned(q[0], q[1], q[2], q[3], o[0], o[1], o[2], -(1.0 - s) * dt)
        m10, m11, m12 = _second_row(q0, q1, q2, q3)
        low, _ = _lowest_of_row(st, p, py, m10, m11, m12)
        best = max(best, low)
    return best


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _impulse(st, p, rcx, rcy, rcz, n0, n1, n2, e, fr, iw):
    """Rigid-body impact at contact offset r_c with unit normal n (module docstring).
    iw: (3,3) world inverse inertia. Returns 1 if an impulse was applied."""
    v = st.vel[p]
    o = st.omega[p]
    m = st.mass[p]
    c0 = v[0] + o[1] * rcz - o[2] * rcy
    c1 = v[1] + o[2] * rcx - o[0] * rcz
    c2 = v[2] + o[0] * rcy - o[1] * rcx
    cn = c0 * n0 + c1 * n1 + c2 * n2
    if cn >= 0.0:
        return 0
    ct0 = c0 - cn * n0
    ct1 = c1 - cn * n1
    ct2 = c2 - cn * n2
    # K = 1/m − [r]× I⁻¹ [r]× as a 3×3 (K x = x/m + r × (I⁻¹ (x × r)) ... written out)
    k00 = k01 = k02 = k10 = k11 = k12 = k20 = k21 = k22 = 0.0
    for col in range(3):
        x0 = 1.0 if col == 0 else 0.0
        x1 = 1.0 if col == 1 else 0.0
        x2 = 1.0 if col == 2 else 0.0
        # y = I⁻¹ (r × x);  K x = x/m + (I⁻¹(r × x)) × r
        a0 = rcy * x2 - rcz * x1
        a1 = rcz * x0 - rcx * x2
        a2 = rcx * x1 - rcy * x0
        y0 = iw[0, 0] * a0 + iw[0, 1] * a1 + iw[0, 2] * a2
        y1 = iw[1, 0] * a0 + iw[1, 1] * a1 + iw[1, 2] * a2
        y2 = iw[2, 0] * a0 + iw[2, 1] * a1 + iw[2, 2] * a2
        z0 = x0 / m + y1 * rcz - y2 * rcy
        z1 = x1 / m + y2 * rcx - y0 * rcz
        z2 = x2 / m + y0 * rcy - y1 * rcx
        if col == 0:
            k00, k10, k20 = z0, z1, z2
        elif col == 1:
            k01, k11, k21 = z0, z1, z2
        else:
            k02, k12, k22 = z0, z1, z2
    # sticking: Δc = −(1+e) c_n n − c_t ;  J = K⁻¹ Δc (Cramer)
    d0 = -(1.0 + e) * cn * n0 - ct0
    d1 = -(1.0 + e) * cn * n1 - ct1
    d2 = -(1.0 + e) * cn * n2 - ct2
    det = k00 * (k11 * k22 - k12 * k21) - k01 * (k10 * k22 - k12 * k20) + k02 * (k10 * k21 - k11 * k20)
    j0 = (d0 * (k11 * k22 - k12 * k21) - k01 * (d1 * k22 - k12 * d2) + k02 * (d1 * k21 - k11 * d2)) / det
    j1 = (k00 * (d1 * k22 - k12 * d2) - d0 * (k10 * k22 - k12 * k20) + k02 * (k10 * d2 - d1 * k20)) / det
    j2 = (k00 * (k11 * d2 - d1 * k21) - k01 * (k10 * d2 - d1 * k20) + d0 * (k10 * k21 - k11 * k20)) / det
    jn = j0 * n0 + j1 * n1 + j2 * n2
    jt0 = j0 - jn * n0
    jt1 = j1 - jn * n1
    jt2 = j2 - jn * n2
    ct = math.sqrt(ct0 * ct0 + ct1 * ct1 + ct2 * ct2)
    if math.sqrt(jt0 * jt0 + jt1 * jt1 + jt2 * jt2) > fr * jn and ct > 0.0:
        # sliding: J = j (n − f t̂), n·(c + K J) = −e c_n
        u0 = n0 - fr * ct0 / ct
        u1 = n1 - fr * ct1 / ct
        u2 = n2 - fr * ct2 / ct
        ku = n0 * (k00 * u0 + k01 * u1 + k02 * u2) + n1 * (k10 * u0 + k11 * u1 + k12 * u2) \
            + n2 * (k20 * u0 + k21 * u1 + k22 * u2)
        if ku > 0.0:
            jj = -(1.0 + e) * cn / ku
            j0, j1, j2 = jj * u0, jj * u1, jj * u2
        else:
            j0 = j1 = j2 = 1e300  # marker: frictionless below
    ke0 = _kinetic(st, p, iw)
    if j0 < 1e299:
        _apply(st, p, j0, j1, j2, rcx, rcy, rcz, iw)
        if _kinetic(st, p, iw) <= ke0 * (1.0 + 1e-12):
            return 1
        _apply(st, p, -j0, -j1, -j2, rcx, rcy, rcz, iw)
    # frictionless fallback: J = j n, j = −(1+e) c_n / (n·K n)
    kn = n0 * (k00 * n0 + k01 * n1 + k02 * n2) + n1 * (k10 * n0 + k11 * n1 + k12 * n2) \
        + n2 * (k20 * n0 + k21 * n1 + k22 * n2)
    jj = -(1.0 + e) * cn / kn
    _apply(st, p, jj * n0, jj * n1, jj * n2, rcx, rcy, rcz, iw)
    return 1


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _kinetic(st, p, iw):
    # rigid kinetic energy ½ m v² + ½ Ω·I Ω with I = iw⁻¹ (use L = I Ω via solve-free form)
    v = st.vel[p]
    ke = 0.5 * st.mass[p] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    # Ω·IΩ: I Ω from the body inertia
    return ke + 0.5 * _omega_i_omega(st, p)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _omega_i_omega(st, p):
    q = st.quat[p]
    w, x, y, z = q[0], q[1], q[2], q[3]
    # body Ω = Rᵀ Ω
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r01 = 2.0 * (x * y - w * z)
    r02 = 2.0 * (x * z + w * y)
    r10 = 2.0 * (x * y + w * z)
    r11 = 1.0 - 2.0 * (x * x + z * z)
    r12 = 2.0 * (y * z - w * x)
    r20 = 2.0 * (x * z - w * y)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    o = st.omega[p]
    b0 = r00 * o[0] + r10 * o[1] + r20 * o[2]
    b1 = r01 * o[0] + r11 * o[1] + r21 * o[2]
    b2 = r02 * o[0] + r12 * o[1] + r22 * o[2]
    i = st.inertia[p]
    return b0 * (i[0, 0] * b0 + i[0, 1] * b1 + i[0, 2] * b2) + b1 * (i[1, 0] * b0 + i[1, 1] * b1 + i[1, 2] * b2) \
        + b2 * (i[2, 0] * b0 + i[2, 1] * b1 + i[2, 2] * b2)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _apply(st, p, j0, j1, j2, rcx, rcy, rcz, iw):
    m = st.mass[p]
    st.vel[p, 0] += j0 / m
    st.vel[p, 1] += j1 / m
    st.vel[p, 2] += j2 / m
    a0 = rcy * j2 - rcz * j1
    a1 = rcz * j0 - rcx * j2
    a2 = rcx * j1 - rcy * j0
    st.omega[p, 0] += iw[0, 0] * a0 + iw[0, 1] * a1 + iw[0, 2] * a2
    st.omega[p, 1] += iw[1, 0] * a0 + iw[1, 1] * a1 + iw[1, 2] * a2
    st.omega[p, 2] += iw[2, 0] * a0 + iw[2, 1] * a1 + iw[2, 2] * a2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _world_inverse_inertia(st, w, p, iw):
    # I_w⁻¹ = R I_b⁻¹ Rᵀ with R of the current orientation (w.rot[p] must hold it)
    rot = w.rot[p]
    ib = st.inertia_inv[p]
    for i in range(3):
        for j in range(3):
            s = 0.0
            for a in range(3):
                for b in range(3):
                    s += rot[i, a] * ib[a, b] * rot[j, b]
            iw[i, j] = s


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def state_row(st, p, x):
    """Grain p's state into the row x (x, v, q, Ω; NX): the start of an RK4 step, or the
    end of a free path (contacts/composites.py)."""
    for i in range(3):
        x[i] = st.pos[p, i]
        x[3 + i] = st.vel[p, i]
        x[10 + i] = st.omega[p, i]
    for i in range(4):
        x[6 + i] = st.quat[p, i]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _set_state(st, p, x):
    """Grain p's state from the row x (x, v, q, Ω; NX), its orientation normalised."""
    nq = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
    for i in range(3):
        st.pos[p, i] = x[i]
        st.vel[p, i] = x[3 + i]
        st.omega[p, i] = x[10 + i]
    for i in range(4):
        st.quat[p, i] = x[6 + i] / nq


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _rotated(q0, q1, q2, q3, r0, r1, r2):
    """The body vector r turned by the unit quaternion q (world frame)."""
    t0 = 2.0 * (q2 * r2 - q3 * r1)
    t1 = 2.0 * (q3 * r0 - q1 * r2)
    t2 = 2.0 * (q1 * r1 - q2 * r0)
    return (r0 + q0 * t0 + q2 * t2 - q3 * t1, r1 + q0 * t1 + q3 * t0 - q1 * t2,
            r2 + q0 * t2 + q1 * t1 - q2 * t0)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def component_at(st, k, x):
    """Centre and velocity (world) of component k for the grain state in the row x (x, v, q, Ω)."""
    rx, ry, rz = _rotated(x[6], x[7], x[8], x[9], st.r_body[k, 0], st.r_body[k, 1], st.r_body[k, 2])
    return ((x[0] + rx, x[1] + ry, x[2] + rz),
            (x[3] + x[11] * rz - x[12] * ry, x[4] + x[12] * rx - x[10] * rz, x[5] + x[10] * ry - x[11] * rx))


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _bottom(st, k, x):
    """Height of component k's bottom above the bed top, and its vertical speed, for the
    grain state in the row x."""
    c, u = component_at(st, k, x)
    return c[1] - 0.5 * st.d_comp[k], u[1]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _bed_impact(f, coef, hc, st, w, p, t, dt, crossed, kb, bed, seed):
    """Rebound of grain p on the virtual bed at its lowest component kb (module docstring).
    ``crossed``: kb's bottom came down through the bed top in this step, else it touches
    it at the step's end (grazing). As for spheres (flight/spheres._bed_impact), second
    order: the hit is where kb's bottom, a cubic Hermite in time through its heights and
    vertical speeds at the step's ends (flight/path.py), reaches the bed top; the centre's
    position and velocity there are its Hermite path's, Ω linear between the ends, the
    orientation turned back from the end by Ω over the rest of the step; after the
    impulse the rest of the step is flown with the fluid forces (``flight_remainder``)."""
    x = w.x[p]
    state_row(st, p, x)
    s = 1.0
    if crossed:
        x0 = w.x0[p]
        h0, v0 = _bottom(st, kb, x0)
        h1, v1 = _bottom(st, kb, x)  # x: the end state
        s = first_below(h0, h1, v0, v1, dt, 0.0)
        for i in range(3):
            x[i], x[3 + i] = hermite_point(x0[i], st.pos[p, i], x0[3 + i], st.vel[p, i], s, dt)
            x[10 + i] = (1.0 - s) * x0[10 + i] + s * st.omega[p, i]
    back = (1.0 - s) * dt
    _rotate_quat(x, st.omega[p], -back)
    t_hit = t + s * dt
    low, kb = _lowest(st, w, p, x[0], x[1], x[2], x[6], x[7], x[8], x[9])
    x[1] -= low  # the lowest point exactly on the bed top at the hit
    # a re-touch within a step of the last contact (a grazing contact closed at the end of
    # one step, the crossing then found at the start of the next) is the same contact
    # episode: its impulse is applied, but it ends no jump (bed/jumps.py)
    close_jump(st, p, st.jump_t0[p], x[0] - st.jump_x0[p], st.jump_ymax[p], t_hit,
               bed[BED_MIN_JUMP_DURATION], bed[BED_MIN_JUMP_HEIGHT])
    st.jump_t0[p] = t_hit
    st.jump_x0[p] = x[0]
    _set_state(st, p, x)
    rot = w.rot[p]  # orientation at the hit (set by _lowest)
    rx = rot[0, 0] * st.r_body[kb, 0] + rot[0, 1] * st.r_body[kb, 1] + rot[0, 2] * st.r_body[kb, 2]
    ry = rot[1, 0] * st.r_body[kb, 0] + rot[1, 1] * st.r_body[kb, 1] + rot[1, 2] * st.r_body[kb, 2]
    rz = rot[2, 0] * st.r_body[kb, 0] + rot[2, 1] * st.r_body[kb, 1] + rot[2, 2] * st.r_body[kb, 2]
    o = st.omega[p]
    uc = w.vec[p]
    uc[0] = st.vel[p, 0] + o[1] * rz - o[2] * ry
    uc[1] = st.vel[p, 1] + o[2] * rx - o[0] * rz
    uc[2] = st.vel[p, 2] + o[0] * ry - o[1] * rx
    n = w.vec[p, 3:6]
    xi1, xi2 = uniform2(seed, p, st.impacts[p])
    virtual_bed_normal(uc, xi1, xi2, bed[2], n)
    iw = w.aug[p, 0:3, 0:3]
    _world_inverse_inertia(st, w, p, iw)
    rad = 0.5 * st.d_comp[kb]
    n0, n1, n2 = n[0], n[1], n[2]
    v0, v1, v2 = st.vel[p, 0], st.vel[p, 1], st.vel[p, 2]
    w0, w1, w2 = o[0], o[1], o[2]
    _impulse(st, p, rx - rad * n0, ry - rad * n1, rz - rad * n2, n0, n1, n2, bed[0], bed[1], iw)
    # second impact on the horizontal bed if the contact point still descends (bed.virtual.bed_rebound)
    cy = st.vel[p, 1] + st.omega[p, 2] * rx - st.omega[p, 0] * rz
    if cy < 0.0:
        _impulse(st, p, rx, ry - rad, rz, 0.0, 1.0, 0.0, bed[0], bed[1], iw)
    st.impacts[p] += 1
    if s < 1.0:
        flight_remainder(f, coef, hc, st, w, p, t_hit, back, st.vel[p, 0] - v0, st.vel[p, 1] - v1,
                         st.vel[p, 2] - v2, o[0] - w0, o[1] - w1, o[2] - w2)
        low, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], st.quat[p, 0], st.quat[p, 1],
                         st.quat[p, 2], st.quat[p, 3])
        if low < 0.0:
            st.pos[p, 1] -= low  # a weak rebound under gravity: no lower than the bed top
    low2, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], st.quat[p, 0], st.quat[p, 1],
                      st.quat[p, 2], st.quat[p, 3])
    st.jump_ymax[p] = max(low2, 0.0)
    st.fresh[p] = 0
    for k in range(st.cstart[p], st.cstart[p + 1]):
        history_mark_impact_at(st.hist_meta[k], 1.0 - s)  # the next step takes the slip step (physics/history.py)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def flight_remainder(f, coef, hc, st, w, p, t, h, dv0, dv1, dv2, dw0, dw1, dw2):
    """Grain p from its rebound at t to the step's end, t + h, by one RK4 step with its
    fluid forces (``_rk4_stages``); with ``forces.basset_impacts = "keep"`` the history
    held at the step's end (``st.hist_i``) and the impulse of each component's slip step
    Δu_k = Δv + ΔΩ × r_k over h, −c_k Δu_k · 2√h through the grain's mass matrix (as
    flight/spheres.flight_remainder); with "restart" none. Leaves the post-impulse state in
    ``w.x0[p]`` (the start of the path it flew)."""
    keep = coef[ON_BASSET] != 0.0 and hc.keep_impacts
    x0 = w.x0[p]
    state_row(st, p, x0)
    _sample_grain(f, coef, st, w, p, x0, t)
    if not _rk4_stages(f, coef, st, w, p, t, h, keep):
        return
    if keep:
        _quat_to_matrix(st.quat[p, 0], st.quat[p, 1], st.quat[p, 2], st.quat[p, 3], w.rot[p])
        rot = w.rot[p]
        rhs = w.ft[p]
        for i in range(6):
            rhs[i] = 0.0
        scale = 2.0 * math.sqrt(h) / math.sqrt(coef[RE_STAR])
        for k in range(st.cstart[p], st.cstart[p + 1]):
            rx, ry, rz = _rotated(st.quat[p, 0], st.quat[p, 1], st.quat[p, 2], st.quat[p, 3], st.r_body[k, 0],
                                  st.r_body[k, 1], st.r_body[k, 2])
            e0 = dv0 + dw1 * rz - dw2 * ry
            e1 = dv1 + dw2 * rx - dw0 * rz
            e2 = dv2 + dw0 * ry - dw1 * rx
            _subtract_wrench(rhs, rot, st.r_body[k], 1.5 * SQRT_PI * st.d_comp[k] ** 2 * scale, e0, e1, e2)
        aug = w.aug[p]
        mm = st.mmat[p]
        for i in range(6):
            for j in range(6):
                aug[i, j] = mm[i, j]
            aug[i, 6] = rhs[i]
        vb = w.vec[p]
        _solve6(aug, vb)
        for i in range(3):
            st.vel[p, i] += rot[i, 0] * vb[0] + rot[i, 1] * vb[1] + rot[i, 2] * vb[2]
            st.omega[p, i] += rot[i, 0] * vb[3] + rot[i, 1] * vb[4] + rot[i, 2] * vb[5]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def _rk4_stages(f, coef, st, w, p, t, dt, with_basset):
    """RK4 of grain p over dt from the state in ``w.x0[p]``, its fluid there already
    sampled, the history held (``with_basset``); the result into st (orientation
    normalised). Returns False (and marks the grain) when it is not finite."""
    x0 = w.x0[p]
    x = w.x[p]
    k = w.k[p]
    _rhs(coef, st, w, p, x0, k[0], with_basset)
    for stage in range(1, 4):
        h = 0.5 * dt if stage < 3 else dt
        for i in range(NX):
            x[i] = x0[i] + h * k[stage - 1, i]
        _sample_grain(f, coef, st, w, p, x, t + h)
        _rhs(coef, st, w, p, x, k[stage], with_basset)
    for i in range(NX):
        x[i] = x0[i] + dt / 6.0 * (k[0, i] + 2.0 * k[1, i] + 2.0 * k[2, i] + k[3, i])
    _set_state(st, p, x)
    for i in range(NX):
        if not np.isfinite(x[i]):
            st.status[p] = NOT_FINITE
            return False
    return True


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def step_grain(f, coef, bed, seed, st, w, hc, p, t, dt):
    """One RK4 step of composite grain p from t to t + dt, with bed impacts."""
    with_basset = coef[ON_BASSET] != 0.0
    x0 = w.x0[p]
    state_row(st, p, x0)
    if st.fresh[p] == 0:
        _sample_grain(f, coef, st, w, p, x0, t)
    else:
        # samples are current; only the rotation matrix and offsets are needed
        _quat_to_matrix(x0[6], x0[7], x0[8], x0[9], w.rot[p])
        rot = w.rot[p]
        for kk in range(st.cstart[p], st.cstart[p + 1]):
            for i in range(3):
                w.rw[kk, i] = rot[i, 0] * st.r_body[kk, 0] + rot[i, 1] * st.r_body[kk, 1] \
                    + rot[i, 2] * st.r_body[kk, 2]
    if with_basset and st.hist_meta[st.cstart[p], META_COUNT] <= 0:
        # release, or the step after an impact: each component's slip step kept, or a restart
        ox, oy, oz = x0[10], x0[11], x0[12]
        for kk in range(st.cstart[p], st.cstart[p + 1]):
            rx, ry, rz = w.rw[kk, 0], w.rw[kk, 1], w.rw[kk, 2]
            sl = w.ft[p, 0:3]
            sl[0] = x0[3] + oy * rz - oz * ry - w.uf[kk, 0]
            sl[1] = x0[4] + oz * rx - ox * rz - w.uf[kk, 1]
            sl[2] = x0[5] + ox * ry - oy * rx - w.uf[kk, 2]
            history_start_step(sl, st.hist_slip[kk], st.hist_meta[kk], st.hist_tail[kk], st.hist_i[kk], dt,
                               hc.keep_impacts, hc.tail_time, hc.tail_weight)
    if not _rk4_stages(f, coef, st, w, p, t, dt, with_basset):
        return
    x = w.x[p]
    _sample_grain(f, coef, st, w, p, x, t + dt)  # next step's stage 1; closes the history
    for i in range(4):
        x[6 + i] = st.quat[p, i]
    _quat_to_matrix(x[6], x[7], x[8], x[9], w.rot[p])
    st.fresh[p] = 1
    if with_basset:
        _basset_end_step(coef, st, w, hc, p, dt)
    if bed.shape[0] > BED_MODEL and bed[BED_MODEL] != 0.0:
        return  # the bed acts after the move (bed/packed_composites.py, virtual_bed_pass)
    virtual_bed_check(f, coef, bed, seed, st, w, hc, p, t, dt)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, error_model="numpy")
def virtual_bed_check(f, coef, bed, seed, st, w, hc, p, t, dt):
    """The virtual bed for grain p at the end of its free-flight step from the row
    ``w.x0[p]`` to its state (module docstring, "Bed"): a rebound when its lowest point is
    below the bed top, else its highest point on the path kept for the jump height.
    Returns whether it touched the bed."""
    x0 = w.x0[p]
    y_new, kb = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], st.quat[p, 0], st.quat[p, 1],
                        st.quat[p, 2], st.quat[p, 3])
    if y_new < 0.0:
        rot = w.rot[p]
        rx = rot[0, 0] * st.r_body[kb, 0] + rot[0, 1] * st.r_body[kb, 1] + rot[0, 2] * st.r_body[kb, 2]
        rz = rot[2, 0] * st.r_body[kb, 0] + rot[2, 1] * st.r_body[kb, 1] + rot[2, 2] * st.r_body[kb, 2]
        # vertical velocity of the lowest component's centre
        vy = st.vel[p, 1] + st.omega[p, 2] * rx - st.omega[p, 0] * rz
        # crossed: this component's bottom started the step on or above the bed top (another
        # component may have been on it: a tumbling grain's second contact)
        h0, _ = _bottom(st, kb, x0)
        if vy < 0.0 and h0 >= 0.0:
            _bed_impact(f, coef, hc, st, w, p, t, dt, True, kb, bed, seed)
        else:
            # grazing contact without a descending crossing: keep the grain on the bed
            st.pos[p, 1] -= y_new
            st.fresh[p] = 0
            if vy < 0.0:
                _bed_impact(f, coef, hc, st, w, p, t, dt, False, kb, bed, seed)
        return True
    st.jump_ymax[p] = max(st.jump_ymax[p], y_new, highest_on_path(st, w, p, dt))
    return False


# A parallel pass over the grains runs over chunks of CHUNK grains; each chunk reads the
# state as tuples again (grains/refs.as_tuple), as the hot loops must.
CHUNK = 16


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def chunk_range(c, n):
    """Grains lo..hi-1 of chunk c of n grains, as int64 whatever the prange index's type
    (int64 where the loop is typed, uint64 inside the parallel kernel): the per-grain
    functions compile once, not twice."""
    lo = np.int64(c) * CHUNK
    return lo, min(n, lo + CHUNK)


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def free_flight_pass(f, coef, bed, seed, st, w, hc, t, dt, top):
    """step_grain (RK4 + bed) for every grain that is OK, in parallel; counts the grains
    above the flow's top (``top``)."""
    above_top, pos, status = st.above_top, st.pos, st.status  # writes in a prange body: not through a tuple
    sr, wr = ClusterStateRef(*st), ClusterWorkRef(*w)  # one pointer each into the loop (grains/refs.py)
    n = pos.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, wv = as_tuple(sr, ClusterState), as_tuple(wr, ClusterWork)
        for p in range(*chunk_range(c, n)):
            if status[p] != OK:
                continue
            step_grain(f, coef, bed, seed, sv, wv, hc, p, t, dt)
            if pos[p, 1] > top:
                above_top[p] += 1


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def virtual_bed_pass(f, coef, bed, seed, st, w, hc, t, dt, step, moved, last_contact):
    """The virtual bed after the contact phase (bed[BED_MODEL] = BED_VIRTUAL_AFTER): the
    rebound of ``virtual_bed_check`` for every grain that is OK and was not moved by the
    contact phase (``moved[p]`` = 0: it keeps its free-flight path of the step, from
    ``w.x0[p]``); a grain that touched the bed gets ``last_contact[p]`` = ``step``, as a
    soft bed contact in that phase would."""
    status = st.status
    sr, wr = ClusterStateRef(*st), ClusterWorkRef(*w)
    n = status.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, wv = as_tuple(sr, ClusterState), as_tuple(wr, ClusterWork)
        for p in range(*chunk_range(c, n)):
            if status[p] != OK or moved[p] != 0:
                continue
            if virtual_bed_check(f, coef, bed, seed, sv, wv, hc, p, t, dt):
                last_contact[p] = step


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy")
def advance_clusters(f, coef, bed, seed, st, w, hc, t0, dt, n_steps, top):
    """Advance all composite grains n_steps from t0 (as tests/peers/sphere_advance.advance): stops early
    when a grain is not finite or a jump buffer is full; returns the steps done."""
    n = st.pos.shape[0]
    cap = st.jump_buf.shape[1]
    k0 = round(t0 / dt)  # the global index of the first step (t0 is always k0 * dt)
    for s in range(n_steps):
        t = (k0 + s) * dt  # from the global step index: never from where a chunk began
        free_flight_pass(f, coef, bed, seed, st, w, hc, t, dt, top)
        stop = False
        for p in range(n):
            if st.status[p] != OK or st.jump_buf_n[p] >= cap:
                stop = True
                break
        if stop:
            return s + 1
    return n_steps
