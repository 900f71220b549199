"""A first run's compile on two cores (saltation/engine/cold_start.py): the contact phase
that a helper process compiles is the one the step loads, nothing is compiled twice, a
warm run starts no helper, and the cold run is the warm run bit for bit. (That the
helper-compiled code gives the recorded results is tests/test_regression_bits.py's check
whenever the suite starts with an empty cache.)"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent / "regression"))
from cases import fingerprint  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

# the start of both scripts: records the kernels of each helper started (``started``);
# count(k): (loaded from the cache, compiled here, compiled signatures) of kernel k in this process
WATCH = textwrap.dedent("""
    import json, sys
    import saltation
    from saltation.engine import cold_start
    started = []
    start = cold_start.compile_elsewhere
    cold_start.compile_elsewhere = lambda jobs: (started.append([k.py_func.__name__ for k, _ in jobs]), start(jobs))[1]
    count = lambda k: [sum(k._cache_hits.values()), sum(k._cache_misses.values()), len(k.overloads)]
""")

RUN = WATCH + textwrap.dedent("""
    from saltation.contacts import phase
    from saltation.contacts.cells import stable_argsort
    from saltation.engine import stepping
    before = cold_start.is_cached(stable_argsort, cold_start.typed(__import__("numpy").zeros(3)))
    res = saltation.run("cases/default.toml", out=sys.argv[1], progress=False, overwrite=True,
                        **{"run.n_particles": 40, "run.duration": 0.05, "output.vtk": False})
    print(json.dumps({"contact": count(phase.soft_contact_phase), "flight": count(stepping._free_flight),
                      "bed": count(stepping._bed_pass), "helpers": started, "argsort_cached_before": before,
                      "argsort_cached_after": cold_start.is_cached(stable_argsort,
                                                                   cold_start.typed(__import__("numpy").zeros(3)))}))
""")


def _run(tmp_path, name, cache, script=RUN):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    env.pop("SALTATION_SERIAL_COMPILE", None)
    out = tmp_path / name
    proc = subprocess.run([sys.executable, "-c", script, str(out)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1]), out


def test_the_helpers_contact_phase_is_used_and_the_run_is_the_same(tmp_path):
    cache = tmp_path / "cache"  # empty: a first run
    cold, out_cold = _run(tmp_path, "cold", cache)
    # the contact phase came from the helper through the cache; the free flight and the bed
    # were compiled here once, for the types the step calls them with (no second signature)
    assert cold["helpers"] == [["soft_contact_phase"]] and cold["contact"] == [1, 0, 1], cold
    assert cold["flight"] == [0, 1, 1] and cold["bed"] == [0, 1, 1], cold
    assert cold["argsort_cached_before"] is False and cold["argsort_cached_after"] is True, cold
    # a second run starts no helper (the step is cached), compiles nothing, gives the same run
    warm, out_warm = _run(tmp_path, "warm", cache)
    assert warm["helpers"] == [], warm
    assert warm["contact"][1] == 0 and warm["flight"][1] == 0 and warm["bed"][1] == 0, warm
    a, b = fingerprint(out_cold), fingerprint(out_warm)  # tables and summary, without wall-clock times
    assert len(a["jumps/particle"]) > 0 and a.keys() == b.keys()
    for key in a:
        assert np.array_equal(a[key], b[key]), key


COMPOSITES = WATCH + textwrap.dedent("""
    from saltation.contacts import composites
    from saltation.flight import composites as flight
    saltation.run("cases/default.toml", out=sys.argv[1], progress=False, overwrite=True,
                  **{"particle.shape": "mixture", "run.n_particles": 40, "run.duration": 0.05, "output.vtk": False})
    kernels = [flight.free_flight_pass, composites.advance_clusters_contacts, composites._reach,
               composites._build_list, composites._poses, composites._engage, composites.component_forces,
               composites._move_par, composites._substeps_ser, composites._force_kick_par, composites._force_kick_ser,
               composites._finish]
    kernels = {k.py_func.__name__: count(k) for k in kernels}
    print(json.dumps({"helpers": started, "kernels": kernels}))
""")


def test_composites_split_their_contact_phase_between_the_two_processes(tmp_path):
    res, _ = _run(tmp_path, "run", tmp_path / "cache", COMPOSITES)  # empty cache: a first run
    (helper,) = res["helpers"]  # one helper, given the sub-step kernels
    assert helper == ["_poses", "_engage", "component_forces", "_move_par", "_substeps_ser", "_force_kick_par",
                      "_force_kick_ser", "_finish"], res
    for name, (hits, misses, sigs) in res["kernels"].items():
        if name in helper:  # compiled by the helper, loaded here by the step: never compiled here
            assert (hits, misses, sigs) == (1, 0, 1), (name, res)
        else:  # the run's own share and the step: compiled here once, for one signature
            assert (hits, misses, sigs) == (0, 1, 1), (name, res)


SERIAL = WATCH + textwrap.dedent("""
    import numba
    from saltation.contacts import phase
    saltation.run("cases/default.toml", out=sys.argv[1], progress=False, overwrite=True,
                  **{"run.n_particles": 40, "run.duration": 0.05, "output.vtk": False})
    kernels = {name: count(k) for name, k in vars(phase).items()
               if isinstance(k, numba.core.registry.CPUDispatcher) and k.overloads}
    print(json.dumps({"helpers": started, "kernels": kernels}))
""")


def test_the_sphere_contact_phase_compiles_each_kernel_once(tmp_path, monkeypatch):
    # everything in this process (no helper), from an empty cache: every kernel of the
    # contact phase that the step reaches is compiled for one signature only. A literal
    # argument (f(..., True) beside f(..., False)) compiles f and all it inlines twice
    # (ARCHITECTURE.md, "What a kernel compiles, and how often"): _forces and _kick_drift
    # did, and the first run took 11 s longer.
    monkeypatch.setenv("SALTATION_SERIAL_COMPILE", "1")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", SERIAL, str(tmp_path / "run")], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert res["helpers"] == [], res
    kernels = res["kernels"]
    for name in ("soft_contact_phase", "_run_block", "_forces", "_kick_drift", "_wake_up", "_substep_part"):
        assert name in kernels, (name, sorted(kernels))
    # _resized (grow one array of the set) serves arrays of several types and ranks; _fill
    # was compiled twice too (its count argument first typed as the literal 0)
    twice = {name: sigs for name, (_, _, sigs) in kernels.items() if sigs > 1 and name != "_resized"}
    assert twice == {}, twice


def test_no_helper_on_request(monkeypatch):
    from saltation.engine import cold_start

    monkeypatch.setenv("SALTATION_SERIAL_COMPILE", "1")
    assert not cold_start.helper_wanted()
    monkeypatch.setenv("SALTATION_SERIAL_COMPILE", "0")
    assert cold_start.helper_wanted() == ((os.cpu_count() or 1) >= 2)
