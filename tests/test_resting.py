"""Grains at rest on the packed bed (SPEC §7, issue 20): resting and rolling contacts are
soft contacts with the bed spheres (physics/contact_law) while the fluid force acts every
step. Checked against analysis: a grain at rest in a hollow stays there in still water;
the critical tilt of a sphere in the hollow of three touching spheres; rolling without
slip down two rails, and sliding once the slope asks more friction than the contacts have;
the same for bonded-sphere grains (one sphere, and a spanwise dumbbell on four rails).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import saltation
import saltation.engine.simulation as simulation
import saltation.engine.stepping as stepping
from saltation.bed.packed import BED_CENTRE_Y, bed_from_centres, hexagonal_layer, hexagonal_pockets
from saltation.case import CaseError

D = 0.69e-3  # m
# still water: velocity scale √(g R d), the submerged weight per virtual mass is
# g' = 1/(1 + R + Cm) in particle units (physics/forces.py, τ* = 1)
R, CM = 1.65, 0.5
G_V = 1.0 / (1.0 + R + CM)
LX, LZ = 6.0, 4.0 * math.sqrt(3.0)  # d: a hexagonal layer of touching spheres (6 × 8 rows)


def _case(n, slope=0.0, duration=0.3, **tables):
    case = {
        "particle": {"diameter": D, "density": 1000.0 * (1 + R)},
        "fluid": {"density": 1000.0, "viscosity": 1e-6},
        "flow": {"source": "still", "slope": slope},
        "bed": {"model": "packed"},
        "collisions": {"model": "soft"},
        "run": {"n_particles": n, "duration": duration, "dt_particle": 0.005, "seed": 3, "start": "rest",
                "domain": [LX * D, LZ * D, 10 * D]},
        "output": {"vtk": False, "variance": False},
    }
    for t, keys in tables.items():
        case.setdefault(t, {}).update(keys)
    return case


def _displacements(tracks):
    g = tracks.groupby("particle")
    a, b = g.first(), g.last()
    return np.sqrt((b.x - a.x) ** 2 + (b.y - a.y) ** 2 + (b.z - a.z) ** 2).to_numpy()


def test_pockets_touch_three_bed_spheres():
    centres, _, _ = hexagonal_layer(7.3, 5.1)  # stretched rows too
    pockets = hexagonal_pockets(7.3, 5.1)
    assert len(pockets) == 2 * len(centres)
    for p in pockets:
        d = centres - p
        d[:, 0] -= 7.3 * np.round(d[:, 0] / 7.3)
        d[:, 2] -= 5.1 * np.round(d[:, 2] / 5.1)
        r = np.sort(np.linalg.norm(d, axis=1))
        np.testing.assert_allclose(r[:3], 1.0, atol=1e-12)
        assert r[3] > 1.05


def test_rest_needs_packed_soft_spheres(tmp_path):
    for tables, word in (({"bed": {"model": "virtual"}}, "bed.model"),
                         ({"collisions": {"model": "hard"}}, "collisions.model")):
        with pytest.raises(CaseError, match=word):
            saltation.load_case(_case(4, **tables))
    with pytest.raises(CaseError, match="room for"):
        full = _case(40)
        full["run"]["domain"][2] = 100 * D
        saltation.run(full, out=tmp_path / "full")
    assert not (tmp_path / "full" / "config.toml").exists()


def test_grain_at_rest_stays_in_still_water(tmp_path):
    """Target (issue 20): drift < 1e-3 d over 10⁴ steps."""
    r = saltation.run(_case(8, duration=0.35), out=tmp_path / "still")
    assert r.summary["steps"] >= 10_000
    drift = _displacements(r.tracks)
    assert drift.max() < 1e-3, drift
    assert np.abs(r.tracks.y.to_numpy() - (math.sqrt(2 / 3) - 0.5)).max() < 1e-3
    assert r.summary["jumps"]["count"] == 0


# Critical tilt of a sphere in the hollow of three touching equal spheres: it rolls out
# over the two downslope contacts when the vertical through its centre leaves the
# triangle of contact points: tan θc = r_in/(h cos ψ), r_in = d/(4√3) the triangle's
# inradius, h = √(2/3) d/2 the centre's height above it, ψ = 30° between the tilt (+x)
# and the edge's outward normal in both kinds of hollow of our layer: θc = 22.21°.
THETA_C = math.degrees(math.atan((1 / (4 * math.sqrt(3))) / (math.sqrt(2 / 3) / 2 * math.cos(math.radians(30)))))


@pytest.mark.parametrize("factor, moves", [(0.95, False), (1.05, True)])
def test_critical_tilt_of_a_grain_in_a_hollow(tmp_path, factor, moves):
    assert abs(THETA_C - 22.21) < 0.01
    r = saltation.run(_case(8, slope=factor * THETA_C, duration=0.3), out=tmp_path / "tilt")
    drift = _displacements(r.tracks)
    if moves:
        assert drift.min() > 0.5, drift  # every grain has left its hollow
    else:
        assert drift.max() < 1e-2, drift


# Rolling down two rails: bed spheres of diameter d spaced `SPACING` along x at z = ±W
# about the grain; its centre lies √(1 − W²) above them, the contact points at ρ =
# √(1 − W²)/2 from it on the rolling axis. Without fluid forces, rolling without slip
# gives a = g' sin θ / (1 + I/(m ρ²)) (m = 1, I = 0.1 in the contact phase), which needs
# |F_t| = I a/ρ² ≤ μ N, N = g' cos θ / cos φ (cos φ = √(1 − W²): the normals' tilt);
# beyond, it slides with a = g' (sin θ − μ cos θ / cos φ).
W = 0.8
RHO = math.sqrt(1 - W * W) / 2
MU = 0.10  # the bed friction of the default coefficients (Schmeeckle et al. 2001)


RAIL_SPACING = 0.025  # d between the bed spheres of a rail


def _rail_bed(monkeypatch, module, rails_z):
    """Replace ``module``'s packed bed by rails of bed spheres along x at heights z ∈ rails_z;
    returns the grain's resting centre height over them."""
    xs = np.arange(0.0, LX, RAIL_SPACING)
    rails = np.concatenate([np.column_stack([xs, np.full(xs.size, BED_CENTRE_Y), np.full(xs.size, z)])
                            for z in rails_z])
    monkeypatch.setattr(module, "make_packed_bed", lambda a, b, cut=1.0: bed_from_centres(rails, a, b, cut))
    return BED_CENTRE_Y + math.sqrt(1 - W * W)


def _roll_run(tmp_path, case, lz, name):
    """One grain released at rest on the rails without fluid forces; its acceleration along
    x (a parabola fitted to x(t)) and its tracks."""
    case["forces"] = {k: False for k in ("drag", "lift", "magnus", "added_mass", "fluid_acceleration", "basset",
                                         "spin")}
    case["run"]["domain"] = [LX * D, lz * D, 10 * D]
    case["output"]["tracks_interval"] = 0.2 * math.sqrt(D / (9.81 * R))  # 0.2 d/u*
    tr = saltation.run(case, out=tmp_path / name).tracks
    return 2.0 * np.polyfit(tr.t.to_numpy(), tr.x.to_numpy(), 2)[0], tr


def _roll(monkeypatch, tmp_path, slope):
    lz = 4.0
    y = _rail_bed(monkeypatch, stepping, [lz / 2 - W, lz / 2 + W])
    monkeypatch.setattr(simulation, "resting_pockets", lambda a, b: np.array([[1.0, y, lz / 2]]))
    a, tr = _roll_run(tmp_path, _case(1, slope=slope, duration=0.1), lz, f"roll{slope}")
    slip = tr.u.to_numpy()[-1] / (RHO * -tr.spin_z.to_numpy()[-1])  # 1: rolling without slip
    return a, slip


@pytest.mark.parametrize("slope", [5.0, 15.0])
def test_rolling_down_rails(monkeypatch, tmp_path, slope):
    theta = math.radians(slope)
    assert MU * math.cos(theta) / math.sqrt(1 - W * W) > 0.1 / RHO**2 * G_V * math.sin(theta) / (1 + 0.1 / RHO**2) / G_V
    a, slip = _roll(monkeypatch, tmp_path, slope)
    expected = G_V * math.sin(theta) / (1 + 0.1 / RHO**2)
    assert abs(a / expected - 1) < 0.05, (a, expected)
    assert abs(slip - 1) < 0.03, slip


def test_sliding_past_the_friction_limit(monkeypatch, tmp_path):
    theta = math.radians(25.0)
    a, slip = _roll(monkeypatch, tmp_path, 25.0)
    expected = G_V * (math.sin(theta) - MU * math.cos(theta) / math.sqrt(1 - W * W))
    assert abs(a / expected - 1) < 0.05, (a, expected)
    assert slip > 1.3, slip  # the grain slides: its surface moves slower than it


# ----------------------------------------------------------------------------- bonded-sphere grains
# The same checks for bonded-sphere grains (engine/composites.py): their bed contacts in the
# contact phase are soft contacts of their component spheres with the bed spheres
# (contacts/composites.py, "The packed bed").
def _composite_case(n, shape="mixture", **kw):
    case = _case(n, **kw)
    case["particle"]["shape"] = shape
    return case


def test_composites_are_placed_on_the_bed_without_overlaps():
    from saltation.engine.composites import draw_grains, random_quaternions
    from saltation.flight.composites import quat_to_matrix_py
    from saltation.grains.initial import composites_resting

    case = saltation.load_case(_composite_case(30))
    _, _, comps = draw_grains(case, 30)
    quat = random_quaternions(30, np.random.default_rng(1))
    offsets = [g.centres @ quat_to_matrix_py(q).T for g, q in zip(comps, quat)]
    radii = [0.5 * np.asarray(g.diameters) for g in comps]
    bed = hexagonal_layer(LX * 2, LZ * 2)[0]
    gap = 1e-3
    pos = composites_resting(offsets, radii, hexagonal_pockets(LX * 2, LZ * 2), bed, (LX * 2, LZ * 2), 3, gap)
    box = np.array([LX * 2, LZ * 2])
    world = [p + o for p, o in zip(pos, offsets)]

    def gaps(a, ra, b, rb):
        d = a[:, None, :] - b[None, :, :]
        d[..., 0] -= box[0] * np.round(d[..., 0] / box[0])
        d[..., 2] -= box[1] * np.round(d[..., 2] / box[1])
        return np.sqrt((d * d).sum(axis=2)) - ra[:, None] - rb[None, :]

    for i in range(30):
        to_bed = gaps(world[i], radii[i], bed, np.full(len(bed), 0.5))
        assert 0.0 < to_bed.min() <= gap  # raised by the gap from its first touch: near, not inside
        for j in range(i):
            assert gaps(world[i], radii[i], world[j], radii[j]).min() >= gap - 1e-12
    with pytest.raises(ValueError, match="room for"):
        composites_resting(offsets * 10, radii * 10, hexagonal_pockets(LX, LZ), hexagonal_layer(LX, LZ)[0],
                           (LX, LZ), 3)


def test_composites_settle_and_stay_at_rest_in_still_water(tmp_path):
    """Target (issue 20): drift < 1e-3 d over 10⁴ steps, once the grains dropped onto the
    bed have tipped into a stable pose (within ~40 d/u* of still-water time here)."""
    case = _composite_case(3, duration=0.66)
    case["output"]["tracks_interval"] = 0.02
    r = saltation.run(case, out=tmp_path / "still")
    tr = r.tracks
    ts = np.sort(tr.t.unique())
    settled = ts[ts >= 40.0][0]
    assert (ts[-1] - settled) / 0.005 >= 10_000
    a = tr[tr.t == settled].set_index("particle")
    b = tr[tr.t == ts[-1]].set_index("particle")
    drift = np.sqrt((b.x - a.x) ** 2 + (b.y - a.y) ** 2 + (b.z - a.z) ** 2).to_numpy()
    assert drift.max() < 1e-3, drift
    assert r.summary["jumps"]["count"] == 0
    # they rest on the bed, not in it: the lowest points lie below the bed top by less
    # than the soft contact's overlap allows
    assert tr[tr.t == ts[-1]].y.min() > 0.0


def _grains_of(monkeypatch, centres, radii):
    """Every bonded-sphere grain of the run made of these spheres (body frame, Dn)."""
    import saltation.engine.composites as engine
    from saltation.grains.shapes import Composite

    grain = Composite.from_spheres(centres, radii, zingg="equant", subtype=1, axes=(1.0, 1.0, 1.0))
    monkeypatch.setattr(engine, "draw_grains", lambda case, n: (["equant"] * n, np.ones((n, 3)), [grain] * n))


def _one_sphere_grains(monkeypatch):
    """Bonded-sphere grains of one sphere of diameter Dn: the sphere contact exactly
    (contacts/composites.py), so the sphere's analytic results apply."""
    _grains_of(monkeypatch, [[0.0, 0.0, 0.0]], [0.5])


@pytest.mark.parametrize("factor, moves", [(0.95, False), (1.05, True)])
def test_critical_tilt_of_a_one_sphere_composite(monkeypatch, tmp_path, factor, moves):
    _one_sphere_grains(monkeypatch)
    r = saltation.run(_composite_case(4, shape="equant", slope=factor * THETA_C, duration=0.3),
                      out=tmp_path / "tilt")
    drift = _displacements(r.tracks)
    if moves:
        assert drift.min() > 0.5, drift
    else:
        assert drift.max() < 1e-2, drift


# Rolling and sliding of bonded-sphere grains down rails, against the sphere's analysis
# above: (a) a one-sphere grain on two rails; (b) a spanwise dumbbell, two spheres of
# diameter Dn at z = ±SPAN about its centre, each on its own two rails. The dumbbell's
# moment about z is that of its two spheres about their own centres, I_zz/m = 0.1 Dn², so
# a and the rolling condition are the sphere's, but the grain's weight, normal and friction
# forces are carried by four contacts whose lever arms (±SPAN in z) must cancel in the
# torque; a spurious yaw or roll would show as spin_x, spin_y or a z drift.
SPAN = 1.5


def _composite_roll(monkeypatch, tmp_path, slope, dumbbell=False):
    import saltation.engine.composites as engine

    if dumbbell:
        lz = 7.0
        _grains_of(monkeypatch, [[0.0, 0.0, -SPAN], [0.0, 0.0, SPAN]], [0.5, 0.5])
        rails_z = [lz / 2 + s * SPAN + t * W for s in (-1, 1) for t in (-1, 1)]
    else:
        lz = 4.0
        _one_sphere_grains(monkeypatch)
        rails_z = [lz / 2 - W, lz / 2 + W]
    y = _rail_bed(monkeypatch, engine, rails_z)
    monkeypatch.setattr(engine, "random_quaternions", lambda n, rng: np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))
    monkeypatch.setattr(engine.ClusterSimulation, "_centres_resting", lambda self, quat: np.array([[1.0, y, lz / 2]]))
    a, tr = _roll_run(tmp_path, _composite_case(1, shape="equant", slope=slope, duration=0.1), lz,
                      f"roll{slope}{dumbbell}")
    # the grain rattles over the rails' bumps (spheres every 0.025 d): slip and stray spin
    # taken over the run, not at one instant
    on = tr[tr.t >= 1.0]
    slip = float((on.u / (RHO * -on.spin_z)).mean())
    spin = np.abs(on.spin_z).max()
    stray = max(np.abs(on.spin_x).max() / spin, np.abs(on.spin_y).max() / spin, np.abs(tr.z - lz / 2).max())
    return a, slip, stray, tr


@pytest.mark.parametrize("dumbbell", [False, True], ids=["one-sphere", "dumbbell"])
def test_composites_roll_down_rails(monkeypatch, tmp_path, dumbbell):
    theta = math.radians(15.0)
    a, slip, stray, tr = _composite_roll(monkeypatch, tmp_path, 15.0, dumbbell)
    assert tr.x.iloc[-1] - tr.x.iloc[0] > 1.0  # it rolled: a measured on the move, not at rest
    expected = G_V * math.sin(theta) / (1 + 0.1 / RHO**2)
    assert abs(a / expected - 1) < 0.05, (a, expected)
    assert abs(slip - 1) < 0.03, slip
    assert stray < 0.02, stray  # the sphere on the same rails: 0.015


def test_a_composite_slides_past_the_friction_limit(monkeypatch, tmp_path):
    theta = math.radians(25.0)
    a, slip, stray, _ = _composite_roll(monkeypatch, tmp_path, 25.0)
    expected = G_V * (math.sin(theta) - MU * math.cos(theta) / math.sqrt(1 - W * W))
    assert abs(a / expected - 1) < 0.05, (a, expected)
    assert slip > 1.3, slip
    assert stray < 0.02, stray  # the sphere on the same rails: 0.015
