"""The bounds that decide when a grain joins the contact phase's sub-steps and which pairs
it looks at (contacts/phase.py, "Which grains are sub-stepped" and "Near pairs"): they must
never put a contact of the free-flight paths before the time they return (that would
lose a contact or change the bits), and they should be tight (that is their point: issue
19's dense cases). Checked on random cubic Hermite paths sampled finely."""
import numpy as np
from numba import njit

from saltation.contacts.phase import _first_bed, _first_touch, _path_gap
from saltation.flight.path import hermite_point

DT = 0.02
BOX = np.array([40.0, 10.0, 40.0])
PER = np.array([True, False, True])
S = np.linspace(0.0, 1.0, 4097)


def _path(x0, x1, u0, u1):
    """The Hermite path at S (flight.path.hermite_point's formula, vectorised; spot-checked below)."""
    s = S[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * x0 + h01 * x1 + DT * (h10 * u0 + h11 * u1)


def _pairs(rng, n):
    """Pairs near contact over one step: speeds of ~10 u*, velocity changes over the step of
    ~0.5 u* (fluid and weight: ~25 u*²/d, above g' ≈ 15 u*²/d at τ* = 0.065), most closing
    along their line of centres, some alongside."""
    for _ in range(n):
        xi0 = np.array([20.0, 3.0, 20.0])
        gap = rng.uniform(-0.02, 0.6)
        e = rng.normal(size=3)
        xj0 = xi0 + (1.0 + gap) * e / np.linalg.norm(e)
        ui0 = rng.normal(scale=8.0, size=3)
        # relative velocity: closing along the line of centres (most pairs), or anything
        uj0 = ui0 + rng.normal(scale=rng.choice([0.5, 10.0]), size=3) * rng.choice([0.2, 1.0])
        if rng.random() < 0.7:
            uj0 -= rng.uniform(0.0, 30.0) * (xj0 - xi0)
        ui1 = ui0 + rng.normal(scale=0.3, size=3)
        uj1 = uj0 + rng.normal(scale=0.3, size=3)
        xi1 = xi0 + DT * 0.5 * (ui0 + ui1) + rng.normal(scale=1e-3, size=3)
        xj1 = xj0 + DT * 0.5 * (uj0 + uj1) + rng.normal(scale=1e-3, size=3)
        yield xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1


def test_the_vectorised_path_is_the_phase_s():
    x0, x1, u0, u1 = np.array([1.0, 2.0, 3.0]), np.array([1.2, 1.9, 3.1]), np.array([9.0, -4.0, 5.0]), \
        np.array([11.0, -6.0, 5.0])
    p = _path(x0, x1, u0, u1)
    for k in (0, 1000, 2048, 4096):
        np.testing.assert_allclose(p[k], [hermite_point(x0[c], x1[c], u0[c], u1[c], S[k], DT)[0] for c in range(3)],
                                   rtol=0, atol=1e-14)


def test_no_contact_of_the_free_paths_before_the_join_bound_and_the_bound_is_tight():
    rng = np.random.default_rng(19)
    touching, tight, tight2 = 0, 0, 0
    for xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1 in _pairs(rng, 1000):
        r = np.linalg.norm(_path(xi0, xi1, ui0, ui1) - _path(xj0, xj1, uj0, uj1), axis=1)
        s_bound = _first_touch(xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1, BOX, PER, DT, 1.0)
        inside = np.nonzero(r < 1.0)[0]
        if inside.size == 0:
            continue
        touching += 1
        s_true = S[inside[0]]
        assert s_bound <= s_true, (s_bound, s_true)
        tight += s_true - s_bound < 1.0 / 128  # within one of the default 128 sub-steps
        tight2 += s_true - s_bound < 2.0 / 128
    assert touching > 100
    # measured: 83 % within one sub-step, 95 % within two (the bulge bound's slack)
    assert tight >= 0.8 * touching and tight2 >= 0.9 * touching, (tight, tight2, touching)


def test_pairs_that_never_touch_are_mostly_let_go():
    """The coarse bound took every neighbour within |Δx_i − Δx_j| of touching; the chord
    bound lets most pairs that pass by or move apart go (inf or > 1)."""
    rng = np.random.default_rng(20)
    never, let_go = 0, 0
    for xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1 in _pairs(rng, 1000):
        r = np.linalg.norm(_path(xi0, xi1, ui0, ui1) - _path(xj0, xj1, uj0, uj1), axis=1)
        if r.min() < 1.0 + 1e-3:
            continue
        never += 1
        if _first_touch(xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1, BOX, PER, DT, 1.0) > 1.0:
            let_go += 1
    assert never > 100
    assert let_go >= 0.9 * never, (let_go, never)


def test_the_path_gap_is_a_lower_bound_on_the_closest_approach():
    rng = np.random.default_rng(21)
    for xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1 in _pairs(rng, 300):
        r = np.linalg.norm(_path(xi0, xi1, ui0, ui1) - _path(xj0, xj1, uj0, uj1), axis=1)
        gap = _path_gap(xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1, BOX, PER, DT)
        assert gap <= r.min()
        assert gap > r.min() - 0.02  # and close to it


def test_across_the_periodic_boundary():
    xi0, xj0 = np.array([0.2, 3.0, 5.0]), np.array([39.5, 3.0, 5.0])  # 0.7 apart through x = 0
    ui = np.array([-10.0, 0.0, 0.0])
    uj = np.array([10.0, 0.0, 0.0])
    s = _first_touch(xi0, xi0 + DT * ui, ui, ui, xj0, xj0 + DT * uj, uj, uj, BOX, PER, DT, 1.0)
    assert s == 0.0  # already within d
    xj0 = np.array([39.1, 3.0, 5.0])  # 1.1 apart, closing at 20 u*: touch at s = 0.1 / 0.4
    s = _first_touch(xi0, xi0 + DT * ui, ui, ui, xj0, xj0 + DT * uj, uj, uj, BOX, PER, DT, 1.0)
    assert 0.25 - 1e-6 < s <= 0.25


@njit
def _first_touch_in_a_kernel(xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1):
    """_first_touch inlined into a kernel compiled with Python's error model (as
    phase._engage_start is): a division by zero there raises."""
    return _first_touch(xi0, xi1, ui0, ui1, xj0, xj1, uj0, uj1, BOX, PER, DT, 1.0)


def test_two_grains_on_the_same_chord_never_touch_and_nothing_divides_by_zero():
    xi0, xj0 = np.array([10.0, 3.0, 5.0]), np.array([12.0, 3.0, 5.0])  # 2 d apart
    for u in (np.zeros(3), np.array([8.0, -1.0, 0.5])):  # at rest, or moving alike: Δ = 0
        s = _first_touch_in_a_kernel(xi0, xi0 + DT * u, u, u, xj0, xj0 + DT * u, u, u)
        assert s == np.inf
    ui, uj = np.array([10.0, 0.0, 0.0]), np.zeros(3)  # i closes on j at 10 u*, 0.2 d in the step
    s = _first_touch_in_a_kernel(xi0, xi0 + DT * ui, ui, ui, xj0, xj0 + DT * uj, uj, uj)
    assert 5.0 - 1e-6 < s <= 5.0  # 1 d to close: five steps on, so not in this one
    xj0 = np.array([11.1, 3.0, 5.0])  # 0.1 d to close: s = 0.5
    s = _first_touch_in_a_kernel(xi0, xi0 + DT * ui, ui, ui, xj0, xj0 + DT * uj, uj, uj)
    assert 0.5 - 1e-6 < s <= 0.5


def test_the_bed_bound():
    rng = np.random.default_rng(22)
    lags = []
    for _ in range(300):
        y0 = rng.uniform(0.5, 0.8)
        u0 = np.array([5.0, rng.normal(scale=8.0), 0.0])
        u1 = u0 + rng.normal(scale=0.3, size=3)
        x0 = np.array([1.0, y0, 1.0])
        x1 = x0 + DT * 0.5 * (u0 + u1)
        y = _path(x0, x1, u0, u1)[:, 1]
        s_bound = _first_bed(np.concatenate([x0, u0])[None, :], x1[None, :], u1[None, :], DT, 0)
        below = np.nonzero(y < 0.5)[0]
        if below.size:
            assert s_bound <= S[below[0]]
            lags.append(S[below[0]] - s_bound)
        else:
            assert s_bound > 1.0 or y.min() < 0.5 + 0.01
    assert len(lags) > 50 and np.mean(np.array(lags) < 2.0 / 128) >= 0.9
