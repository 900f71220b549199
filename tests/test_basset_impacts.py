"""The Basset history through impacts (SPEC §2 revised) in whole runs: spheres and
bonded-sphere grains run with the history kept (the default) and restarted, and the
two differ; the option is checked."""
import numpy as np
import pytest

from saltation.case.schema import CaseError, load_case
from saltation.engine.simulation import run

D = 0.69e-3


def case(shape="sphere", impacts=None, duration=0.4):
    forces = {} if impacts is None else {"basset_impacts": impacts}
    return {"particle": {"diameter": D, "shape": shape},
            "flow": {"source": "loglaw", "profile": "rough", "tau_ratio": 2.43},
            "forces": forces, "collisions": {"model": "off"},
            "run": {"n_particles": 8, "duration": duration, "seed": 3, "threads": 1},
            "output": {"vtk": False, "tracks": False}}


@pytest.mark.parametrize("shape", ["sphere", "mixture"])
def test_keeping_the_history_through_impacts_changes_the_jumps(tmp_path, shape):
    keep = run(case(shape), out=tmp_path / "keep", progress=False)
    restart = run(case(shape, "restart"), out=tmp_path / "restart", progress=False)
    assert load_case(case(shape)).forces.basset_impacts == "keep"  # the default
    for r in (keep, restart):
        assert r.summary["status"] == "completed" and r.summary["jumps"]["recorded"] > 0
        assert np.isfinite(r.jumps[["length", "height", "velocity"]].to_numpy()).all()
    kj, rj = keep.jumps, restart.jumps
    n = min(len(kj), len(rj))
    # same grains, same seeds, same first impact: the histories part after it
    assert not np.array_equal(kj["length"].to_numpy()[:n], rj["length"].to_numpy()[:n])


def test_a_wrong_basset_impacts_value_names_the_key_and_the_choices():
    with pytest.raises(CaseError, match=r"forces.basset_impacts.*keep.*restart"):
        load_case(case(impacts="forget"))
