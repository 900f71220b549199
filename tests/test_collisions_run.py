"""Grain contacts and the packed bed inside the run loop (issue 4; contacts/phase.py, engine/stepping.py,
bed/packed.py). The binary collision physics itself is tested in test_contacts.py; here:
the contact phase reproduces contacts.pairs.advance_granular on straight free-flight paths, runs
with contacts keep overlaps small and grains above the bed, contacts change the result,
and the packed bed rebounds along the real normal and is never penetrated."""
import math

import numpy as np
import pytest
from test_integrator import uniform_flow

from saltation.bed.packed import BED_CENTRE_Y, hexagonal_layer, make_packed_bed, packed_bed_check_particle
from saltation.bed.virtual import bed_parameters
from saltation.contacts import pairs as K
from saltation.contacts.phase import (
    CLOCK_ENGAGE,
    CLOCK_GATHER,
    CLOCK_LIST,
    CLOCK_SCATTER,
    CLOCK_SUBSTEPS,
    N_CLOCKS,
    empty_substep_set,
    make_bed_context,
    make_contact_phase,
    soft_contact_phase,
)
from saltation.engine.simulation import run
from saltation.flight.spheres import make_state, make_workspace
from saltation.physics.forces import make_coefficients
from saltation.physics.history import make_history_coefficients

D = 0.69e-3


def small_case(model="soft", n=400, duration=0.15, bed="virtual", seed=3, source="loglaw", **extra):
    """A small, dense loglaw case: 400 grains in 40 d × 20 d × 6 d (C ≈ 4.4 %)."""
    case = {
        "particle": {"diameter": D, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1e-6},
        "flow": {"source": source, "tau_ratio": 1.79},
        "bed": {"model": bed},
        "collisions": {"model": model},
        "run": {"n_particles": n, "duration": duration, "dt_particle": 0.02, "seed": seed,
                "domain": [40 * D, 20 * D, 6 * D], "threads": 1},
        "output": {"tracks": True, "vtk": False, "tracks_interval": 0.02 * 0.0273 * 5},
    }
    for key, value in extra.items():
        table, name = key.split(".")
        case.setdefault(table, {})[name] = value
    return case


# ----------------------------------------------------------------------------- kernel


def _straight_steps(st, model, skin, dt, n_sub, steps, after_step=None, profile=False):
    """``steps`` steps of free flight without forces (straight paths) and the soft contact
    phase, virtual bed, in a 12 × 8 × 12 d box; ``after_step(ph)`` after each. Returns the
    ContactList and the ContactPhase."""
    n = st.pos.shape[0]
    ws = make_workspace(n)
    cl = K.make_contact_list(st.pos, (12.0, 8.0, 12.0), (True, False, True), 1.0, skin)
    ph = make_contact_phase(n, profile=profile)
    bc = make_bed_context(n, False, make_packed_bed(3.0, 3.0), 0.65, 0.1, 0.5, model.kn, model.kt, 0,
                          np.full(n, -2, np.int64))
    cs = empty_substep_set()
    for s in range(steps):
        ws.x0[:, 0:3] = st.pos
        ws.x0[:, 3:6] = st.vel
        ws.x0[:, 6:9] = st.spin
        st.pos[:] += dt * st.vel
        cl, cs = soft_contact_phase(st, ws.x0, model, cl, ph, bc, s * dt, s, dt, n_sub, cs)
        if after_step is not None:
            after_step(ph)
    return cl, ph


def test_contact_phase_reproduces_velocity_verlet_on_straight_paths():
    """No fluid force: the free flight is a straight line, so the contact phase (Hermite
    path + deviation) must give what contacts.pairs.advance_granular gives for the same
    sub-steps — same restitution, momentum, spins (the duplicated force arithmetic)."""
    model = K.make_contact_model(5e5, 0.65, 0.3)
    dt, n_sub, steps = 0.02, 128, 6
    pos0 = np.array([[5.0, 3.0, 5.0], [5.0 + 1.03, 3.2, 5.1]])
    vel0 = np.array([[2.0, 0.0, 0.5], [-1.5, -0.3, 0.0]])
    spin0 = np.array([[0.0, 0.0, -1.0], [0.3, 0.0, 0.0]])
    box = (12.0, 8.0, 12.0)
    # reference: velocity Verlet with contacts only
    p_ref, v_ref, w_ref = pos0.copy(), vel0.copy(), spin0.copy()
    cl_ref = K.make_contact_list(p_ref, box, (True, False, True), 1.0, 0.5)
    K.advance_granular(p_ref, v_ref, w_ref, np.zeros((2, 3)), np.zeros((2, 3)), model, cl_ref, dt / n_sub, steps * n_sub)
    # the run loop's contact phase, step by step
    st = make_state(pos0, vel0, spin0, 0.0, 4)
    ws = make_workspace(2)
    cl = K.make_contact_list(st.pos, box, (True, False, True), 1.0, 0.5)
    ph = make_contact_phase(2)
    pb = make_packed_bed(3.0, 3.0)
    bc = make_bed_context(2, False, pb, 0.65, 0.1, 0.5, model.kn, model.kt, 0, np.full(2, -2, np.int64))
    cs = empty_substep_set()
    for s in range(steps):
        ws.x0[:, 0:3] = st.pos
        ws.x0[:, 3:6] = st.vel
        ws.x0[:, 6:9] = st.spin
        st.pos[:] += dt * st.vel  # free flight without forces
        cl, cs = soft_contact_phase(st, ws.x0, model, cl, ph, bc, s * dt, s, dt, n_sub, cs)
    assert cl.collisions.sum() == 2 and cl_ref.collisions.sum() == 2
    np.testing.assert_allclose(st.pos, p_ref, atol=1e-9)
    np.testing.assert_allclose(st.vel, v_ref, atol=1e-8)
    np.testing.assert_allclose(st.spin, w_ref, atol=1e-7)
    # and the collision did something: the pair now separates
    assert np.dot(st.vel[1] - st.vel[0], st.pos[1] - st.pos[0]) > 0


def test_a_grain_not_engaged_is_woken_when_a_deflected_grain_hits_it():
    """Grain 2 sits still out of reach of the undeflected paths; grain 0 is knocked
    towards it by grain 1 within the step: the wake-up must give a real contact (both
    grains feel it, momentum conserved)."""
    model = K.make_contact_model(5e5, 0.9, 0.0)
    dt, n_sub = 0.02, 128
    pos0 = np.array([[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0], [5.0 + 1.0 + 0.1, 3.0, 5.0]])
    vel0 = np.array([[0.0, 0.0, 0.0], [12.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    st = make_state(pos0, vel0, np.zeros((3, 3)), 0.0, 4)
    p_total = st.vel.sum(axis=0).copy()
    cl, ph = _straight_steps(st, model, 0.6, dt, n_sub, 3)
    assert ph.counters[2] >= 1  # a wake-up happened
    assert st.vel[2, 0] > 1.0  # grain 2 was hit
    np.testing.assert_allclose(st.vel.sum(axis=0), p_total, atol=1e-9)


def test_the_list_is_not_rebuilt_for_a_drift_common_to_all_grains():
    """The list's validity test takes out one displacement common to all grains (phase._drift):
    a layer moving as a whole by more than half the skin per step keeps its list, grains
    moving across each other by as much do not, and both find the same contact as a list rebuilt
    every step would (the pair at 1.02 d closing at 0.05 d per step). Fails when the
    common drift is not taken out (every step rebuilds) or is taken out of relative
    motion."""
    from saltation.contacts.phase import LIST_REBUILDS, LIST_ROOM

    model = K.make_contact_model(5e5, 0.9, 0.0)
    skin = 0.8
    step = 0.5 * skin  # per step, more than the skin's half less the room for deviations
    assert step > 0.5 * skin - LIST_ROOM
    lattice = np.array([[x, y, z] for x in (1.5, 4.5, 7.5, 10.5) for y in (2.0, 5.0) for z in (1.5, 4.5, 7.5, 10.5)])
    pair = np.array([[6.0, 3.5, 6.0], [6.0 + 1.02, 3.5, 6.0]])
    pos0 = np.vstack([lattice, pair])
    n = len(pos0)
    closing = np.zeros((n, 3))
    dt = 0.02
    closing[-1, 0] = -0.05 / dt  # the pair closes by 0.05 d per step

    def rebuilds(vel, steps=4):
        st = make_state(pos0.copy(), vel.copy(), np.zeros((n, 3)), 0.0, 4)
        cl, ph = _straight_steps(st, model, skin, dt, 128, steps)
        return int(ph.counters[LIST_REBUILDS]), int(cl.collisions.sum())

    together = np.tile([step / dt, 0.0, 0.0], (n, 1)) + closing
    apart = together.copy()
    apart[: len(lattice) // 2] = [0.0, 0.0, step / dt]  # half the lattice across (no collisions in 4 steps)
    assert rebuilds(together) == (0, 2)
    moved, collided = rebuilds(apart)
    assert moved >= 2 and collided == 2


def test_profiling_times_the_parts_and_changes_nothing():
    """ContactPhase.clocks (bench_dense's split of the phase): with profiling on, every
    part that ran has its time and the grains end in the same bits as without."""
    model = K.make_contact_model(5e5, 0.9, 0.0)
    ends = {}
    for profile in (False, True):
        pos0 = np.array([[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0], [5.0 + 1.0 + 0.1, 3.0, 5.0]])
        vel0 = np.array([[0.0, 0.0, 0.0], [12.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
        st = make_state(pos0, vel0, np.zeros((3, 3)), 0.0, 4)
        _, ph = _straight_steps(st, model, 0.6, 0.02, 128, 3, profile=profile)
        ends[profile] = (st.pos.copy(), st.vel.copy())
        if not profile:
            assert ph.clocks.shape == (0,)
    assert ph.clocks.shape == (N_CLOCKS,)
    ran = [CLOCK_LIST, CLOCK_ENGAGE, CLOCK_GATHER, CLOCK_SUBSTEPS, CLOCK_SCATTER]
    assert (ph.clocks[ran] > 0.0).all() and (ph.clocks >= 0.0).all()
    np.testing.assert_array_equal(ends[True][0], ends[False][0])
    np.testing.assert_array_equal(ends[True][1], ends[False][1])


def test_the_jump_height_follows_a_grain_whether_or_not_the_contact_phase_took_it():
    """Two grains rising side by side, 0.002 d apart and separating: near enough to be
    taken into the contact phase by its coarse test, never touching. The bed pass (here:
    its jump-height update) skips the grains the phase took, so the phase must keep their
    jump's highest point; before issue 19 it kept it only for grains that touched
    something, and a grain sub-stepped through its apex kept its last bed contact's."""
    model = K.make_contact_model(5e5, 0.65, 0.3)
    dt, n_sub = 0.02, 128
    pos0 = np.array([[5.0, 3.0, 5.0], [5.0 + 1.002, 3.0, 5.0]])
    vel0 = np.array([[-0.1, 2.0, 0.0], [0.1, 2.0, 0.0]])
    st = make_state(pos0, vel0, np.zeros((2, 3)), 0.0, 4)
    st.jump_ymax[:] = 3.0

    def after_step(ph):
        for p in range(2):
            if ph.active[p] == 0:  # what the bed pass does for the grains it does not skip
                st.jump_ymax[p] = max(st.jump_ymax[p], st.pos[p, 1])
        np.testing.assert_array_equal(st.jump_ymax, st.pos[:, 1])

    cl, _ = _straight_steps(st, model, 0.5, dt, n_sub, 3, after_step)
    assert cl.collisions.sum() == 0


# ----------------------------------------------------------------------------- runs


@pytest.fixture(scope="module")
def soft_and_off(tmp_path_factory):
    base = tmp_path_factory.mktemp("runs")
    soft = run(small_case("soft"), out=base / "soft", progress=False)
    off = run(small_case("off"), out=base / "off", progress=False)
    return soft, off


def test_dense_soft_run_collides_with_small_overlaps_and_stays_above_the_bed(soft_and_off):
    soft, _ = soft_and_off
    s = soft.summary
    c = s["collisions"]
    assert 0.03 < s["concentration"] < 0.05
    assert c["particle_particle"] > 0 and c["per_particle"] > 0
    per = soft.directory / "particles.parquet"
    import pandas as pd

    table = pd.read_parquet(per)
    assert table["collisions"].sum() == 2 * c["particle_particle"]
    # SPEC §5: overlaps ≲ 1 % d, contacts resolved in ≳ 20 sub-steps
    assert c["overlap"]["max_over_d"] < 0.01
    assert 0.0 < c["overlap"]["mean_over_d"] < 0.005
    assert c["overlap"]["contact_duration_substeps_mean"] >= 19.0
    assert c["contact_phase"]["missed_contacts"] == 0
    # no grain below the bed: centre at most the largest soft-bed overlap under d/2
    assert soft.tracks["y"].min() > 0.5 - 0.01
    t = s["timing"]
    assert t["particle_collisions_s"] > 0 and t["bed_s"] > 0 and t["free_flight_s"] > 0
    assert t["free_flight_s"] + t["particle_collisions_s"] + t["bed_s"] <= t["kernel_s"] * 1.001


def test_contacts_change_the_result(soft_and_off):
    soft, off = soft_and_off
    assert off.summary["collisions"]["particle_particle"] == 0
    a = soft.tracks.sort_values(["t", "particle"])
    b = off.tracks.sort_values(["t", "particle"])
    assert len(a) == len(b)
    last = a["t"].max()
    diff = np.abs(a[a.t == last][["x", "y", "z"]].to_numpy() - b[b.t == last][["x", "y", "z"]].to_numpy())
    assert np.mean(diff.max(axis=1) > 0.1) > 0.2  # many grains ended elsewhere


def test_results_do_not_depend_on_the_neighbour_skin(tmp_path):
    """The skin decides when the list is rebuilt and how long its rows are, not the physics:
    rows are in partner-id order (contacts/cells.build_neighbour_list), so every force sum
    is the same whenever the list was built. Fails when rows follow the cells' order."""
    import pandas as pd

    # the regression set's dense layer (3.94 % on the LES): grains with three and more
    # contacts at once, whose force sums depend on the order of their terms
    case = small_case("soft", n=None, duration=0.25, source="les", seed=5, **{"run.concentration": 0.0394})
    del case["run"]["n_particles"]
    case["run"]["domain"] = [0.008, 0.004, 0.028]
    case["output"]["tracks_interval"] = 0.25
    soft = run(case, out=tmp_path / "default", progress=False)
    case["collisions"]["skin"] = 0.9
    wide = run(case, out=tmp_path / "wide", progress=False)
    a, b = soft.summary["collisions"], wide.summary["collisions"]
    assert a["soft"]["skin_d"] != b["soft"]["skin_d"]
    assert a["contact_phase"]["list_builds_total"] != b["contact_phase"]["list_builds_total"]
    pd.testing.assert_frame_equal(soft.tracks, wide.tracks, check_exact=True)
    for name in ("jumps.parquet", "particles.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(soft.directory / name), pd.read_parquet(wide.directory / name),
                                      check_exact=True)
    assert a["particle_particle"] == b["particle_particle"] and a["overlap"] == b["overlap"]


def test_dilute_results_do_not_depend_on_the_neighbour_skin(tmp_path):
    """The README's main job (300 grains, soft contacts, dilute) for 2.5 s with two skins
    gives the same bits. Which grains are candidates (and so have the soft bed rather than
    the hard one) must not depend on which extra pairs the list holds: a grain hitting the
    bed counts a margin of three reaches, beyond the list's guarantee (contacts/phase.py,
    _engage_unlisted). Fails when the engagement test looks only at the list's rows: the
    tracks part at 2.0 s on the development machine."""
    from pathlib import Path

    import pandas as pd

    default = Path(__file__).resolve().parents[1] / "cases" / "default.toml"
    runs = {}
    for skin in (None, 0.9):
        extra = {} if skin is None else {"collisions.skin": skin}
        runs[skin] = run(default, out=tmp_path / str(skin), progress=False, **{"run.duration": 2.5,
                                                                               "output.vtk": False}, **extra)
    a, b = runs[None], runs[0.9]
    assert a.summary["collisions"]["soft"]["skin_d"] != b.summary["collisions"]["soft"]["skin_d"]
    assert a.summary["collisions"]["particle_particle"] > 1000  # contacts happen
    pd.testing.assert_frame_equal(a.tracks, b.tracks, check_exact=True)
    for name in ("jumps.parquet", "particles.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(a.directory / name), pd.read_parquet(b.directory / name),
                                      check_exact=True)


def test_one_block_after_a_giant_block_gives_the_same_bits(tmp_path):
    """Blocks never change a result, only what the phase costs ("Blocks"): when one block
    holds most members the next steps run as one block. The dense LES layer (3.94 %) run
    with blocks tried in every step (``ph.unblocked[1] = 0``) and with the default ends in
    the same bits, the default with fewer blocks. Fails when the rule is not applied or
    when running as one block changes a result."""
    import pandas as pd

    from saltation.case.schema import load_case, resolve_domain
    from saltation.contacts.phase import BLOCKS, SUBSTEPPED, UNBLOCKED_STEPS
    from saltation.engine.simulation import Simulation, _les_box_m, open_flow

    case = small_case("soft", n=None, duration=0.1, source="les", seed=5, **{"run.concentration": 0.0394})
    del case["run"]["n_particles"]
    case["run"]["domain"] = [0.032, 0.004, 0.028]  # ~800 grains: more members than one block holds
    case["output"]["tracks_interval"] = 0.1
    c = load_case(case)
    ds = open_flow(c)
    c = resolve_domain(c, _les_box_m(ds, c))
    runs = {}
    for steps in (0, UNBLOCKED_STEPS):
        sim = Simulation(c, ds, tmp_path / f"u{steps}", progress=False)
        sim.stepper.ph.unblocked[1] = steps
        result = sim.run()
        runs[steps] = (result, int(sim.stepper.ph.counters[BLOCKS]), int(sim.stepper.ph.counters[SUBSTEPPED]))
    (always, blocks_always, _), (default, blocks_default, substepped) = runs[0], runs[UNBLOCKED_STEPS]
    assert substepped > 0 and blocks_default < blocks_always
    pd.testing.assert_frame_equal(always.tracks, default.tracks, check_exact=True)
    for name in ("jumps.parquet", "particles.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(always.directory / name),
                                      pd.read_parquet(default.directory / name), check_exact=True)


def test_hard_sphere_run_collides(tmp_path):
    res = run(small_case("hard", duration=0.08), out=tmp_path / "hard", progress=False)
    c = res.summary["collisions"]
    assert c["model"] == "hard" and c["particle_particle"] > 0
    assert np.isfinite(res.tracks[["x", "y", "z", "u", "v", "w"]].to_numpy()).all()


# ----------------------------------------------------------------------------- packed bed


def test_hexagonal_layer_is_close_packed_and_periodic():
    centres, sx, sz = hexagonal_layer(20.0, 10.0)
    assert abs(sx - 1.0) < 0.05 and abs(sz - math.sqrt(3) / 2) < 0.05
    assert np.all(centres[:, 1] == BED_CENTRE_Y)
    # nearest-neighbour distance (minimum image) ≈ d everywhere, six neighbours each
    d = centres[:, None, [0, 2]] - centres[None, :, [0, 2]]
    d[..., 0] -= 20.0 * np.round(d[..., 0] / 20.0)
    d[..., 1] -= 10.0 * np.round(d[..., 1] / 10.0)
    r = np.sqrt((d ** 2).sum(-1)) + np.eye(len(centres)) * 9
    assert np.all(np.abs(r.min(axis=1) - 1.0) < 0.06)
    assert np.all((r < 1.1).sum(axis=1) == 6)


def drop_on_bed(offset_x, offset_z=0.0, speed=3.0, e=1.0, f=0.0):
    """One grain falling vertically onto bed sphere 0's top, offset sideways, in still water;
    one step whose path (a straight line: the same velocity at both ends) reaches the
    sphere 60 % into the step."""
    pb = make_packed_bed(20.0, 10.0)
    k = int(np.argmin(np.abs(pb.centres[:, 0] - 10.0) + np.abs(pb.centres[:, 2] - 5.0)))
    c = pb.centres[k]
    x_hit = np.array([c[0] + offset_x, 0.0, c[2] + offset_z])
    x_hit[1] = c[1] + math.sqrt(1.0 - offset_x ** 2 - offset_z ** 2)
    dt = 0.02
    vel = np.array([0.0, -speed, 0.0])
    pos = x_hit + vel * (0.4 * dt)  # the free flight's end, 40 % of the step after the hit
    st = make_state(pos[None, :], vel[None, :], np.zeros((1, 3)), 0.0, 4)
    st.jump_t0[0], st.jump_ymax[0] = -3.0, 2.0  # in flight since 3 d/u*, up to 1.5 d: a hop ends here
    ws = make_workspace(1)
    ws.x0[0, :3] = pos - vel * dt
    ws.x0[0, 3:6] = vel
    last = np.full(1, -2, np.int64)
    coef = make_coefficients(tau_star=0.0573, re_star=17.5, lift=False, magnus=False, added_mass=False,
                             fluid_acceleration=False, basset=False, spin=False)
    hc = make_history_coefficients(dt, 4)
    hits = packed_bed_check_particle(uniform_flow().arrays, coef, hc, st, ws, 0, 0.0, dt, 10,
                                     bed_parameters(e, f, 0.5), pb, last)
    return hits, st, ws, (x_hit - c), pb


def test_grain_dropped_off_centre_rebounds_along_the_real_normal():
    hits, st, ws, n, _ = drop_on_bed(0.3)
    assert hits == 1
    n = n / np.linalg.norm(n)
    np.testing.assert_allclose(ws.normal[0], n, atol=1e-9)  # the contact found where the path met the sphere
    assert abs(st.jump_t0[0] - 0.6 * 0.02) < 1e-9
    v_in = np.array([0.0, -3.0, 0.0])
    v_expected = v_in - 2.0 * np.dot(v_in, n) * n  # e = 1, f = 0: mirror about the tangent plane
    # then weight and drag in still water for the rest of the step, 0.008 d/u*: weight alone
    # takes 0.053 u* off v here (measured: 0.063 with the drag)
    np.testing.assert_allclose(st.vel[0], v_expected, atol=0.1)
    assert np.abs(st.vel[0] - v_expected).max() > 1e-4  # (the fluid forces did act)
    assert st.vel[0, 0] > 0.5  # deflected sideways, away from the sphere's top
    hits, st2, _, _, _ = drop_on_bed(-0.3)
    assert st2.vel[0, 0] < -0.5
    hits, st3, _, _, _ = drop_on_bed(0.0)
    assert abs(st3.vel[0, 0]) < 1e-12 and st3.vel[0, 1] > 0  # head-on: straight back up
    assert st.jump_count[0] == 1 and st.impacts[0] == 1


def bed_clearance(pos, pb):
    """Smallest centre distance of each grain to any bed sphere (minimum image in x, z)."""
    lx, lz = pb.box[0], pb.box[2]
    d = pos[:, None, :] - pb.centres[None, :, :]
    d[..., 0] -= lx * np.round(d[..., 0] / lx)
    d[..., 2] -= lz * np.round(d[..., 2] / lz)
    return np.sqrt((d ** 2).sum(-1)).min(axis=1)


@pytest.mark.parametrize("model", ["off", "soft"])
def test_grains_never_penetrate_the_packed_bed(tmp_path, model):
    case = small_case(model, n=120, duration=0.12, bed="packed")
    res = run(case, out=tmp_path / model, progress=False)
    tr = res.tracks
    pb = make_packed_bed(40.0, 20.0)
    clear = bed_clearance(tr[["x", "y", "z"]].to_numpy(), pb)
    tol = 1e-9 if model == "off" else 0.01  # soft bed contacts overlap by ≲ 1 % d
    assert clear.min() > 1.0 - tol
    assert res.summary["collisions"]["bed"] > 0 and res.summary["jumps"]["recorded"] > 0


def _skin_run(base_skin, steps=40, slow_from=10):
    """A layer of grains on straight paths (no forces) in a 12 × 8 × 12 d box, one of them
    fast (0.5 d per step) until ``slow_from``; the list's cells allow twice the 0.5 d skin,
    as stepping.Stepper makes them. Returns the state, the skin after each step and the
    phase's counters."""
    model = K.make_contact_model(5e5, 0.65, 0.3)
    dt, n_sub = 0.02, 128
    xs = np.arange(6) * 2.0 + 0.5
    pos = np.array([[x, y, z] for x in xs for z in xs for y in (3.0, 4.5)])
    n = len(pos)
    rng = np.random.default_rng(1)
    vel = np.zeros((n, 3))
    vel[:, 0::2] = rng.normal(0.0, 3.0, (n, 2))
    vel[0] = (25.0, 0.0, 0.0)
    st = make_state(pos, vel, np.zeros((n, 3)), 0.0, 4)
    ws = make_workspace(n)
    box = (12.0, 8.0, 12.0)
    cl = K.make_contact_list(st.pos, box, (True, False, True), 1.0, 1.0)
    cl = cl._replace(cutoff=1.5, skin=0.5)
    ph = make_contact_phase(n)
    bc = make_bed_context(n, False, make_packed_bed(3.0, 3.0), 0.65, 0.1, 0.5, model.kn, model.kt, 0,
                          np.full(n, -2, np.int64))
    cs = empty_substep_set()
    skins = []
    for s in range(steps):
        if s == slow_from:
            st.vel[0, 0] = 3.0
        ws.x0[:, 0:3] = st.pos
        ws.x0[:, 3:6] = st.vel
        ws.x0[:, 6:9] = st.spin
        st.pos[:] += dt * st.vel
        cl, cs = soft_contact_phase(st, ws.x0, model, cl, ph, bc, s * dt, s, dt, n_sub, cs, 1, base_skin)
        skins.append(cl.skin)
    return st, np.array(skins), ph.counters.copy(), cl.collisions.sum()


def test_a_widened_skin_narrows_back_with_the_same_bits():
    """A fast grain widens the list's skin; once it has slowed down, the next rebuild
    narrows the skin back to the case's (base_skin), which only changes how long the rows
    are: the same bits as keeping the wide skin. Fails if the skin stays wide, or if
    narrowing misses a contact (a different state, or a missed one counted)."""
    from saltation.contacts.phase import MISSED, OVERRUNS

    slow = 10
    narrow, skins_n, cnt_n, coll_n = _skin_run(0.5)
    wide, skins_w, cnt_w, coll_w = _skin_run(0.0)
    # widened for the fast grain (to 1 d, as far as the cells allow)
    assert skins_n[0] == skins_w[0] == 1.0
    assert np.all(skins_w == 1.0)  # without a base skin it stays wide
    assert np.all(skins_n[:slow] == 1.0) and skins_n[-1] == 0.5  # with one it narrows back once the grain slows
    assert coll_n == coll_w > 0  # grains did collide
    # an overrun only makes the phase search the end positions for contacts the list missed
    assert cnt_n[MISSED] == cnt_w[MISSED] == 0 and cnt_n[OVERRUNS] >= 1
    for a, b in ((narrow.pos, wide.pos), (narrow.vel, wide.vel), (narrow.spin, wide.spin)):
        assert np.array_equal(a, b)
