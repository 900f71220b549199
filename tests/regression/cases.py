"""The bit-for-bit regression set of issue 18: a dozen short runs covering spheres and
composites × virtual and packed bed × contacts off / soft / hard × Basset on / off ×
checkpoint-resume. ``fingerprint`` reduces a finished run directory to arrays (every
column of jumps.parquet in (particle, jump) order and of tracks.parquet — the tracks'
last frame is the end state —
and every number of summary.json except wall-clock timings); the reference is written by
``make_reference.py`` before a refactor.

Bits depend on the machine as well as on the code: the same code gives other last bits on
another CPU or with another libm / Numba / NumPy (found on an AMD znver3 host: 6 of the
15 cases differ from the reference recorded on the machine of stops 23–24). So each
reference is kept per machine: ``references/<MACHINE>.npz`` (``MACHINE``: the LLVM host
CPU name, glibc, Numba and NumPy versions), and ``reference.npz``, recorded on the first
machine, whose signature was not written down; ``reference.json`` lists the cases that an
intended physics change made stale in it (it cannot be re-recorded elsewhere).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
LEGACY_REFERENCE = HERE / "reference.npz"  # the first machine's (signature unknown)
STALE = json.loads((HERE / "reference.json").read_text()).get("stale", {})  # case: why, in the legacy one


def machine_signature() -> str:
    import platform

    import llvmlite.binding as ll
    import numba

    libc = "-".join(platform.libc_ver()) or "nolibc"
    return f"{ll.get_host_cpu_name()}-{libc}-numba{numba.__version__}-numpy{np.__version__}"


MACHINE = machine_signature()
REFERENCE = HERE / "references" / f"{MACHINE}.npz"
if not REFERENCE.exists():
    REFERENCE = LEGACY_REFERENCE
# summary numbers that count work, not physics, changed by a change recorded on another
# machine (references/<machine>.json: case -> keys and why); on this machine they are not
# compared until its reference is re-recorded (make_reference.py removes the entry)
STALE_COUNTERS_FILE = REFERENCE.with_suffix(".json")


def stale_counters() -> dict:
    """{case: {"keys": [...], "why": ...}} of this machine's reference (empty: none)."""
    if not STALE_COUNTERS_FILE.exists():
        return {}
    return json.loads(STALE_COUNTERS_FILE.read_text()).get("stale_counters", {})


def stale_cases() -> dict:
    """{case: why} of this machine's reference: whole cases that an intended physics change,
    recorded on another machine, made stale here (the same file, "stale_cases"; the legacy
    reference lists its own in reference.json). Not compared until re-recorded here."""
    if not STALE_COUNTERS_FILE.exists():
        return {}
    return json.loads(STALE_COUNTERS_FILE.read_text()).get("stale_cases", {})
D = 0.69e-3


def _case(shape="sphere", bed="virtual", contacts="off", basset=True, source="les", dense=False, threads=1,
          impacts="keep", seed=5, duration=0.25):
    run = {"duration": duration, "dt_particle": 0.02, "seed": seed, "threads": threads, "name": "reg"}
    if dense:  # a small box at the paper's densest concentrations: grains in contact, sub-stepped
        if shape == "sphere":
            run.update({"concentration": 0.0394, "domain": [0.008, 0.004, 0.028]})
        else:  # composite contacts need a box ≥ 7.84 Dn wide (contacts/composites.py)
            run.update({"concentration": 0.0207, "domain": [0.012, 0.006, 0.028]})
    else:
        run["n_particles"] = 16
    flow = {"source": source, "tau_ratio": 1.79}
    return {
        "particle": {"diameter": D, "shape": shape},
        "flow": flow,
        "bed": {"model": bed},
        "collisions": {"model": contacts},
        "forces": {"basset": basset, "basset_impacts": impacts},
        "run": run,
        "output": {"tracks": True, "tracks_interval": duration, "vtk": False},
    }


# name -> (case dict, resume step or None): a resumed case is interrupted at that step and
# resumed; its fingerprint must be the uninterrupted run's.
CASES = {
    "sphere_virtual_off": (_case(), None),
    "sphere_virtual_off_nobasset_loglaw": (_case(basset=False, source="loglaw"), None),
    "sphere_virtual_off_restart": (_case(impacts="restart"), None),
    "sphere_virtual_soft_dense": (_case(contacts="soft", dense=True), None),
    "sphere_virtual_hard_dense": (_case(contacts="hard", dense=True), None),
    "sphere_packed_soft_dense": (_case(bed="packed", contacts="soft", dense=True), None),
    "sphere_packed_off_nobasset": (_case(bed="packed", basset=False), None),
    "sphere_virtual_soft_dense_2threads": (_case(contacts="soft", dense=True, threads=2), None),
    "sphere_packed_soft_dense_resumed": (_case(bed="packed", contacts="soft", dense=True), 300),
    "mixture_virtual_off": (_case(shape="mixture"), None),
    "mixture_virtual_off_nobasset": (_case(shape="mixture", basset=False), None),
    "mixture_virtual_soft_dense": (_case(shape="mixture", contacts="soft", dense=True), None),
    "mixture_packed_soft_dense": (_case(shape="mixture", bed="packed", contacts="soft", dense=True), None),
    "rod_packed_off": (_case(shape="rod", bed="packed"), None),
}

# top-level summary keys that are measured wall times
_WALL_CLOCK = ("timing", "particle_steps_per_s", "component_sphere_steps_per_s")


def _numbers(obj, prefix=""):
    """Flatten summary.json to {path: float}: its numbers, not its texts, without the
    wall-clock timings."""
    out = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.update(_numbers(v, f"{prefix}/{k}"))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            out.update(_numbers(v, f"{prefix}/{i}"))
    elif isinstance(obj, bool) or obj is None:
        pass
    elif isinstance(obj, (int, float)):
        if prefix.split("/")[1] not in _WALL_CLOCK:
            out[prefix] = float(obj)
    return out


def fingerprint(out: Path) -> dict[str, np.ndarray]:
    out = Path(out)
    fp = {}
    for table in ("jumps", "tracks"):
        frame = pd.read_parquet(out / f"{table}.parquet")
        if table == "jumps":
            # rows are appended at chunk ends, so their order follows the chunking (output
            # times, checkpoint cadence) while the jumps do not: compare them in (particle,
            # jump) order
            frame = frame.sort_values(["particle", "jump"], kind="stable").reset_index(drop=True)
        for col in frame.columns:
            fp[f"{table}/{col}"] = frame[col].to_numpy()
    summary = _numbers(json.loads((out / "summary.json").read_text()))
    keys = sorted(summary)
    fp["summary/keys"] = np.array(keys)
    fp["summary/values"] = np.array([summary[k] for k in keys])
    return fp


def run_case(name: str, out: Path) -> dict[str, np.ndarray]:
    """Run one case of the set (interrupting and resuming it where it says) and return its
    fingerprint."""
    import pytest

    from saltation.case.schema import load_case
    from saltation.engine.simulation import RunInterrupted, Simulation, _les_box_m, open_flow, resolve_domain, run

    case, stop = CASES[name]
    out = Path(out)
    if stop is not None:
        c = load_case(case)
        ds = open_flow(c)
        c = resolve_domain(c, _les_box_m(ds, c) if c.flow.source == "les" else None)
        with pytest.raises(RunInterrupted):
            Simulation(c, ds, out, progress=False, stop_after_steps=stop).run()
        run(case, out=out, progress=False, resume=True)
    else:
        run(case, out=out, progress=False, overwrite=True)
    return fingerprint(out)


def _without(fp: dict, keys) -> dict:
    """The fingerprint without the summary numbers ``keys``."""
    if not keys:
        return fp
    names = list(fp["summary/keys"])
    keep = [i for i, k in enumerate(names) if k not in set(keys)]
    out = dict(fp)
    out["summary/keys"] = fp["summary/keys"][keep]
    out["summary/values"] = fp["summary/values"][keep]
    return out


def compare(name: str, got: dict, ref: dict, skip=()) -> list[str]:
    """What differs between a fingerprint and the reference (empty: identical bits);
    ``skip``: summary numbers left out of both (stale_counters)."""
    bad = []
    if skip:
        got, ref = _without(got, skip), _without(ref, skip)
    for k in sorted(set(got) | set(ref)):
        if k not in got or k not in ref:
            bad.append(f"{name}: {k} only in {'reference' if k in ref else 'this run'}")
            continue
        a, b = got[k], ref[k]
        if a.shape != b.shape or not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
            bad.append(f"{name}: {k} differs")
    return bad
