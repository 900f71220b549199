"""benchmarks/bench_dense.py's tools: --spinup-states (a saved spin-up comes back as it was
saved, and a file made for another case, or not a saved spin-up at all, is refused by
name), the count of touching pairs (the same as a direct count over all pairs), the
estimate's warning when it extrapolates below the measured concentrations, which
measurement of a concentration it takes, and --print-json of a run saved elsewhere."""
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
import benchmark_module  # noqa: E402


class State(NamedTuple):
    pos: np.ndarray
    count: np.ndarray


@pytest.fixture(scope="module")
def bench():
    return benchmark_module.load("bench_dense")


META = {"cases": "concentration_sweep.toml", "concentration_pct": 3.94, "tau_ratio": 1.79, "spinup_steps": 1833,
        "spinup_threads": 1, "n": 4, "seed": 1, "dt_particle": 0.02, "n_sub": 128, "code": "abc1234"}


def _state(rng):
    return State(rng.random((4, 3)), rng.integers(0, 9, 4))


def test_a_saved_spin_up_loads_bit_for_bit(bench, tmp_path):
    rng = np.random.default_rng(3)
    st, ws, arrays = _state(rng), _state(rng), {"cl_nbr": rng.integers(0, 4, (4, 5)), "timers": rng.random(3)}
    path = bench.spun_state_path(tmp_path, "cases/concentration_sweep.toml", 3.94, 1.79, 1.0, 1)
    assert path.name == "spun_concentration_sweep_C3.94_tau1.79_1s_1thr.npz"
    bench.save_spun_state(path, {**META, "wall_s": 12.0}, st, ws, arrays)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no part file left
    fresh = State(np.zeros((4, 3)), np.zeros(4, np.int64))
    # another code version may load it (recorded only)
    st2, ws2, arrays2, saved = bench.load_spun_state(path, {**META, "code": "other"}, fresh, fresh,
                                                      {k: None for k in arrays})
    assert saved["wall_s"] == 12.0 and saved["code"] == "abc1234"
    for a, b in zip(st + ws, st2 + ws2):
        assert np.array_equal(a, b) and a.dtype == b.dtype
    assert all(np.array_equal(arrays[k], arrays2[k]) for k in arrays)


def test_a_spin_up_for_another_case_or_a_broken_file_is_refused(bench, tmp_path):
    rng = np.random.default_rng(4)
    st = _state(rng)
    path = tmp_path / "spun.npz"
    bench.save_spun_state(path, META, st, st, {})
    with pytest.raises(SystemExit, match=r"spun\.npz: a spin-up made for another case \(seed: saved 1, this run 2\)"):
        bench.load_spun_state(path, {**META, "seed": 2}, st, st, {})
    with pytest.raises(SystemExit, match="pos is float64.*needs float64\\(5, 3\\)"):
        bench.load_spun_state(path, META, State(np.zeros((5, 3)), st.count), st, {})
    path.write_bytes(b"not a state")
    with pytest.raises(SystemExit, match=r"spun\.npz: not a readable saved spin-up.*delete it"):
        bench.load_spun_state(path, META, st, st, {})


def test_touching_pairs_are_those_of_a_direct_count(bench):
    """Periodic in x and z (grains outside the box wrap), pairs just inside and just
    outside contact, against every pair's minimum-image distance."""
    rng = np.random.default_rng(5)
    lx, lz, n = 12.0, 6.0, 900
    pos = rng.random((n, 3)) * [2 * lx, 3.0, lz] + [-lx / 2, 0.2, 0.0]
    pos[:40] = pos[40:80] + [0.0, 0.0, 1.0 - 1e-7]  # just touching
    pos[80:120] = pos[120:160] + [0.0, 1.0 + 1e-7, 0.0]  # just apart
    pos[160] = pos[161] + [lx - 0.5, 0.0, 0.0]  # touching across the periodic boundary
    a = pos[:, None, :] - pos[None, :, :]
    a[..., 0] -= lx * np.round(a[..., 0] / lx)
    a[..., 2] -= lz * np.round(a[..., 2] / lz)
    r2 = (a * a).sum(-1)
    np.fill_diagonal(r2, np.inf)
    direct = int((r2 < 1.0).sum()) // 2
    assert direct > 40
    assert bench._touching(pos, lx, lz) == (direct, int((pos[:, 1] < 0.5).sum()))


def _estimate(measured):
    cases = [{"concentration_pct": c, "tau_ratio": 1.79, "steps": 100, "n": 10, "us_per_grain_step": 2.0,
              "interpolated": c not in measured, "core_s": 3600.0} for c in (0.04, 0.52, 2.07, 3.94)]
    return {"sweep": "concentration_sweep.toml", "cases": cases, "workers": 2, "core_s": 4 * 3600.0,
            "days_even_split": 1.0, "days_longest_first": 1.0, "longest_case_s": 3600.0}


def test_the_estimate_warns_when_it_extrapolates_below_the_lowest_measured_concentration(bench, capsys):
    bench.print_estimate(_estimate({2.07, 3.94}))
    out = capsys.readouterr().out
    assert "WARNING: 0.04, 0.52 % lie below the lowest measured concentration (2.07 %)" in out
    bench.print_estimate(_estimate({0.04, 0.52, 2.07, 3.94}))
    assert "WARNING" not in capsys.readouterr().out


def test_a_paper_domain_measurement_replaces_the_reduced_one_of_the_same_concentration(bench):
    # the two sweeps' grain counts give concentrations that differ in the third decimal
    # (1.0294 % reduced, 1.0300 % on the paper's domain): they are the same case's
    sweep = Path(__file__).resolve().parents[1] / "cases" / "concentration_sweep.toml"
    rows = [{"concentration_pct": c, "domain": dom, "runs": {"1": {"us_per_grain_step": us}}}
            for c, dom, us in ((0.0399764, "reduced", 1.0), (1.0293924, "reduced", 3.5), (1.0299853, "paper", 4.0),
                               (3.9405312, "reduced", 9.0), (3.9399873, "paper", 13.0))]
    est = bench.sweep_estimate(rows, sweep)
    by_c = {}
    for case in est["cases"]:
        by_c.setdefault(round(case["concentration_pct"], 2), set()).add(
            (case["us_per_grain_step"], case["measured_on_paper_domain"], case["interpolated"]))
    assert by_c[1.03] == {(4.0, True, False)}
    assert by_c[3.94] == {(13.0, True, False)}
    assert by_c[0.04] == {(1.0, False, False)}


def test_a_saved_run_from_another_checkout_names_its_missing_sweep_file_and_takes_sweep(bench, tmp_path, monkeypatch,
                                                                                     capsys):
    saved = tmp_path / "run.json"
    saved.write_text('{"cases": "/gone/cases/concentration_sweep_reduced.toml", "sweep": '
                     '"/gone/cases/concentration_sweep.toml", "tau_ratio": 1.79, "steps": 200, "concentrations": []}')
    monkeypatch.setattr(sys, "argv", ["bench_dense.py", "--print-json", str(saved)])
    with pytest.raises(SystemExit) as err:
        bench.main()
    assert "its sweep file /gone/cases/concentration_sweep.toml is not there" in str(err.value)
    assert "--sweep cases/concentration_sweep.toml" in str(err.value)
    sweep = Path(__file__).resolve().parents[1] / "cases" / "concentration_sweep.toml"
    joined = tmp_path / "paper.json"  # one measured concentration, so that there is an estimate to print
    joined.write_text('{"cases": "concentration_sweep.toml", "concentrations": '
                      '[{"concentration_pct": 3.94, "runs": {"1": {"us_per_grain_step": 10.0}}}]}')
    monkeypatch.setattr(sys, "argv", ["bench_dense.py", "--print-json", str(saved), "--with-json", str(joined),
                                      "--sweep", str(sweep)])
    bench.main()  # a --sweep given wins over the saved one
    assert "Full sweep (concentration_sweep.toml: 24 cases" in capsys.readouterr().out
