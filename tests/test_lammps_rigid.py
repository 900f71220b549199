"""Rigid bonded-sphere grains against LAMMPS ``fix rigid`` (no fluid): torque-free
rotation of an asymmetric clump and a drop onto a plane (benchmarks/shapes_lammps.py
holds the set-up; tolerances from the observed 3e-6 and 3e-3, see the report there)."""
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
import benchmark_module  # noqa: E402

pytestmark = [
    pytest.mark.lammps,
    pytest.mark.skipif(shutil.which("lmp") is None, reason="lammps: needs LAMMPS (lmp) on PATH"),
]


def _bench():
    return benchmark_module.load("shapes_lammps")


def test_torque_free_rotation_matches_lammps():
    b = _bench()
    comp, q = b.clump(), b.initial()
    om = np.array([1.0, 2.0, 0.5])
    kw = dict(gravity=False, wall=False, t_end=10.0, every_t=0.1)
    tl, dl = b.run_lammps(comp, [0, 30, 0], [0.0, 0, 0], q, om, dt=1e-3, **kw)
    to, do, _ = b.run_ours(comp, [0, 30, 0], [0.0, 0, 0], q, om, dt=0.01, **kw)
    m = min(len(tl), len(to))
    assert m > 90
    assert np.ptp(do[:m, 2:5], axis=0).max() > 0.3  # it tumbles: a real comparison
    assert np.abs(dl[:m, 2:5] - do[:m, 2:5]).max() < 1e-4


def test_drop_onto_plane_matches_lammps():
    b = _bench()
    comp, q = b.clump(), b.initial()
    om = np.array([0.5, -1.0, 2.0])
    kw = dict(gravity=True, wall=True, t_end=5.0, every_t=0.02)
    to, do, hits = b.run_ours(comp, [0, 2.0, 0], [0.3, 0, 0], q, om, dt=0.002, **kw)
    tl, dl = b.run_lammps(comp, [0, 2.0, 0], [0.3, 0, 0], q, om, dt=2e-5, **kw)
    assert hits[-1] >= 2
    hit = np.concatenate([[False], np.diff(hits) != 0])
    ok = ~(hit | np.concatenate([hit[1:], [False]]))
    m = min(len(tl), len(to))
    ok = ok[:m]
    assert np.abs(dl[:m, 1] - do[:m, 1])[ok].max() < 0.02
    assert np.abs(dl[:m, 2:5] - do[:m, 2:5])[ok].max() < 0.02
    # the impacts changed the spin: the comparison covers them
    assert np.abs(do[-1, 2:5] - om).max() > 0.5
