"""Cell partitioning and neighbour search (saltation/contacts/cells.py): counting sort invariants,
stencils, and no pair missed across cell and periodic boundaries (against brute force)."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from saltation.contacts.cells import (
    allocate_cells,
    build_cells,
    build_neighbour_list,
    cell_index,
    make_grid,
    neighbour_pairs,
    stencil_cells,
)


def brute_force_pairs(pos, box, periodic, cutoff):
    """All pairs i < j with minimum-image distance < cutoff, by testing every pair."""
    d = pos[:, None, :] - pos[None, :, :]
    for a in range(3):
        if periodic[a]:
            d[..., a] -= box[a] * np.round(d[..., a] / box[a])
    r2 = (d**2).sum(-1)
    i, j = np.nonzero(np.triu(r2 < cutoff * cutoff, 1))
    return set(zip(i.tolist(), j.tolist()))


@st.composite
def configurations(draw):
    """Random boxes (periodic and bounded axes), cutoffs and grain positions, with many
    grains on or near the box faces, unwrapped images, and grains outside bounded axes."""
    cutoff = draw(st.sampled_from([1.0, 1.1, 1.3]))
    periodic = tuple(draw(st.booleans()) for _ in range(3))
    box = tuple(draw(st.floats(2.0 * cutoff + 1e-9, 7.0)) for _ in range(3))
    n = draw(st.integers(2, 60))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    box_a = np.array(box)
    pos = rng.uniform(0.0, 1.0, (n, 3)) * box_a
    kind = rng.integers(0, 7, (n, 3))
    for a in range(3):
        length = box_a[a]
        edge = rng.uniform(0.0, 0.6, n)
        pos[kind[:, a] == 1, a] = edge[kind[:, a] == 1]  # near the low face
        pos[kind[:, a] == 2, a] = length - edge[kind[:, a] == 2]  # near the high face
        pos[kind[:, a] == 3, a] = rng.choice([0.0, length, np.nextafter(length, 0.0), -0.0],
                                             int((kind[:, a] == 3).sum()))
        if periodic[a]:  # unwrapped images, of points inside and of points on the faces
            shift = rng.integers(-3, 4, n) * length
            pos[kind[:, a] == 4, a] += shift[kind[:, a] == 4]
            face = rng.choice([0.0, length], n) + shift  # 3L may wrap to -1e-15 or round to L
            pos[kind[:, a] == 6, a] = face[kind[:, a] == 6]
        else:  # outside the bounded range: clamped into the end layers
            pos[kind[:, a] == 4, a] = rng.uniform(-2.0, length + 5.0, int((kind[:, a] == 4).sum()))
    return pos, box, periodic, cutoff


@settings(max_examples=300, deadline=None)
@given(configurations(), st.sampled_from([1.0, 1.0, 0.5, 0.37]))
def test_no_pair_missed_across_cell_and_periodic_boundaries(config, cell):
    """Cells of one cutoff (27-cell stencil, pairs.rebuild's search) and narrower ones
    (ceil(cutoff / size) layers either side)."""
    pos, box, periodic, cutoff = config
    grid = make_grid(box, cell * cutoff, periodic)
    found = neighbour_pairs(pos, grid, cutoff)
    pairs = set(map(tuple, found.tolist()))
    assert len(pairs) == len(found)  # no pair listed twice (small grids: stencil deduplicated)
    # rows in id order (the contact forces sum over them): sorted by i, then j
    assert np.array_equal(found, found[np.lexsort((found[:, 1], found[:, 0]))])
    expected = brute_force_pairs(pos, box, periodic, cutoff)
    assert pairs == expected
    # every row whole, from both sides (the search measures each pair from each grain)
    cell_of, start, count, order = allocate_cells(len(pos), grid)
    build_cells(pos, grid, cell_of, start, count, order)
    nbr = np.empty((len(pos), len(pos)), np.int32)
    cnt = np.zeros(len(pos), np.int64)
    build_neighbour_list(pos, grid, cell_of, start, count, order, cutoff, nbr, cnt)
    for i in range(len(pos)):
        assert set(nbr[i, :cnt[i]].tolist()) == {j for p in expected if i in p for j in p if j != i}


def test_a_grain_wrapping_to_just_below_zero_finds_its_neighbours():
    """x = 3L rounds to 3 box lengths and wraps to -1.8e-15 (filed in the first layer);
    wrapping that once more gives L. The search must file it where the cells did: its row
    was empty (seen in tests/test_contacts.py, seed 14)."""
    box = (4.013531755356191, 3.0, 3.0)
    pos = np.array([[4.013531755356191, 0.89613925, 0.0], [12.040595266068573, 0.47471953, 0.08840052]])
    grid = make_grid(box, 1.0, (True, False, False))
    cell_of, start, count, order = allocate_cells(2, grid)
    build_cells(pos, grid, cell_of, start, count, order)
    nbr = np.empty((2, 2), np.int32)
    cnt = np.zeros(2, np.int64)
    build_neighbour_list(pos, grid, cell_of, start, count, order, 1.0, nbr, cnt)
    assert cnt.tolist() == [1, 1] and nbr[0, 0] == 1 and nbr[1, 0] == 0


@settings(max_examples=100, deadline=None)
@given(configurations())
def test_counting_sort_is_a_stable_partition(config):
    pos, box, periodic, cutoff = config
    grid = make_grid(box, cutoff, periodic)
    cell_of, start, count, order = allocate_cells(len(pos), grid)
    build_cells(pos, grid, cell_of, start, count, order)
    assert sorted(order.tolist()) == list(range(len(pos)))
    assert count.sum() == len(pos)
    assert np.all(np.diff(cell_of[order]) >= 0)  # sorted by cell
    for c in np.nonzero(count)[0]:
        members = order[start[c]:start[c] + count[c]]
        assert np.all(cell_of[members] == c)
        assert np.all(np.diff(members) > 0)  # stable: increasing id within a cell
    for i, p in enumerate(pos):
        assert cell_of[i] == cell_index(grid, p[0], p[1], p[2])
        assert 0 <= cell_of[i] < np.prod(grid.n)


def test_cells_are_at_least_the_cutoff_and_fill_the_box():
    grid = make_grid((10.5, 4.0, 7.9), 1.3, (True, False, True))
    assert np.all(grid.size >= 1.3)
    np.testing.assert_allclose(grid.n * grid.size, grid.box)
    assert grid.n.tolist() == [8, 3, 6]


def test_short_periodic_axis_is_refused():
    with pytest.raises(ValueError, match="minimum image"):
        make_grid((1.9, 5.0, 5.0), 1.0, (True, False, True))
    make_grid((5.0, 1.0, 5.0), 1.0, (True, False, True))  # bounded axis: one layer is fine


@pytest.mark.parametrize("n, periodic, expected", [
    ((5, 5, 5), (1, 1, 1), 27),
    ((2, 5, 5), (1, 1, 1), 18),
    ((2, 5, 2), (1, 1, 1), 12),
    ((5, 5, 5), (1, 0, 1), 18),  # bounded axis clipped at the bottom layer
])
def test_stencil_cells_are_distinct(n, periodic, expected):
    grid = make_grid(np.array(n, dtype=float) * 1.5, 1.5, periodic)
    out = np.empty(27, np.int64)
    c = cell_index(grid, 0.1, 0.1, 0.1)
    m = stencil_cells(grid, c, out)
    assert m == expected
    assert len(set(out[:m].tolist())) == m
    assert c in out[:m]


def test_neighbour_list_reports_overflow_and_truncates():
    pos = np.array([[2.0, 2.0, 2.0], [2.3, 2.0, 2.0], [2.0, 2.3, 2.0], [2.0, 2.0, 2.3]])
    grid = make_grid((6.0, 6.0, 6.0), 1.0, (True, True, True))
    cell_of, start, count, order = allocate_cells(4, grid)
    build_cells(pos, grid, cell_of, start, count, order)
    nbr = np.full((4, 2), -1, np.int32)
    cnt = np.zeros(4, np.int64)
    most = build_neighbour_list(pos, grid, cell_of, start, count, order, 1.0, nbr, cnt)
    assert most == 3 and cnt.tolist() == [3, 3, 3, 3]
    assert np.all(nbr >= 0)


def test_neighbour_pairs_scale_to_many_grains_at_fixed_density():
    """Same density, 8× the grains: 8× the pairs (± noise), and all of them found."""
    rng = np.random.default_rng(5)
    counts = []
    for length in (12.0, 24.0):
        n = int(0.1 * length**3)
        pos = rng.uniform(0.0, length, (n, 3))
        grid = make_grid((length,) * 3, 1.0, (True, True, True))
        counts.append(len(neighbour_pairs(pos, grid, 1.0)))
        if length == 12.0:
            assert counts[0] == len(brute_force_pairs(pos, (length,) * 3, (1, 1, 1), 1.0))
    assert 6.0 < counts[1] / counts[0] < 10.0


def test_capped_grid_with_one_periodic_layer_still_finds_every_pair():
    rng = np.random.default_rng(2)
    box = (4.0, 3.0, 4.5)
    pos = rng.uniform(-1.0, 5.0, (80, 3))
    grid = make_grid(box, 1.0, (True, False, True), max_cells=4)
    assert np.prod(grid.n) <= 4
    found = set(map(tuple, neighbour_pairs(pos, grid, 1.0).tolist()))
    assert found == brute_force_pairs(pos, box, (1, 0, 1), 1.0)


def test_stable_argsort_is_numpys_stable_argsort():
    """The contact phase orders its candidates with it (contacts/phase._gather): it must be
    np.argsort(kind="mergesort") exactly, ties (−0.0 = 0.0 included) kept in their order."""
    from saltation.contacts.cells import stable_argsort

    rng = np.random.default_rng(3)
    cases = [np.zeros(0), np.array([0.5]), np.array([0.0, -0.0, 0.0, -np.inf, np.inf, -0.0]),
             rng.integers(0, 5, 257).astype(float), rng.random(1000), np.round(rng.normal(size=333), 1)]
    for key in cases:
        assert np.array_equal(stable_argsort(key), np.argsort(key, kind="mergesort")), key[:8]
