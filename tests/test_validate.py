"""`saltation validate nino-garcia`: one configuration over several flows, every
regression's ratio, the widened envelope, growth with stage, sensitivity rows."""
import math

import pandas as pd
import pytest

from saltation.analysis import regressions
from saltation.case.schema import load_case
from saltation.studies import validate


def test_compare_gives_a_ratio_per_regression_and_the_widened_envelope():
    refs = pd.DataFrame({"H_over_d": [2.0, 1.0], "L_over_d": [10.0, float("nan")], "U_over_ustar": [5.0, 8.0]},
                        index=["A", "B"])
    row = {"H_mean": 2.4, "L_mean": 13.0, "U_mean": 3.0}
    out = validate._compare(row, refs)
    assert out["H / A"] == pytest.approx(1.2) and out["H / B"] == pytest.approx(2.4)
    assert "L / B" not in out  # B gives no length
    assert out["H_in_envelope"]  # 2.4 <= 1.25 * 2.0
    assert not out["L_in_envelope"]  # 13 > 1.25 * 10
    assert not out["U_in_envelope"]  # 3.0 < 0.75 * 5
    row["U_mean"] = 3.76
    assert validate._compare(row, refs)["U_in_envelope"]


def test_every_case_and_flow_is_consistent_with_its_references():
    for ratio, name in validate.CASES.items():
        case = load_case(validate.cases_dir() / name)
        assert case.flow.source == "les"
        assert case.tau_ratio == pytest.approx(ratio)
        refs = validate.references(case)
        assert {"van Rijn 1984", "Fernandez Luque & van Beek 1976"} <= set(refs.index)
        vr = validate.van_rijn(case)
        assert vr["U_vanrijn"] == pytest.approx(refs.loc["van Rijn 1984", "U_over_ustar"])
    assert validate.DEFAULT_FLOW == next(iter(validate.FLOWS))
    # every sensitivity row is a valid override set of the cases
    for _label, over in validate.SENSITIVITY:
        load_case(validate.cases_dir() / validate.CASES[1.79], over)


def test_validation_over_the_log_law_writes_its_tables(tmp_path):
    res = validate.run_validation(tmp_path, duration_scale=0.05, ablation=False, sensitivity=False,
                                  progress=False, flows=("rough log law",))
    table = pd.read_csv(tmp_path / "validation.csv")
    assert list(table["tau_ratio"]) == list(validate.CASES)
    assert (table["count"] > 0).all()
    for q in ("H", "L", "U"):
        assert f"{q} / van Rijn 1984" in table and f"{q}_in_envelope" in table
    refs = pd.read_csv(tmp_path / "references.csv")
    assert len(refs) == 4 * len(regressions.REGRESSIONS)
    assert (tmp_path / "validation.png").stat().st_size > 0
    assert not math.isnan(res["validation"][0]["U / Fernandez Luque & van Beek 1976"])


def test_a_flow_whose_dataset_is_not_there_is_skipped_with_the_command_that_makes_it(monkeypatch):
    import flowfields.dataset as fd

    monkeypatch.setitem(fd.SHIPPED_DATASETS, "sandbed395", fd.SHIPPED_DATASET.parent / "no_such_dataset")
    why = validate._missing_dataset(validate.FLOWS["rough LES"])
    assert why and "saltation flow generate" in why and "--bed porous" in why
    assert validate._missing_dataset(validate.FLOWS["smooth LES"]) is None
    assert validate._missing_dataset(validate.FLOWS["rough log law"]) is None
