"""The OpenFOAM tracker case of benchmarks/bench_openfoam_tracker.py runs and moves grains.

The benchmark writes an ``icoUncoupledKinematicParcelFoam`` case (cloud dictionary,
injection positions, gravity, transport properties) onto a copy of an LES mesh; these
tests write the same case onto a small blockMesh channel with a uniform flow, run a few
steps and check that every grain is tracked and that the grains are carried by the flow,
with and without ``pairCollision`` contacts. The helpers that need no OpenFOAM (the
restitution of OpenFOAM's spring–dashpot, the log parser, the unit conversion) are
tested always.
"""
from __future__ import annotations

import math
import re
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
import benchmark_module  # noqa: E402

bench = benchmark_module.load("bench_openfoam_tracker")

HAVE_SOLVER = shutil.which(bench.SOLVER) is not None and shutil.which("blockMesh") is not None
needs_openfoam = pytest.mark.skipif(not HAVE_SOLVER, reason=f"{bench.SOLVER} / blockMesh not on PATH")

RE_TAU = 400.0
FLOW = np.array([0.1, 0.0, 0.0])  # m/s in the mesh's units, ~12 u_tau


# ------------------------------------------------------------------ no OpenFOAM needed
def test_parameters_keep_the_dimensionless_groups():
    case = bench.load_free_case()
    par = bench.tracker_parameters(case, RE_TAU)
    assert par["d"] * par["u_tau"] / par["nu"] == pytest.approx(case.shear_reynolds, rel=1e-12)
    r = par["rho_p"] / par["rho_f"] - 1.0
    assert par["u_tau"] ** 2 / (par["g"] * r * par["d"]) == pytest.approx(case.shields_number, rel=1e-12)
    assert par["dt"] * par["u_tau"] / par["d"] == pytest.approx(case.dt_particle, rel=1e-12)
    # stiffness: the overlap at the design speed is the case's max_overlap (linear spring)
    m_eff = 0.5 * par["mass"]
    overlap = par["impact_speed"] * math.sqrt(m_eff / par["kn"])  # undamped bound
    assert overlap / par["d"] == pytest.approx(case.collisions.max_overlap, rel=0.02)


def test_openfoam_restitution_limits_and_inverse():
    kn, m_eff, v0 = 1.0e3, 0.5, 0.1
    assert bench.openfoam_restitution(0.0, kn, m_eff, v0) == pytest.approx(1.0, abs=1e-6)
    e1 = bench.openfoam_restitution(0.5, kn, m_eff, v0)
    e2 = bench.openfoam_restitution(1.0, kn, m_eff, v0)
    assert 0.0 < e2 < e1 < 1.0
    alpha = bench.openfoam_alpha(kn, m_eff, v0, 0.65)
    assert bench.openfoam_restitution(alpha, kn, m_eff, v0) == pytest.approx(0.65, abs=1e-6)
    # δ^(1/4) damping: a slower impact (smaller overlap) is damped less
    assert bench.openfoam_restitution(alpha, kn, m_eff, 0.1 * v0) > 0.65


def test_parse_log():
    text = """Time = 0.1
    Current number of parcels       = 7
    Current mass in system          = 2
    Linear momentum                 = (0.3 0.4 -1e-3)
   |Linear momentum|                = 0.5
    12 move-collide subCycles
ExecutionTime = 1.5 s  ClockTime = 2 s
Time = 0.2
    Current number of parcels       = 7
   |Linear momentum|                = 0.75
    14 move-collide subCycles
ExecutionTime = 2.25 s  ClockTime = 3 s
"""
    res = bench.parse_log(text)
    assert res["execution_s"] == [1.5, 2.25] and res["subcycles"] == [12, 14]
    assert res["parcels"] == [7, 7] and res["momentum"] == [0.5, 0.75] and not res["fatal"]
    assert res["momentum_vector"] == [(0.3, 0.4, -1e-3)] and res["mass"] == [2.0]
    rate = bench.openfoam_rate(res, 7, 1)
    assert rate["timed_steps"] == 1 and rate["particle_steps_per_cpu_s"] == round(7 / 0.75)


# ------------------------------------------------------------------ with OpenFOAM
@pytest.fixture(scope="module")
def small_channel(tmp_path_factory):
    """A 12 × 8 × 8-cell channel (4 × 2 × 2 m, walls at y = 0 and 2) with uniform U."""
    from flowfields import openfoam as of

    case = tmp_path_factory.mktemp("channel")
    of.write_block_mesh_dict(case, lx=4.0, lz=2.0, h=1.0, nx=12, ny=8, nz=8, expansion=4.0)
    (case / "system" / "controlDict").write_text(
        of.foam_header("dictionary", "controlDict", "system")
        + "application blockMesh;\nstartFrom startTime;\nstartTime 0;\nstopAt endTime;\n"
          "endTime 1;\ndeltaT 1;\nwriteControl timeStep;\nwriteInterval 1;\n")
    of.run_block_mesh(case)
    of.write_velocity_field(case, FLOW)
    return case


def _positions(par, n, seed=0):
    rng = np.random.default_rng(seed)
    d = par["d"]
    return np.column_stack([rng.uniform(0.2, 3.8, n), rng.uniform(1.0 * d, 3.0 * d, n), rng.uniform(0.2, 1.8, n)])


def _written_positions(case_dir):
    """(N, 3) grain positions of the last written time (v1912 writes the old-style
    ``positions`` file, '(x y z) celli' per line, next to the barycentric ones)."""
    times = sorted((p for p in case_dir.iterdir() if p.is_dir() and re.fullmatch(r"[0-9.eE+-]+", p.name)
                    and float(p.name) > 0), key=lambda p: float(p.name))
    text = (times[-1] / "lagrangian" / "kinematicCloud" / "positions").read_text()
    rows = re.findall(r"^\(([-0-9.eE+]+) ([-0-9.eE+]+) ([-0-9.eE+]+)\)", text, flags=re.M)
    return np.array(rows, dtype=float)


@pytest.mark.openfoam
@needs_openfoam
@pytest.mark.parametrize("contacts", [False, True], ids=["free", "pairCollision"])
def test_tracker_case_runs_and_moves_grains(small_channel, tmp_path, contacts):
    case = bench.load_free_case()
    par = bench.tracker_parameters(case, RE_TAU)
    n, steps = 40, 6
    pos = _positions(par, n)
    mat = bench.collision_material(par, 8, 10 * par["u_tau"]) if contacts else None
    u0 = (0.0, 0.0, 0.0)
    run_dir = bench.write_tracker_case(tmp_path / "tracker", small_channel, small_channel / "0" / "U", pos, par,
                                       steps, collisions=mat, max_co=1.0, u0=u0, write_at_end=True)
    res, _ = bench.run_tracker(run_dir, timeout=120)
    assert len(res["execution_s"]) == steps
    assert res["parcels"] and all(p == n for p in res["parcels"])  # nobody lost or stuck
    assert len(res["momentum_vector"]) == steps and len(res["mass"]) == steps
    if contacts:
        assert res["subcycles"] and min(res["subcycles"]) >= 2
    # the flow (+x) drags the grains: streamwise momentum grows every step
    mom = np.array(res["momentum"])
    assert np.all(np.diff(mom) > 0)
    end = _written_positions(run_dir)
    assert end.shape == (n, 3)
    dx = end[:, 0] - pos[:, 0]
    dx = (dx + 2.0) % 4.0 - 2.0  # periodic in x (4 m)
    assert np.all(dx > 0.0)
    # gravity (−y) wins over nothing else vertically: the grains sink or rest on the wall
    assert np.all(end[:, 1] <= pos[:, 1] + 1e-9)
    assert np.all(end[:, 1] >= 0.0)
