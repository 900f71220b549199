"""benchmarks/bench_dense.py judges a run against issue 19's targets: met or MISSED from
the 3.94 % one-thread row and the sweep estimate, and "not comparable" when the dense
layer had no time to form (spin-up under 1 s)."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
import benchmark_module  # noqa: E402


@pytest.fixture(scope="module")
def bench():
    return benchmark_module.load("bench_dense")


def _rows(grain_steps, contacts_us, free_us, spinup_s=1.0000001, c=3.9405):
    one = {"grain_steps_per_s": grain_steps, "contacts_us": contacts_us, "free_flight_us": free_us}
    return [{"concentration_pct": 2.07, "runs": {"1": dict(one)}, "spinup_s_simulated": spinup_s},
            {"concentration_pct": c, "runs": {"1": one, "2": dict(one)}, "spinup_s_simulated": spinup_s}]


def _lines(bench, capsys, rows, days):
    bench.print_targets(rows, {"days_longest_first": days})
    return [x.strip() for x in capsys.readouterr().out.splitlines() if x.strip()]


def test_a_run_that_meets_every_target_says_so(bench, capsys):
    out = _lines(bench, capsys, _rows(3.0e5, 2.9, 1.0), 4.9)
    assert out[0] == "Targets (issue 19), this run:"
    assert out[1].endswith("3e+05 grain-steps/s against >= 2.7e+05: met")
    assert out[2].endswith("contact phase / free flight 2.90 against <= 3: met")
    assert out[3] == "full-sweep estimate 4.9 days against <= 5: met"


def test_each_missed_target_is_marked(bench, capsys):
    out = _lines(bench, capsys, _rows(1.2e5, 4.4, 1.0), 12.3)
    assert [x.rsplit(": ", 1)[1] for x in out[1:]] == ["MISSED", "MISSED", "MISSED"]
    out = _lines(bench, capsys, _rows(3.0e5, 3.1, 1.0), 4.0)  # only the ratio over 3
    assert [x.rsplit(": ", 1)[1] for x in out[1:]] == ["met", "MISSED", "met"]


def test_a_short_spin_up_is_not_comparable(bench, capsys):
    """A run whose dense layer has not formed must not be reported as meeting a target."""
    out = _lines(bench, capsys, _rows(3.0e5, 1.8, 1.0, spinup_s=0.05), 4.0)
    assert "not formed" in out[1]
    assert [x.rsplit(": ", 1)[1] for x in out[2:]] == ["not comparable"] * 3


def test_without_the_densest_case_only_the_estimate_is_judged(bench, capsys):
    out = _lines(bench, capsys, _rows(3.0e5, 1.0, 1.0)[:1], 4.0)
    assert out[1] == "C = 3.94 % not measured on one thread in this run"
    assert out[2].endswith("not comparable")  # its cost was extrapolated from 2.07 %


def test_a_run_on_the_papers_domain_is_not_the_targets_case(bench, capsys):
    """The per-step targets are for the reduced case: a run on the paper's domain is not
    judged against them (its estimate still is)."""
    rows = [{**r, "domain": "paper"} for r in _rows(3.0e5, 2.0, 1.0)]
    out = _lines(bench, capsys, rows, 4.0)
    assert "paper's domain" in out[1]
    assert [x.rsplit(": ", 1)[1] for x in out[2:]] == ["not comparable", "not comparable", "met"]


def _measured(c, us, domain):
    return {"concentration_pct": c, "domain": domain, "runs": {"1": {"us_per_grain_step": us}}}


def test_the_estimate_takes_a_paper_domain_measurement_over_a_reduced_one(bench, capsys):
    """Where the near-bed layer percolates the cost per grain-step depends on the domain
    size: a run on the paper's domain (--with-json) replaces the reduced one at its
    concentration, and the estimate says which concentrations still came from the reduced
    domain."""
    reduced = [_measured(2.07, 4.0, "reduced"), _measured(3.94, 7.0, "reduced")]
    est = bench.sweep_estimate(reduced, bench.FULL)
    merged = bench.sweep_estimate(reduced + [_measured(3.94, 15.0, "paper")], bench.FULL)
    at = lambda e, c: [x for x in e["cases"] if round(x["concentration_pct"], 2) == c]  # noqa: E731
    assert {x["us_per_grain_step"] for x in at(merged, 3.94)} == {15.0}
    assert all(x["measured_on_paper_domain"] for x in at(merged, 3.94))
    assert {x["us_per_grain_step"] for x in at(merged, 2.07)} == {4.0}
    # only the 3.94 % cases cost more: by 15/7
    assert merged["core_s"] - est["core_s"] == pytest.approx(sum(x["core_s"] for x in at(est, 3.94)) * (15 / 7 - 1))
    # the order of the rows does not matter
    assert bench.sweep_estimate([_measured(3.94, 15.0, "paper")] + reduced, bench.FULL) == merged
    bench.print_estimate(merged)
    out = capsys.readouterr().out
    assert " 15.00F" in out and " 4.00 " in out
    assert "2.07 % came from the reduced domain, so this estimate is low" in out
    bench.print_estimate(bench.sweep_estimate([_measured(2.07, 9.0, "paper"), _measured(3.94, 15.0, "paper")],
                                              bench.FULL))
    assert "came from the reduced domain" not in capsys.readouterr().out


def _at_tau(c, us, domain, tau):
    return {**_measured(c, us, domain), "tau_ratio": tau}


def test_the_estimate_takes_each_cases_own_flow_intensity_and_says_where_it_could_not(bench, capsys):
    """Each case costs what was measured at its τ*/τ*c; a reduced-domain measurement is
    scaled by the paper/reduced ratio of its concentration measured at another τ*/τ*c
    (marked R); where a τ*/τ*c was not measured the nearest one stands in (marked T)."""
    rows = [_at_tau(2.07, 4.0, "reduced", 1.79), _at_tau(3.94, 5.0, "reduced", 1.79),
            _at_tau(3.94, 7.5, "paper", 1.79), _at_tau(3.94, 4.0, "reduced", 2.43),
            _at_tau(2.07, 3.0, "reduced", 2.67)]
    est = bench.sweep_estimate(rows, bench.FULL)
    at = {(round(x["concentration_pct"], 2), x["tau_ratio"]): x for x in est["cases"]}
    assert at[(3.94, 1.79)]["us_per_grain_step"] == 7.5 and at[(3.94, 1.79)]["measured_on_paper_domain"]
    # 2.43: the reduced 4.0 times 7.5 / 5.0
    assert at[(3.94, 2.43)]["us_per_grain_step"] == pytest.approx(6.0)
    assert at[(3.94, 2.43)]["domain_factor"] == pytest.approx(1.5) and not at[(3.94, 2.43)]["other_tau"]
    # 2.67 not measured at 3.94 %: the nearest, 2.43, scaled likewise
    assert at[(3.94, 2.67)]["us_per_grain_step"] == pytest.approx(6.0) and at[(3.94, 2.67)]["other_tau"]
    assert at[(2.07, 2.67)]["us_per_grain_step"] == 3.0 and not at[(2.07, 2.67)]["other_tau"]
    assert at[(2.07, 2.43)]["us_per_grain_step"] == 3.0 and at[(2.07, 2.43)]["other_tau"]  # 2.67 nearer than 1.79
    assert at[(2.07, 2.43)]["domain_factor"] is None
    bench.print_estimate(est)
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith(" 3.94"))
    assert " 7.50F " in line and " 6.00R " in line and " 6.00RT" in line
    # 2.07 % has no paper-domain measurement at any tau*/tau*c: still named
    assert "2.07 % came from the reduced domain, so this estimate is low" in out


def test_rows_with_and_without_a_flow_intensity_mix(bench):
    """An older saved run (no τ*/τ*c: it serves every one) joined with newer ones."""
    rows = [_measured(3.94, 5.0, "reduced"), _measured(3.94, 7.5, "paper"),
            _at_tau(3.94, 4.0, "reduced", 2.43), _at_tau(3.94, 6.0, "paper", 2.43)]
    at = {x["tau_ratio"]: x["us_per_grain_step"] for x in bench.sweep_estimate(rows, bench.FULL)["cases"]
          if round(x["concentration_pct"], 2) == 3.94}
    assert at == {1.79: 7.5, 2.43: 6.0, 2.67: 7.5}


def test_a_run_at_another_time_step_is_not_the_targets_case(bench, capsys):
    """The per-step targets are for the issue's case at dt = 0.02 d/u*: a grain-step at
    0.01 covers half the time, so a run there is not judged against them; its per-time
    equivalent is printed."""
    rows = [{**r, "dt_particle": 0.01} for r in _rows(3.4e5, 2.0, 1.0)]
    out = _lines(bench, capsys, rows, 4.0)
    assert "dt = 0.01 d/u*" in out[1] and "1.7e+05 grain-steps of 0.02 d/u* per second" in out[1]
    assert [x.rsplit(": ", 1)[1] for x in out[2:]] == ["not comparable", "not comparable", "met"]
    rows = [{**r, "dt_particle": 0.02} for r in _rows(3.4e5, 2.0, 1.0)]
    out = _lines(bench, capsys, rows, 4.0)
    assert [x.rsplit(": ", 1)[1] for x in out[1:]] == ["met", "met", "met"]


def test_the_estimate_refuses_measurements_at_another_time_step(bench):
    sweep = Path(__file__).resolve().parents[1] / "cases" / "concentration_sweep.toml"  # dt 0.02
    rows = [{**_measured(c, 2.0, "reduced"), "dt_particle": 0.01} for c in (0.52, 3.94)]
    with pytest.raises(SystemExit, match="measure at the sweep's dt"):
        bench.sweep_estimate(rows, sweep)
    rows = [{**_measured(c, 2.0, "reduced"), "dt_particle": 0.02} for c in (0.52, 3.94)]
    assert bench.sweep_estimate(rows, sweep)["core_s"] > 0
