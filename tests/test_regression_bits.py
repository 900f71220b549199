"""Results must not change under a refactor (issue 18): every case of the regression set
(tests/regression/cases.py — spheres and composites, virtual and packed bed, contacts
off / soft / hard, Basset on / off and restart, 1 and 2 threads, a checkpoint-resume)
gives the same bits as the recorded reference: every column of jumps.parquet and
tracks.parquet (end state included) and every number of summary.json."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "regression"))
from cases import (  # noqa: E402
    CASES,
    LEGACY_REFERENCE,
    MACHINE,
    REFERENCE,
    STALE,
    compare,
    run_case,
    stale_cases,
    stale_counters,
)


def _reference(name):
    with np.load(REFERENCE, allow_pickle=False) as z:
        return {k.split("|", 1)[1]: z[k] for k in z.files if k.split("|", 1)[0] == name}


@pytest.mark.parametrize("name", list(CASES))
def test_same_bits_as_the_recorded_reference(tmp_path, name):
    if REFERENCE == LEGACY_REFERENCE and name in STALE:
        pytest.skip(f"{name}: {STALE[name]}; no reference recorded for this machine ({MACHINE}): "
                    f"record one with tests/regression/make_reference.py on the pre-change code")
    if name in stale_cases():
        pytest.skip(f"{name}: {stale_cases()[name]}; not re-recorded on this machine ({MACHINE}): "
                    f"tests/regression/make_reference.py --cases {name}")
    ref = _reference(name)
    assert ref, f"{name} is not in {REFERENCE}: rerun tests/regression/make_reference.py on the pre-change code"
    got = run_case(name, tmp_path / name)
    # work counters changed by a change recorded on another machine: everything else compared
    skip = stale_counters().get(name, {}).get("keys", ())
    assert compare(name, got, ref, skip) == []


def test_the_comparison_can_fail(tmp_path):
    """A changed bit is found: the reference against itself with one ulp moved."""
    ref = _reference("sphere_virtual_off")
    assert compare("x", ref, ref) == []
    moved = dict(ref)
    moved["tracks/x"] = ref["tracks/x"].copy()
    moved["tracks/x"][-1] = np.nextafter(moved["tracks/x"][-1], np.inf)
    assert compare("x", moved, ref) == ["x: tracks/x differs"]
    fewer = {k: v for k, v in ref.items() if k != "jumps/length"}
    assert compare("x", fewer, ref) == ["x: jumps/length only in reference"]
    # a stale work counter is left out, and only it
    counted = dict(ref)
    counted["summary/values"] = ref["summary/values"].copy()
    counted["summary/values"][0] += 1.0
    first = str(ref["summary/keys"][0])
    assert compare("x", counted, ref) == ["x: summary/values differs"]
    assert compare("x", counted, ref, [first]) == []
    assert compare("x", moved, ref, [first]) == ["x: tracks/x differs"]


def test_every_stale_entry_names_a_case_of_the_set():
    """The per-machine lists of stale cases and counters (references/<machine>.json) and the
    legacy list (reference.json) name cases that exist, each with a reason: a renamed case
    must not leave a skip behind that matches nothing."""
    import json

    files = sorted((Path(__file__).resolve().parent / "regression" / "references").glob("*.json"))
    for f in files:
        doc = json.loads(f.read_text())
        for part in ("stale_cases", "stale_counters"):
            for name, why in doc.get(part, {}).items():
                assert name in CASES, f"{f.name}: {part} names {name}, not a case of the set"
                assert why, f"{f.name}: {part}[{name}] gives no reason"
    for name, why in STALE.items():
        assert name in CASES and why
