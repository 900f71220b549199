"""Cost of the dense cases: the reduced concentration sweep after spin-up, its split, and
the contact part against LAMMPS; the full 24-case sweep's wall time estimated from it
(issue 19, item 4).

    python benchmarks/bench_dense.py [--concentrations 0.52 2.07 3.94] [--tau-ratio 1.79]
        [--spinup 1.0] [--spinup-threads 1] [--steps 200] [--threads 1 2] [--no-lammps]
        [--lammps-concentrations 3.94] [--lammps-segment 10] [--lammps-skin 0.3]
        [--lmp lmp] [--keep DIR] [--cases cases/concentration_sweep_reduced.toml]
        [--sweep cases/concentration_sweep.toml] [--spinup-states DIR] [--json OUT]
        [--with-json SAVED ...]

Cases: ``cases/concentration_sweep_reduced.toml`` (the paper's physics on the paper's
domain / 6 in x and z, so 1/36 of its grains at its concentration; soft contacts, virtual
bed, shipped LES, dt = 0.02 d/u*) at the given concentrations (%, default the eight
0.04 … 3.94) and one τ*/τ*c (default 1.79), seed 1 (``--cases`` takes them from another
sweep file: the full sweep checks the domain-size assumption below). Each concentration
runs in its own process:

1. compile on a small case (excluded), build the reduced case, spin up ``--spinup``
   simulated seconds (default 1.0 s: the near-bed dense layer forms over ~1 s; not
   timed for the table, on ``--spinup-threads``, default 1; its cost per grain-step and
   the share of grains below 2 d are traced chunk by chunk, ``spinup_trace``);
   With ``--spinup-states DIR`` the state after the spin-up is saved in DIR
   (``spun_<sweep file>_C<C>_tau<τ*/τ*c>_<spin-up>s_<threads>thr.npz``) and a later run
   with the same case, spin-up and spin-up threads loads it instead of spinning up (the
   paper's domain takes ~1 h at 3.94 %); a file made for another case is refused, naming
   what differs;
2. keep the state (grains, fluid workspace, contact list and history, bed contacts,
   counters: the arrays a checkpoint keeps, engine/stepping.Stepper.state_arrays) and,
   for each thread count, restore it and time ``--steps`` hydrodynamic steps
   (stepping.Stepper.advance in one call per chunk; its timers give the free flight /
   contacts / bed split; wall and process CPU time). Every thread count starts from the
   same state; their end states are compared (``same_end_state``: the split and its
   contacts are race-free, so they should agree bit for bit);
3. restore it once more and step one step at a time (not timed, ``--spinup-threads``)
   to count the grains the contact phase sub-stepped in each step (``ph.active``),
   keeping the state every ``--lammps-segment`` steps for 4.: the **engaged fraction** =
   sub-stepped grain-steps / (N · steps). The counter ``SUBSTEPPED`` (grain-sub-steps
   done) over N · n_sub · steps is the **sub-step share** (a grain joins at the sub-step
   before it can first touch, so share ≤ engaged fraction);
4. (``--lammps-concentrations``, default 3.94 %) the contact part alone in LAMMPS, run
   right after in the same process (same machine load), in segments: our state at the
   start of every ``--lammps-segment`` (default 10) steps of the timed window, each
   written as a LAMMPS data file (particle units: d = 1, m = 1, x and z wrapped into the
   periodic box) and run for n_sub × segment steps, so that the segments together span
   the sub-steps of our timed contact phase (n_sub × steps) on the same configurations.
   Each segment: ``pair_style gran/hooke/history`` with the run's k_n, k_t, γ_n, γ_t = 0,
   f (contacts.pairs.contact_model_from_case), a ``fix wall/gran hooke/history`` plane at
   y = 0 (y is the centre height above the bed top: a grain touches the bed below
   y = 0.5 in both codes) with the bed's k_n, k_t, γ_n (from the bed restitution for
   m_eff = m, as contacts.phase.make_bed_context) and the bed friction, ``fix gravity``
   the submerged weight per unit mass (α/τ*, physics.forces.weight_components), no fluid,
   ``fix nve/sphere``, time step h = dt/n_sub, ``neighbor SKIN bin`` checked every step,
   one rank, OMP_NUM_THREADS=1 (one ``lmp`` process, the segments after ``clear``; their
   "Loop time"s summed, set-up and file reading excluded). Touching grain pairs and
   grains touching the bed are counted in our states (``_touching``) and by LAMMPS
   (``compute contact/atom``, y < 0.5) at each segment's first and last step. Then our
   one-thread window of 2. is timed once more, and LAMMPS run once more after it (ours,
   LAMMPS, ours, LAMMPS): the ratios use the mean of each code's two timings, and a
   warning is printed when either code's two differ by more than 15 % (a shared
   machine's speed can change by 1.6× within minutes, during LAMMPS's own run too; the
   ratio then measures the machine, not the code).

Ratios (``ours / LAMMPS``, both wall time, ours on one thread; < 1: ours is cheaper):

- ``per_engaged``: our contact-phase time per grain-sub-step actually done
  (``SUBSTEPPED``) against LAMMPS's loop time per atom-step. LAMMPS moves every atom
  every step; ours sub-steps only the engaged grains, and its phase time also carries
  its per-step O(N) passes (reach, list upkeep, engagement test, gather/scatter, blocks);
- ``per_grain``: our contact-phase time per (grain × sub-step) of *all* grains, i.e. the
  cost of resolving the contacts of the whole suspension for one step, against the same
  LAMMPS figure (LAMMPS would have to step all of them: this is the ratio of the two
  codes' cost for the same physical time and the same grains).

LAMMPS is not a like-for-like run of the physics: without the fluid the saltating grains
fall, so its contacts drift away from ours within a segment (one run over the whole
window, 4 d/u* at 200 steps, piled them into a packed layer with ~40 times the touching
pairs: hence the segments); the counts at each segment's first and last step say how
much. Its tangential springs start from zero in each segment (ours carry theirs); our
lever arm is r/2 (LAMMPS d/2); its neighbour list is half (each pair once), ours full.

Full-sweep estimate: the paper's sweep (``--sweep``, default cases/concentration_sweep
.toml: 8 concentrations × τ*/τ*c 1.79, 2.43, 2.67, the paper's domain = 36 × the reduced
grains, 200 s each) costs Σ N · n_steps / (grain-steps/s at that concentration, one
thread) core-seconds; with 2 workers × 1 thread on this 2-core machine the wall time is
that sum / 2 (and at least the longest case; the greedy longest-first schedule is
printed too). Each case takes the cost measured at its own τ*/τ*c (a run measures one,
``--tau-ratio``; ``--with-json`` joins runs at the others), else at the nearest one
measured (marked T). Assumptions: the cost per grain-step at a concentration does not
depend on the domain size (the phases are linear in N: benchmarks/bench_scaling.py;
where a concentration was measured on the paper's domain at one τ*/τ*c and only on the
reduced one at another, the reduced figure is scaled by the paper/reduced ratio of the
first, marked R), the measured state (after the spin-up) is
representative of the 200 s, each worker has a core to itself (this machine is shared:
the load average at each measurement is printed; a busier machine is slower; repeated
runs of the same deterministic state differed by up to ~35 % in grain-steps/s), only the
stepping is counted (not a run's outputs: jumps, displacement variances, checkpoints),
and concentrations not measured are interpolated linearly in C (marked).

The domain-size assumption fails where the near-bed layer percolates (2.07 % and 3.94 %):
it is one block there, and at full size that block no longer fits in cache
(contacts/phase.py, "Blocks", known limit). ``--cases cases/concentration_sweep.toml
--concentrations 2.07 3.94 --no-lammps --steps 100`` measured it on 2026-12-06 from
spin-ups saved with ``--spinup-states`` (52 189 and 99 335 grains; 15 and 53 min of
spin-up): 11.5 and 17.8 µs per grain-step on one thread, against 4.7 and 7.5 in the
reduced cases ten minutes later. ``--with-json`` joins saved runs to the estimate, a
measurement on the paper's domain replacing a reduced one at its concentration (marked
F), and the estimate names the concentrations from 2.07 % on that still came from the
reduced domain. The reduced sweep with those two full-domain runs joined: 18.2 days
(the reduced sweep alone: 8.3).

Prints a table, the estimate, and this run against issue 19's targets (3.94 %, one thread:
grain-steps/s, the contact phase over the free flight of the same run; the full-sweep
estimate), each marked met or missed; ``--json`` writes everything.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REDUCED = ROOT / "cases" / "concentration_sweep_reduced.toml"
FULL = ROOT / "cases" / "concentration_sweep.toml"
PAPER_C = (0.04, 0.12, 0.18, 0.26, 0.52, 1.03, 2.07, 3.94)  # %
PERCOLATING_C = 2.07  # %: from here the near-bed layer is one block in the reduced case (module docstring)
WORKERS = 2


def paper_c(c_pct):
    """The paper's concentration (%) a realised one stands for: its two decimals. The two
    sweeps' grain counts make the realised values differ in the third (1.0294 % reduced,
    1.0300 % on the paper's domain), so every match of two runs' or cases' concentrations
    goes through this."""
    return round(c_pct, 2)


# --------------------------------------------------------------------------- one concentration


def _sweep_case(path, concentration_pct, tau_ratio):
    """(tables, overrides) of the sweep case at that concentration (%) and τ*/τ*c, seed 1."""
    from saltation.studies.sweep import load_sweep

    sw = load_sweep(path)
    for c in sw.cases:
        v = c.values
        if (abs(100.0 * v["run.concentration"] - concentration_pct) < 1e-9
                and abs(v["flow.tau_ratio"] - tau_ratio) < 1e-9):
            return c.tables, dict(v)
    raise SystemExit(f"{path}: no case at C = {concentration_pct} %, tau_ratio = {tau_ratio} "
                     f"(concentrations {sorted({100 * c.values['run.concentration'] for c in sw.cases})})")


def _code_version():
    """The commit of this checkout (and "+changes" when it has uncommitted ones), or "unknown"."""
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()
        return head + ("+changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def build(tables, overrides=None, out="/tmp/bench_dense_unused"):
    """(simulation, flow dataset, grain state, workspace) of a case, started, not stepped
    (its stepper advanced directly: no outputs)."""
    from saltation.case.schema import load_case, resolve_domain
    from saltation.engine.simulation import Simulation, _les_box_m, open_flow
    from saltation.flight.spheres import make_workspace

    case = load_case(tables, overrides)
    ds = open_flow(case)
    case = resolve_domain(case, _les_box_m(ds, case))
    sim = Simulation(case, ds, out, progress=False)
    st = sim._initial_state()
    ws = make_workspace(sim.n)
    sim.stepper.start(st.pos)
    return sim, ds, st, ws


def steps(sim, f, st, ws, step0, n):
    """n hydrodynamic steps from global step step0 (jumps not collected); returns n."""
    done = 0
    while done < n:
        k = sim.stepper.advance(f, st, ws, (step0 + done) * sim.dt, n - done, step0 + done)
        st.jump_buf_n[:] = 0  # jumps are not collected here
        done += k
    return done


def _copy_tuple(t):
    return type(t)(*[a.copy() for a in t])


def spun_state_path(folder, cases, c_pct, tau_ratio, spinup, threads):
    return Path(folder) / f"spun_{Path(cases).stem}_C{c_pct:g}_tau{tau_ratio:g}_{spinup:g}s_{threads}thr.npz"


def save_spun_state(path, meta, st, ws, arrays):
    """The state after a spin-up: the grain state and workspace (by field), the stepper's
    checkpoint arrays (Stepper.state_arrays) and ``meta`` (what it was made for), written
    whole or not at all."""
    import numpy as np

    data = {f"st.{k}": v for k, v in zip(st._fields, st)}
    data.update({f"ws.{k}": v for k, v in zip(ws._fields, ws)})
    data.update({f"arr.{k}": v for k, v in arrays.items()})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta, sort_keys=True)), **data)
    os.replace(tmp, path)


def spun_meta(cases, c_pct, tau_ratio, sim, spin_steps, threads):
    """What a saved spin-up is made for (it loads only into a run where all but "code" agree)."""
    return {"cases": Path(cases).name, "concentration_pct": c_pct, "tau_ratio": tau_ratio, "spinup_steps": spin_steps,
            "spinup_threads": threads, "n": sim.n, "seed": sim.case.run.seed, "dt_particle": sim.dt,
            "n_sub": sim.stepper.n_sub, "code": _code_version()}


def load_spun_into(path, meta, sim, st, ws):
    """A saved spin-up loaded into the simulation's stepper: (grain state, workspace, what
    was saved with it)."""
    stp = sim.stepper
    st, ws, arrays, saved = load_spun_state(path, meta, st, ws, stp.state_arrays())
    stp.start(st.pos)
    stp.load_state_arrays(arrays, st.pos)
    return st, ws, saved


def load_spun_state(path, meta, st, ws, arrays):
    """(st, ws, arrays) from a saved spin-up made for ``meta``, shaped as the fresh ones
    given; SystemExit naming the file and what differs when it was made for another case."""
    import numpy as np

    try:
        with np.load(path) as z:
            saved = json.loads(str(z["meta"]))
            keys = ["code"]  # which code made it: for the record only
            diff = {k: (saved.get(k), v) for k, v in meta.items() if k not in keys and saved.get(k) != v}
            if diff:
                what = ", ".join(f"{k}: saved {a!r}, this run {b!r}" for k, (a, b) in diff.items())
                raise SystemExit(f"{path}: a spin-up made for another case ({what}); delete it or use another "
                                 "--spinup-states")
            new_st = type(st)(*[z[f"st.{k}"] for k in st._fields])
            new_ws = type(ws)(*[z[f"ws.{k}"] for k in ws._fields])
            new_arrays = {k: z[f"arr.{k}"] for k in arrays}
    except (OSError, KeyError, ValueError) as err:
        raise SystemExit(f"{path}: not a readable saved spin-up ({type(err).__name__}: {err}); delete it to spin up "
                         "again") from None
    for name, a, b in zip(st._fields + ws._fields, new_st + new_ws, st + ws):
        if a.shape != b.shape or a.dtype != b.dtype:
            raise SystemExit(f"{path}: {name} is {a.dtype}{a.shape}, this run needs {b.dtype}{b.shape}; delete it")
    return new_st, new_ws, new_arrays, saved


def _touching(pos, lx, lz):
    """(grain pairs closer than d, grains with y < 1/2) at pos (N, 3), x and z periodic.
    Candidate pairs from a k-d tree (periodic in x and z; y padded to no wrap), each
    counted when its minimum-image distance² is below 1."""
    import numpy as np
    from scipy.spatial import cKDTree

    p = pos.copy()
    p[:, 0] %= lx
    p[:, 2] %= lz
    p[:, 1] -= p[:, 1].min()
    box = [lx, p[:, 1].max() + 2.0, lz]  # y wider than the layer plus the cutoff: no image in y
    ij = cKDTree(p, boxsize=box).query_pairs(1.0 + 1e-9, output_type="ndarray")
    a = p[ij[:, 0]] - p[ij[:, 1]]
    a[:, 0] -= lx * np.round(a[:, 0] / lx)
    a[:, 2] -= lz * np.round(a[:, 2] / lz)
    pairs = int(((a * a).sum(-1) < 1.0).sum())
    return pairs, int((pos[:, 1] < 0.5).sum())


def _write_lammps_data(path, pos, vel, spin, lx, lz, ytop):
    """atom_style sphere data file: d = 1, density 6/π (m = 1), x and z wrapped."""
    lines = ["saltation dense layer (benchmarks/bench_dense.py)", "", f"{len(pos)} atoms", "1 atom types", "",
             f"0 {float(lx)!r} xlo xhi", f"-0.5 {float(ytop)!r} ylo yhi", f"0 {float(lz)!r} zlo zhi", "",
             "Atoms # sphere", ""]
    for i, p in enumerate(pos):
        x, y, z = float(p[0]) % lx, float(p[1]), float(p[2]) % lz
        lines.append(f"{i + 1} 1 1.0 {6.0 / math.pi!r} {x!r} {y!r} {z!r}")
    lines += ["", "Velocities", ""]
    lines += [f"{i + 1} " + " ".join(repr(float(x)) for x in (*v, *w)) for i, (v, w) in enumerate(zip(vel, spin))]
    Path(path).write_text("\n".join(lines) + "\n")


def _lammps_segment(data, model, bed_gamma, bed_friction, g, h, n_steps, skin):
    """One LAMMPS segment: read ``data``, run n_steps of h (the input is a chain of these,
    each after ``clear``)."""
    gx, gy = g  # a = (gx, -gy, 0)
    mag = math.hypot(gx, gy)
    return f"""clear
units lj
atom_style sphere
atom_modify map array
boundary p fm p
comm_modify vel yes
read_data {data}
set group all mass 1.0
pair_style gran/hooke/history {model.kn!r} {model.kt!r} {model.gamma_n!r} 0.0 {model.friction!r} 0
pair_coeff * *
neighbor {skin!r} bin
neigh_modify delay 0 every 1 check yes
fix integrate all nve/sphere
fix weight all gravity {mag!r} vector {gx / mag!r} {-gy / mag!r} 0.0
fix bed all wall/gran hooke/history {model.kn!r} {model.kt!r} {bed_gamma!r} 0.0 {bed_friction!r} 0 yplane 0.0 NULL
timestep {h!r}
compute nc all contact/atom
compute npairs all reduce sum c_nc
variable inbed atom "y < 0.5"
compute nbed all reduce sum v_inbed
thermo_style custom step atoms c_npairs c_nbed ke
thermo_modify norm no
thermo {n_steps}
run {n_steps}
"""


def _run_lammps(lmp, work, sim, states, h, n_steps, skin):
    """LAMMPS from each of our ``states`` (pos, vel, spin) for n_steps steps of h: one
    input, one process, the segments one after the other; the loop times are summed."""
    from saltation.physics.forces import weight_components

    stp = sim.stepper
    lx, _, lz = stp.box
    bp = stp.bc.params  # packed, e, f, tilt, γ_n (m_eff = m), k_n, k_t, …
    g = weight_components(sim.coef)
    text = []
    for k, (pos, vel, spin) in enumerate(states):
        ytop = max(float(pos[:, 1].max()) + 20.0, 10.0)
        _write_lammps_data(work / f"data.{k}", pos, vel, spin, lx, lz, ytop)
        text.append(_lammps_segment(f"data.{k}", stp.model, float(bp[4]), float(bp[2]), g, h, n_steps, skin))
    (work / "in.dense").write_text("\n".join(text))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    subprocess.run([lmp, "-in", "in.dense", "-log", "log.dense", "-screen", "none"], cwd=work, check=True, env=env)
    wall = time.perf_counter() - t0
    log = (work / "log.dense").read_text()
    loops = [float(x) for x in re.findall(r"Loop time of ([0-9.eE+-]+) on 1 procs", log)]
    sections = {}
    for m in re.finditer(r"^(Pair|Neigh|Comm|Output|Modify|Other)\s*\|\s*([0-9.eE+-]+)", log, re.M):
        sections[m.group(1).lower()] = sections.get(m.group(1).lower(), 0.0) + float(m.group(2))
    firsts, lasts = [], []  # thermo rows (step, atoms, contact/atom sum, bed contacts, ke) of each segment
    for head in re.finditer(r"^\s*Step\s+Atoms\s+c_npairs\s+c_nbed\s+KinEng\s*$", log, re.M):
        rows = []
        for line in log[head.end():].lstrip("\n").splitlines():
            parts = line.split()
            try:
                row = [float(x) for x in parts]
            except ValueError:
                break
            if len(row) != 5:
                break
            rows.append(row)
        if rows:
            firsts.append(rows[0])
            lasts.append(rows[-1])
    cpu = [float(x) for x in re.findall(r"([0-9.]+)% CPU use", log)]
    n = len(states[0][0])
    total = n_steps * len(states)
    loop = sum(loops)
    mean = lambda xs: sum(xs) / len(xs) if xs else None  # noqa: E731
    out = {
        "version": re.search(r"LAMMPS \(([^)]*)\)", log).group(1),
        "atoms": n, "segments": len(states), "steps_per_segment": n_steps, "steps": total, "timestep": h,
        "skin": skin, "loop_s": loop, "loop_s_per_segment": loops, "wall_s": wall, "sections_s": sections,
        "neighbor_builds": sum(int(x) for x in re.findall(r"Neighbor list builds = (\d+)", log)),
        "cpu_use_percent": mean(cpu), "ns_per_atom_step": 1e9 * loop / (n * total), "load_avg_1min": load,
        # contact/atom counts each pair from both grains
        "touching_pairs_first": mean([r[2] / 2.0 for r in firsts]),
        "touching_pairs_last": mean([r[2] / 2.0 for r in lasts]),
        "bed_contacts_first": mean([r[3] for r in firsts]), "bed_contacts_last": mean([r[3] for r in lasts]),
        "atoms_last": int(min(r[1] for r in lasts)) if lasts else None,
    }
    return out


def one_concentration(args) -> dict:
    """Runs in a child process (main): the measurements at one concentration."""
    import numba
    import numpy as np

    from saltation.contacts.phase import CLOCK_NAMES, CLOCK_SUBSTEPS, N_CLOCKS, RETIRED_SUBSTEPS, SUBSTEPPED

    most = numba.config.NUMBA_NUM_THREADS
    threads = [t for t in args.threads if t <= most]
    say = lambda *a: print(f"[C = {args.one} %]", *a, file=sys.stderr, flush=True)  # noqa: E731

    # compile (cached after the first run) on a small case
    t0 = time.perf_counter()
    warm = {"particle": {"diameter": 0.69e-3, "density": 2650.0}, "fluid": {"density": 1000.0, "viscosity": 1e-6},
            "flow": {"source": "les", "tau_ratio": 1.79}, "bed": {"model": "virtual"}, "collisions": {"model": "soft"},
            "run": {"n_particles": 300, "duration": 1.0, "dt_particle": 0.02, "seed": 7,
                    "domain": [0.03, 0.015, 0.005]}, "output": {"tracks": False, "vtk": False}}
    sim, ds, st, ws = build(warm)
    numba.set_num_threads(max(threads))
    steps(sim, ds.arrays, st, ws, 0, 3)
    compile_s = time.perf_counter() - t0

    tables, values = _sweep_case(args.cases, args.one, args.tau_ratio)
    sim, ds, st, ws = build(tables, values)
    c, stp, f = sim.case, sim.stepper, ds.arrays
    stp.ph = stp.ph._replace(clocks=np.zeros(N_CLOCKS))  # the contact phase's parts timed (CLOCK_*)
    n, n_sub = sim.n, stp.n_sub
    seconds_per_step = c.dt
    spin_steps = int(round(args.spinup / seconds_per_step))
    numba.set_num_threads(min(args.spinup_threads, most))
    say(f"N = {n}, n_sub = {n_sub}, spin-up {args.spinup} s = {spin_steps} steps on "
        f"{numba.get_num_threads()} thread(s)")
    t0 = time.perf_counter()
    done = 0
    chunk = max(1, spin_steps // 10)
    trace = []  # per spin-up chunk: has the layer (and the cost per grain-step) settled?
    spun, loaded = None, None
    if args.spinup_states:
        spun = spun_state_path(args.spinup_states, args.cases, args.one, args.tau_ratio, args.spinup,
                               numba.get_num_threads())
        meta = spun_meta(args.cases, args.one, args.tau_ratio, sim, spin_steps, numba.get_num_threads())
        if spun.exists():
            st, ws, loaded = load_spun_into(spun, meta, sim, st, ws)
            done = spin_steps
            trace = loaded.get("trace", [])
            say(f"spin-up loaded from {spun} (made by {loaded.get('code')}, {loaded.get('wall_s', 0):.0f} s wall)")
    while done < spin_steps:
        k, c0 = min(chunk, spin_steps - done), time.perf_counter()
        done += steps(sim, f, st, ws, done, k)
        el = time.perf_counter() - c0
        trace.append({"t_s": done * seconds_per_step, "grain_steps_per_s": n * k / el,
                      "mean_height_d": float(st.pos[:, 1].mean()), "share_below_2d": float((st.pos[:, 1] < 2.0).mean()),
                      "load_avg_1min": os.getloadavg()[0]})
        say(f"spin-up {done}/{spin_steps} steps, {time.perf_counter() - t0:.0f} s, {n * k / el:.3g} grain-steps/s, "
            f"{100 * trace[-1]['share_below_2d']:.0f} % below 2 d, load {trace[-1]['load_avg_1min']:.2f}")
    spinup_wall = time.perf_counter() - t0 if loaded is None else loaded.get("wall_s", float("nan"))
    if spun is not None and loaded is None:
        save_spun_state(spun, {**meta, "trace": trace, "wall_s": spinup_wall}, st, ws, stp.state_arrays())
        say(f"spin-up saved in {spun}")

    # the state after spin-up, restored before every measurement
    keep_st, keep_ws = _copy_tuple(st), _copy_tuple(ws)
    keep_arrays = {k: np.array(v, copy=True) for k, v in stp.state_arrays().items()}

    def restore():
        s, w = _copy_tuple(keep_st), _copy_tuple(keep_ws)
        stp.start(s.pos)
        stp.load_state_arrays({k: v.copy() for k, v in keep_arrays.items()}, s.pos)
        return s, w

    lx, _, lz = stp.box
    pairs0, bed0 = _touching(keep_st.pos, lx, lz)
    out = {
        "concentration_pct": 100.0 * c.concentration, "tau_ratio": c.tau_ratio, "n": n, "substeps_per_step": n_sub,
        "dt_particle": sim.dt, "substep_particle": sim.dt / n_sub, "domain_d": [round(lx, 2), round(lz, 2)],
        "spinup_s_simulated": spin_steps * seconds_per_step, "spinup_steps": spin_steps,
        "spinup_wall_s": spinup_wall, "spinup_threads": min(args.spinup_threads, most), "spinup_trace": trace,
        "spinup_loaded_from": str(spun) if loaded is not None else None,
        "compile_and_warmup_s": compile_s, "threading_layer": numba.threading_layer(),
        "steps": args.steps, "touching_pairs_start": pairs0, "bed_contacts_start": bed0,
        "mean_height_start_d": float(keep_st.pos[:, 1].mean()),
        "share_below_2d_start": float((keep_st.pos[:, 1] < 2.0).mean()),
        "kn": stp.model.kn, "kt": stp.model.kt, "gamma_n": stp.model.gamma_n, "friction": stp.model.friction,
        "bed_gamma_n": float(stp.bc.params[4]), "bed_friction": float(stp.bc.params[2]),
        "runs": {},
    }
    ends = {}
    for th in threads:
        numba.set_num_threads(th)
        s, w = restore()
        stp.timers[:] = 0.0
        stp.ph.clocks[:] = 0.0
        cnt0 = stp.ph.counters.copy()
        load = os.getloadavg()[0]
        c0, t0 = time.process_time(), time.perf_counter()
        k = steps(sim, f, s, w, spin_steps, args.steps)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        ff, pc, bd = (float(x) for x in stp.timers)
        dc = stp.ph.counters - cnt0
        gs = n * k
        sub = int(dc[SUBSTEPPED])
        out["runs"][str(th)] = {
            "threads": th, "steps": k, "wall_s": wall, "cpu_s": cpu, "cpu_per_wall": cpu / wall,
            "grain_steps_per_s": gs / wall, "us_per_grain_step": 1e6 * wall / gs,
            "free_flight_us": 1e6 * ff / gs, "contacts_us": 1e6 * pc / gs, "bed_us": 1e6 * bd / gs,
            "other_us": 1e6 * (wall - ff - pc - bd) / gs,
            "contacts_s": pc, "substeps_done": sub, "substep_share": sub / (gs * n_sub),
            "retired_share": float(dc[RETIRED_SUBSTEPS]) / sub if sub else 0.0,
            "contacts_ns_per_substep_done": 1e9 * pc / sub if sub else None,
            "contacts_ns_per_grain_substep": 1e9 * pc / (gs * n_sub),
            "list_rebuilds": int(dc[0]), "overruns": int(dc[1]), "wakes": int(dc[2]), "missed": int(dc[4]),
            "blocks_per_step": float(dc[5]) / k, "redone": int(dc[6] + dc[7]),
            "load_avg_1min": load,
            "contact_parts_us": {name: 1e6 * float(stp.ph.clocks[i]) / gs for i, name in enumerate(CLOCK_NAMES)},
            "substeps_ns_per_substep_done": 1e9 * float(stp.ph.clocks[CLOCK_SUBSTEPS]) / sub if sub else None,
        }
        ends[th] = (s.pos.copy(), s.vel.copy())
        say(f"{th} thread(s): {gs / wall:.4g} grain-steps/s, load {load:.2f}")
    if len(ends) > 1:
        ref = ends[threads[0]]
        out["same_end_state"] = all(np.array_equal(ref[0], e[0]) and np.array_equal(ref[1], e[1])
                                    for e in ends.values())
    end_pos = ends[threads[0]][0]
    out["touching_pairs_end"], out["bed_contacts_end"] = _touching(end_pos, lx, lz)

    # engaged grains per step (untimed, one step at a time)
    numba.set_num_threads(min(args.spinup_threads, most))
    s, w = restore()
    engaged = 0
    seg = max(1, min(args.lammps_segment, args.steps))
    states, pairs_at = [], []  # our state at the start of each LAMMPS segment
    for j in range(args.steps):
        if j % seg == 0 and j + seg <= args.steps:
            states.append((s.pos.copy(), s.vel.copy(), s.spin.copy()))
            pairs_at.append(_touching(s.pos, lx, lz) if args.lammps_on else (0, 0))
        steps(sim, f, s, w, spin_steps + j, 1)
        engaged += int(stp.ph.active.sum())
    out["engaged_fraction"] = engaged / (n * args.steps)

    if args.lammps_on:
        lmp = shutil.which(args.lmp)
        if lmp is None:
            out["lammps"] = {"error": f"{args.lmp} not found"}
        else:
            work = Path(args.keep) / f"c{args.one:g}" if args.keep else Path(tempfile.mkdtemp(prefix="bench_dense_"))
            work.mkdir(parents=True, exist_ok=True)
            say(f"LAMMPS: {n} atoms, {len(states)} segments of {n_sub * seg} steps in {work}")
            try:
                lam = _run_lammps(lmp, work, sim, states, sim.dt / n_sub, n_sub * seg, args.lammps_skin)
                lam["ours_touching_pairs_at_segment_starts"] = sum(p for p, _ in pairs_at) / len(pairs_at)
                lam["ours_bed_contacts_at_segment_starts"] = sum(b for _, b in pairs_at) / len(pairs_at)
            except (subprocess.CalledProcessError, AttributeError) as err:
                lam = {"error": f"{type(err).__name__}: {err}", "log_tail": (work / "log.dense").read_text()[-2000:]
                       if (work / "log.dense").exists() else ""}
            out["lammps"] = lam
            if "loop_s" in lam and "1" in out["runs"]:
                # ours timed again right after LAMMPS: the two bracket it, so a change of the
                # machine's speed between ours and LAMMPS's is seen (a shared VM's speed can
                # change by 1.6x within minutes); the ratios use their mean
                r1 = out["runs"]["1"]
                numba.set_num_threads(1)
                s, w = restore()
                stp.ph.clocks[:] = 0.0
                t_pc = float(stp.timers[1])
                steps(sim, f, s, w, spin_steps, args.steps)
                pc_after = float(stp.timers[1]) - t_pc
                sub = r1["substeps_done"]
                after = {"contacts_s": pc_after,
                         "contacts_ns_per_substep_done": 1e9 * pc_after / sub if sub else None,
                         "substeps_ns_per_substep_done":
                             1e9 * float(stp.ph.clocks[CLOCK_SUBSTEPS]) / sub if sub else None}
                lam["ours_after"] = after
                lam["ours_before_after"] = pc_after / r1["contacts_s"]
                mean = 0.5 * (r1["contacts_s"] + pc_after) / r1["contacts_s"]  # of ours, over the first timing
                # LAMMPS again after ours (ours, LAMMPS, ours, LAMMPS): a change of speed
                # during LAMMPS's own run is seen too; the ratios use the mean of its two
                say("LAMMPS again, after ours")
                try:
                    again = _run_lammps(lmp, work, sim, states, sim.dt / n_sub, n_sub * seg, args.lammps_skin)
                    lam["ns_per_atom_step_first"] = lam["ns_per_atom_step"]
                    lam["ns_per_atom_step_again"] = again["ns_per_atom_step"]
                    lam["lammps_again_over_first"] = again["ns_per_atom_step"] / lam["ns_per_atom_step"]
                    lam["ns_per_atom_step"] = 0.5 * (lam["ns_per_atom_step"] + again["ns_per_atom_step"])
                except (subprocess.CalledProcessError, AttributeError) as err:
                    lam["again_error"] = f"{type(err).__name__}: {err}"
                if r1["contacts_ns_per_substep_done"]:
                    lam["ratio_per_engaged"] = mean * r1["contacts_ns_per_substep_done"] / lam["ns_per_atom_step"]
                    lam["ratio_substeps_per_engaged"] = (0.5 * (r1["substeps_ns_per_substep_done"]
                                                                + after["substeps_ns_per_substep_done"])
                                                         / lam["ns_per_atom_step"])
                lam["ratio_per_grain"] = mean * r1["contacts_ns_per_grain_substep"] / lam["ns_per_atom_step"]
            if not args.keep:
                shutil.rmtree(work, ignore_errors=True)
            say(f"LAMMPS done: {lam.get('ns_per_atom_step', float('nan')):.4g} ns per atom-step")
    return out


# --------------------------------------------------------------------------- the driver


def run_one(c_pct, args) -> dict:
    cmd = [sys.executable, __file__, "--one", repr(c_pct), "--tau-ratio", repr(args.tau_ratio),
           "--spinup", repr(args.spinup), "--spinup-threads", str(args.spinup_threads), "--steps", str(args.steps),
           "--threads", *map(str, args.threads),
           "--cases", str(args.cases), "--lmp", args.lmp, "--lammps-skin", repr(args.lammps_skin),
           "--lammps-segment", str(args.lammps_segment)]
    if args.spinup_states:
        cmd += ["--spinup-states", str(args.spinup_states)]
    if not args.no_lammps and any(abs(c_pct - x) < 1e-9 for x in args.lammps_concentrations):
        cmd.append("--lammps-on")
    if args.keep:
        cmd += ["--keep", args.keep]
    res = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)  # stderr: progress, passed through
    if res.returncode != 0 or not res.stdout.strip():
        return {"concentration_pct": c_pct, "error": f"rc {res.returncode}"}
    return json.loads(res.stdout.strip().splitlines()[-1])


def sweep_estimate(rows, path, threads=1):
    """Wall time of the full sweep with WORKERS workers × 1 thread from the measured rates
    (module docstring, "Full-sweep estimate")."""
    from saltation.case.schema import load_case
    from saltation.studies.sweep import load_sweep

    # (concentration, τ*/τ*c or None: a row that does not say serves every τ) -> {domain: µs per grain-step}
    meas = {}
    for r in rows:
        if "error" in r or str(threads) not in r.get("runs", {}):
            continue
        tau = r.get("tau_ratio")
        key = (paper_c(r["concentration_pct"]), None if tau is None else round(tau, 2))
        meas.setdefault(key, {})[r.get("domain", "reduced")] = r["runs"][str(threads)]["us_per_grain_step"]
    if not meas:
        return None

    def at_c(cp, tau):
        """(µs, paper's domain, domain factor, τ measured) at a measured concentration: the
        measurement at this τ (or one that serves every τ), else at the nearest τ; on the
        paper's domain if there is one, else the reduced one times the paper/reduced ratio
        measured at another τ of this concentration (the domain factor), if any."""
        taus = [t for c, t in meas if c == cp]
        if tau in taus:
            t_used = tau
        elif None in taus:
            t_used = None
        else:
            t_used = min(taus, key=lambda t: (abs(t - tau), t))
        m = meas[(cp, t_used)]
        if "paper" in m:
            return m["paper"], True, None, t_used
        both = [t for t in taus if {"paper", "reduced"} <= set(meas[(cp, t)])]
        if both:
            f = meas[(cp, min(both, key=lambda t: 0.0 if t is None else abs(t - tau)))]
            factor = f["paper"] / f["reduced"]
            return m["reduced"] * factor, False, factor, t_used
        return m["reduced"], False, None, t_used

    cs = sorted({c for c, _ in meas})

    def cost_us(c_pct, tau):
        """(µs per grain-step, interpolated in C, paper's domain, domain factor, measured at
        another τ): linear in C between measured concentrations, constant beyond them."""
        cp = paper_c(c_pct)
        if cp in cs:
            us, full, factor, t_used = at_c(cp, tau)
            return us, False, full, factor, t_used not in (None, tau)
        lo = max((x for x in cs if x < cp), default=None)
        hi = min((x for x in cs if x > cp), default=None)
        if lo is None or hi is None:
            us, _, factor, t_used = at_c(hi if lo is None else lo, tau)
            return us, True, False, factor, t_used not in (None, tau)
        (u0, _, f0, t0), (u1, _, f1, t1) = at_c(lo, tau), at_c(hi, tau)
        return (u0 + (u1 - u0) * (cp - lo) / (hi - lo), True, False, f0 or f1,
                t0 not in (None, tau) or t1 not in (None, tau))

    sw = load_sweep(path)
    measured_dts = sorted({round(r["dt_particle"], 12) for r in rows if "dt_particle" in r})
    cases = []
    for sc in sw.cases:
        case = load_case(sc.tables, sc.values)
        if measured_dts and measured_dts != [round(case.dt_particle, 12)]:
            raise SystemExit(f"{path}: its case {sc.name} runs at dt = {case.dt_particle:g} d/u*, the measurements at "
                             f"{', '.join(f'{x:g}' for x in measured_dts)} d/u*: the cost per grain-step depends on dt "
                             "(the contact phase's work per step grows with it); measure at the sweep's dt, or give "
                             "--sweep a sweep at the measured dt")
        c_pct = 100.0 * case.concentration
        us, interp, full, factor, other_tau = cost_us(c_pct, round(case.tau_ratio, 2))
        core_s = case.n_particles * case.n_steps * us * 1e-6
        cases.append({"name": sc.name, "concentration_pct": c_pct, "tau_ratio": case.tau_ratio,
                      "n": case.n_particles, "steps": case.n_steps, "us_per_grain_step": us,
                      "interpolated": interp, "measured_on_paper_domain": full, "domain_factor": factor,
                      "other_tau": other_tau, "core_s": core_s})
    total = sum(x["core_s"] for x in cases)
    finish = [0.0] * WORKERS  # greedy longest first
    for x in sorted(cases, key=lambda x: -x["core_s"]):
        finish[finish.index(min(finish))] += x["core_s"]
    return {"sweep": str(path), "cases": cases, "core_s": total, "workers": WORKERS, "threads_per_worker": 1,
            "wall_s_even_split": total / WORKERS, "wall_s_longest_first": max(finish),
            "longest_case_s": max(x["core_s"] for x in cases),
            "days_even_split": total / WORKERS / 86400.0, "days_longest_first": max(finish) / 86400.0}


def _with_domain(rows, cases):
    """The rows, each marked with the domain it was measured on: "paper" when ``cases``
    (the run's --cases) is the full sweep, else "reduced"."""
    domain = "paper" if Path(cases).name == FULL.name else "reduced"
    return [{**r, "domain": domain} for r in rows]


def _saved_rows(paths):
    """The measured concentrations of saved --json runs, each marked with its domain."""
    rows = []
    for p in paths:
        try:
            saved = json.loads(Path(p).read_text())
            rows += _with_domain(saved["concentrations"], saved["cases"])
        except (OSError, ValueError, KeyError) as err:
            sys.exit(f"--with-json {p}: not a saved bench_dense --json run ({type(err).__name__}: {err})")
    return rows


def print_table(rows, args):
    print(f"\nCases of {Path(args.cases).name}, tau*/tau*c = {args.tau_ratio}, spin-up {args.spinup} s simulated, "
          f"{args.steps} timed steps; times in us per grain-step")
    head = (f"{'C %':>5} {'N':>5} {'thr':>3} {'g-steps/s':>10} {'us/g-st':>8} {'free fl.':>8} {'contacts':>8} "
            f"{'bed':>6} {'n_sub':>5} {'engaged':>7} {'sub-sh.':>7} {'retired':>7} {'ns/sub':>7} {'cpu/wall':>8} "
            f"{'load':>5}")
    print(head + "\n" + "-" * len(head))
    for r in rows:
        if "error" in r:
            print(f"{r['concentration_pct']:>5.2f} error: {r['error']}")
            continue
        for th, x in r["runs"].items():
            print(f"{r['concentration_pct']:>5.2f} {r['n']:>5d} {th:>3} {x['grain_steps_per_s']:>10.4g} "
                  f"{x['us_per_grain_step']:>8.3f} {x['free_flight_us']:>8.3f} {x['contacts_us']:>8.3f} "
                  f"{x['bed_us']:>6.3f} {r['substeps_per_step']:>5d} {100 * r['engaged_fraction']:>6.1f}% "
                  f"{100 * x['substep_share']:>6.1f}% {100 * x['retired_share']:>6.1f}% "
                  f"{x['contacts_ns_per_substep_done'] or 0.0:>7.0f} "
                  f"{x['cpu_per_wall']:>8.2f} {x['load_avg_1min']:>5.2f}")
    print("engaged: grains sub-stepped in a step / N; sub-sh.: grain-sub-steps done / (N n_sub); retired: share of "
          "those done retired (no contact looked for, contacts/phase.py \"Retired members\"; none in a block cut between threads); "
          "ns/sub: contact phase per grain-sub-step done")
    print("\nThe contact phase by part, us per grain-step (contacts/phase.py CLOCK_*; sub-steps also in ns per "
          "grain-sub-step done)")
    timed = [(r, th, x) for r in rows for th, x in r.get("runs", {}).items() if "contact_parts_us" in x]
    if not timed:
        print("  not in this result (saved by a version without ContactPhase.clocks)")
    else:
        names = list(timed[0][2]["contact_parts_us"])  # contacts/phase.CLOCK_NAMES, as saved
        head = f"{'C %':>5} {'thr':>3} " + " ".join(f"{p:>9}" for p in names) + f" {'ns/sub':>7}"
        print(head + "\n" + "-" * len(head))
        for r, th, x in timed:
            parts = x["contact_parts_us"]
            print(f"{r['concentration_pct']:>5.2f} {th:>3} " + " ".join(f"{parts[p]:>9.3f}" for p in names)
                  + f" {x.get('substeps_ns_per_substep_done') or 0.0:>7.0f}")
        print("list: reach of every path and neighbour-list rebuild; engage: candidates and their earliest "
              "contacts; gather: compact set, rows, near pairs, blocks; conflicts: the cross-block check (and "
              "redone passes); scatter: results back")
    for r in rows:
        if "error" in r:
            continue
        extra = f", same end state on all thread counts: {r['same_end_state']}" if "same_end_state" in r else ""
        print(f"C = {r['concentration_pct']:.2f} %: spin-up {r['spinup_s_simulated']:.3g} s ({r['spinup_steps']} steps, "
              f"{r['spinup_wall_s']:.0f} s wall on {r['spinup_threads']} thr.); touching pairs {r['touching_pairs_start']}"
              f" -> {r['touching_pairs_end']}, on the bed {r['bed_contacts_start']} -> {r['bed_contacts_end']}; "
              f"{100 * r['share_below_2d_start']:.0f} % of grains below y = 2 d{extra}")
        tr = r.get("spinup_trace") or []
        if len(tr) >= 3:
            print("    spin-up, grain-steps/s and % below 2 d at t = " + ", ".join(
                f"{x['t_s']:.2f} s: {x['grain_steps_per_s']:.3g}, {100 * x['share_below_2d']:.0f}" for x in tr[::3]))
    for r in rows:
        lam = r.get("lammps")
        if not lam:
            continue
        if "error" in lam:
            print(f"\nLAMMPS at C = {r['concentration_pct']:.2f} %: {lam['error']}")
            continue
        r1 = r["runs"].get("1", {})
        sec = lam["sections_s"]
        print(f"\nContact part against LAMMPS {lam['version']} at C = {r['concentration_pct']:.2f} % ({lam['atoms']} "
              f"grains; {lam['segments']} segments of {lam['steps_per_segment']} steps of h = {lam['timestep']:.4g} d/u*, "
              f"each from our state at its step; skin {lam['skin']} d, 1 rank, load {lam['load_avg_1min']:.2f}):")
        print(f"  LAMMPS loop {lam['loop_s']:.2f} s = {lam.get('ns_per_atom_step_first', lam['ns_per_atom_step']):.0f}"
              f" ns per atom-step (pair "
              f"{sec.get('pair', 0):.2f} s, neigh {sec.get('neigh', 0):.2f} s, modify {sec.get('modify', 0):.2f} s, "
              f"{lam['neighbor_builds']} list builds, {lam['cpu_use_percent']:.1f} % CPU)")
        print(f"  touching pairs, mean over segments: ours at the segment starts "
              f"{lam['ours_touching_pairs_at_segment_starts']:.1f}, LAMMPS first step {lam['touching_pairs_first']:.1f}"
              f", last step {lam['touching_pairs_last']:.1f}; on the bed: ours "
              f"{lam['ours_bed_contacts_at_segment_starts']:.1f}, LAMMPS {lam['bed_contacts_first']:.1f} -> "
              f"{lam['bed_contacts_last']:.1f} (no fluid in LAMMPS: the grains fall)")
        if r1:
            print(f"  ours (1 thread): contact phase {r1['contacts_s']:.2f} s = {r1['contacts_ns_per_substep_done']:.0f}"
                  f" ns per grain-sub-step done ({100 * r1['substep_share']:.1f} % of N x n_sub), "
                  f"{r1['contacts_ns_per_grain_substep']:.0f} ns per grain x sub-step of all grains")
            drift = lam.get("ours_before_after")
            if drift is not None:
                _bracket(f"ours again right after LAMMPS: contact phase {lam['ours_after']['contacts_s']:.2f} s "
                         f"({drift:.2f}x the first timing); the ratios below use the mean of the two", drift,
                         "ours before and after LAMMPS")
            again = lam.get("lammps_again_over_first")
            if again is not None:
                _bracket(f"LAMMPS again after that: {lam['ns_per_atom_step_again']:.0f} ns per atom-step ({again:.2f}x "
                         f"the first); the ratios below use the mean of the two, {lam['ns_per_atom_step']:.0f} ns",
                         again, "LAMMPS's two runs")
            elif "again_error" in lam:
                print(f"  LAMMPS again: {lam['again_error']}")
            print(f"  ratio ours/LAMMPS per engaged grain-sub-step: {lam.get('ratio_per_engaged', float('nan')):.3g}"
                  f"   (ours sub-steps only engaged grains; LAMMPS every atom every step)")
            print(f"  the same, our sub-steps alone (without the per-step set-up, which LAMMPS's steps have no "
                  f"counterpart of): {lam.get('ratio_substeps_per_engaged', float('nan')):.3g}")
            print(f"  ratio ours/LAMMPS per grain x sub-step (all grains, same physical time): "
                  f"{lam['ratio_per_grain']:.3g}   (< 1: ours is cheaper)")


def _bracket(line, factor, whose):
    """A timing repeated to bracket the other code's, and a warning when the two differ by
    more than 15 % (the machine's speed changed: the ratios then measure the machine)."""
    print(f"  {line}")
    if not 0.85 <= factor <= 1.0 / 0.85:
        print(f"  WARNING: the machine's speed changed during the comparison ({whose} differ by more than 15 %): "
              "the ratios are not reliable in this run")


def print_estimate(est):
    if not est:
        return
    print(f"\nFull sweep ({Path(est['sweep']).name}: {len(est['cases'])} cases, 200 s each, the paper's domain) "
          f"on this machine, {est['workers']} workers x 1 thread:")
    taus = sorted({x["tau_ratio"] for x in est["cases"]})
    steps = {x["tau_ratio"]: x["steps"] for x in est["cases"]}
    print("  steps per case: " + ", ".join(f"{steps[t]} at tau*/tau*c = {t}" for t in taus))
    head = f"{'C %':>5} {'N':>6} " + " ".join(f"{'us/g-st':>8} {'core-h':>7}" for _ in taus)
    print(" " * 13 + " ".join(f"{'tau*/tau*c ' + str(t):>16}" for t in taus))
    print(head + "\n" + "-" * len(head))
    by_c = {}
    for x in est["cases"]:
        by_c.setdefault(paper_c(x["concentration_pct"]), []).append(x)

    def mark(x):
        return (("*" if x["interpolated"] else "F" if x.get("measured_on_paper_domain") else
                 "R" if x.get("domain_factor") else " ") + ("T" if x.get("other_tau") else " "))

    for cp, xs in sorted(by_c.items()):
        xs.sort(key=lambda x: x["tau_ratio"])
        print(f"{cp:>5.2f} {xs[0]['n']:>6d} "
              + " ".join(f"{x['us_per_grain_step']:>6.2f}{mark(x)} {x['core_s'] / 3600:>7.1f}" for x in xs))
    print("* not measured: linear in C between the measured concentrations, constant beyond them; F: measured on "
          "the paper's domain (else on the reduced one); R: on the reduced one times the paper/reduced ratio "
          "measured at another tau*/tau*c of that concentration; T: measured at another tau*/tau*c (the nearest)")
    measured = [x["concentration_pct"] for x in est["cases"] if not x["interpolated"]]
    below = sorted({paper_c(x["concentration_pct"]) for x in est["cases"]
                    if x["interpolated"] and measured and x["concentration_pct"] < min(measured)})
    if below:
        print(f"  WARNING: {', '.join(f'{c:g}' for c in below)} % lie below the lowest measured concentration "
              f"({min(measured):.2f} %) and take its cost per grain-step, which the dilute cases do not have (a "
              "denser layer costs more): measure them, or add a run that does (--with-json)")
    print(f"  total {est['core_s'] / 3600:.0f} core-hours; wall time {est['days_even_split']:.1f} days split evenly over "
          f"{est['workers']} workers, {est['days_longest_first']:.1f} days with longest-case-first scheduling "
          f"(longest case {est['longest_case_s'] / 86400:.1f} days)")
    print("  assumes: cost per grain-step independent of domain size below the percolating concentrations (R: "
          "the paper/reduced ratio independent of tau*/tau*c), T: of tau*/tau*c, the post-spin-up state "
          "representative of 200 s, a free core per worker; stepping only (no outputs: jumps, variances, "
          "checkpoints)")
    reduced = sorted({paper_c(x["concentration_pct"]) for x in est["cases"]
                      if x["concentration_pct"] >= PERCOLATING_C - 0.005 and not x.get("measured_on_paper_domain")
                      and not x.get("domain_factor")})
    if reduced:
        print(f"  the domain size does matter where the near-bed layer percolates (from {PERCOLATING_C} %: module "
              f"docstring); {', '.join(f'{c:g}' for c in reduced)} % came from the reduced domain, so this estimate "
              "is low; --cases cases/concentration_sweep.toml measures the paper's domain, --with-json adds such a run")


# issue 19's targets, on one thread in the reduced case at 3.94 % (realised: 3.9405 %)
TARGET_C = 3.94
TARGET_GRAIN_STEPS = 2.7e5  # grain-steps/s
TARGET_CONTACTS_OVER_FREE = 3.0  # contact phase / free flight, the same run
TARGET_SWEEP_DAYS = 5.0
TARGET_SPINUP_S = 1.0  # s simulated: the dense near-bed layer forms over ~1 s
TARGET_DT = 0.02  # d/u*: the case; a grain-step at another dt covers another time


def print_targets(rows, est):
    """This run against issue 19's targets, each marked met or missed. The contact phase
    over the free flight of the same run is the figure least moved by a shared machine's
    drift."""
    r = next((r for r in rows if "runs" in r and paper_c(r["concentration_pct"]) == TARGET_C), None)
    x = r["runs"].get("1") if r else None
    formed = r is not None and r["spinup_s_simulated"] >= 0.99 * TARGET_SPINUP_S  # to the nearest step
    reduced = r is None or r.get("domain") != "paper"  # the targets' case is the reduced one
    same_dt = r is None or abs(r.get("dt_particle", TARGET_DT) - TARGET_DT) < 1e-12
    mark = lambda ok: ("met" if ok else "MISSED") if formed and reduced and same_dt else "not comparable"  # noqa: E731
    mark_est = lambda ok: ("met" if ok else "MISSED") if formed else "not comparable"  # noqa: E731
    print("\nTargets (issue 19), this run:")
    if x is None:
        print(f"  C = {TARGET_C} % not measured on one thread in this run")
    else:
        if not reduced:
            print("  (measured on the paper's domain: the per-step targets are for the reduced case)")
        if not formed:
            print(f"  (spin-up {r['spinup_s_simulated']:.3g} s < {TARGET_SPINUP_S:g} s: the dense near-bed layer has "
                  f"not formed, so this is not the state the targets are for)")
        if not same_dt:
            dt = r["dt_particle"]
            print(f"  (dt = {dt:g} d/u*: the per-step targets are for the issue's case at {TARGET_DT:g} d/u*; per "
                  f"simulated time this run's one thread does {x['grain_steps_per_s'] * dt / TARGET_DT:.3g} grain-steps "
                  f"of {TARGET_DT:g} d/u* per second)")
        gs, ratio = x["grain_steps_per_s"], x["contacts_us"] / x["free_flight_us"]
        print(f"  C = {TARGET_C} %, one thread: {gs:.3g} grain-steps/s against >= {TARGET_GRAIN_STEPS:.3g}: "
              f"{mark(gs >= TARGET_GRAIN_STEPS)}")
        print(f"  C = {TARGET_C} %, one thread: contact phase / free flight {ratio:.2f} against <= "
              f"{TARGET_CONTACTS_OVER_FREE:g}: {mark(ratio <= TARGET_CONTACTS_OVER_FREE)}")
    if est:
        days = est["days_longest_first"]
        print(f"  full-sweep estimate {days:.1f} days against <= {TARGET_SWEEP_DAYS:g}: {mark_est(days <= TARGET_SWEEP_DAYS)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concentrations", type=float, nargs="+", default=list(PAPER_C), help="%% (default all eight)")
    ap.add_argument("--tau-ratio", type=float, default=1.79)
    ap.add_argument("--spinup", type=float, default=1.0, help="simulated seconds before timing (default 1.0)")
    ap.add_argument("--spinup-threads", type=int, default=1,
                    help="threads for the spin-up (default 1: on a shared machine 2 threads can be much slower)")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--no-lammps", action="store_true")
    ap.add_argument("--lammps-concentrations", type=float, nargs="+", default=[3.94])
    ap.add_argument("--lammps-skin", type=float, default=0.3)
    ap.add_argument("--lammps-segment", type=int, default=10,
                    help="hydrodynamic steps per LAMMPS segment, each started from our state at that step")
    ap.add_argument("--lmp", default="lmp")
    ap.add_argument("--keep", default=None, help="keep the LAMMPS files under this directory")
    ap.add_argument("--cases", default=str(REDUCED),
                    help="sweep file the measured cases come from (default the reduced sweep; the full sweep "
                         "cases/concentration_sweep.toml checks the domain-size assumption)")
    ap.add_argument("--sweep", default=None,
                    help=f"the full sweep to estimate (default {FULL.relative_to(ROOT)}; with --print-json, the saved run's)")
    ap.add_argument("--spinup-states", default=None, metavar="DIR",
                    help="save each spun-up state here, and load it instead of spinning up when it is there")
    ap.add_argument("--json", default=None)
    ap.add_argument("--print-json", default=None, metavar="FILE", help="print the table and estimate of a saved --json")
    ap.add_argument("--with-json", nargs="+", default=[], metavar="FILE",
                    help="saved --json runs whose concentrations join the estimate (not the table or the targets); "
                         "a measurement on the paper's domain replaces one on the reduced domain")
    ap.add_argument("--one", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--lammps-on", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one_concentration(args)))
        return
    if args.print_json:  # the table and the estimate again, from a saved --json
        saved = json.loads(Path(args.print_json).read_text())
        for k in ("tau_ratio", "spinup", "steps", "cases"):
            key = {"spinup": "spinup_s"}.get(k, k)
            if key in saved:
                setattr(args, k, saved[key])
        args.sweep = args.sweep or saved.get("sweep") or str(FULL)  # a --sweep given wins
        if not Path(args.sweep).is_file():
            sys.exit(f"--print-json {args.print_json}: its sweep file {args.sweep} is not there (saved from another "
                     f"checkout?): name one with --sweep, e.g. --sweep {FULL.relative_to(ROOT)}")
        rows = sorted(_with_domain(saved["concentrations"], args.cases), key=lambda r: r["concentration_pct"])
        print_table(rows, args)
        est = sweep_estimate(rows + _saved_rows(args.with_json), args.sweep)
        print_estimate(est)
        print_targets(rows, est)
        print(f"\n(saved {saved.get('date')}, command: {saved.get('command')})")
        return
    args.sweep = args.sweep or str(FULL)
    import saltation

    t0 = time.perf_counter()
    start = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_avg": os.getloadavg(), "cpu_count": os.cpu_count(),
             "command": " ".join(sys.argv),
             # which code is measured: an editable install wins over this script's own tree
             # unless PYTHONPATH names it
             "saltation": str(Path(saltation.__file__).parent),
             # idle OpenMP threads' spin (flowfields/_openmp.py): it moves the two-thread figures
             "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"), "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY")}
    rows = []
    for c in args.concentrations:
        rows.append(run_one(c, args))
        print(f"[done C = {c} %, {time.perf_counter() - t0:.0f} s so far]", file=sys.stderr, flush=True)
        if args.json:  # what is done so far, in case the run is cut short
            with open(args.json, "w") as fh:
                json.dump({**start, "partial": True, "concentrations": rows}, fh, indent=1)
    rows = sorted(_with_domain(rows, args.cases), key=lambda r: r["concentration_pct"])
    print_table(rows, args)
    est = sweep_estimate(rows + _saved_rows(args.with_json), args.sweep)
    print_estimate(est)
    print_targets(rows, est)
    result = {**start, "tau_ratio": args.tau_ratio, "spinup_s": args.spinup, "steps": args.steps,
              "cases": str(args.cases), "sweep": str(args.sweep),
              "threads": args.threads, "concentrations": rows, "with_json": args.with_json, "full_sweep_estimate": est,
              "wall_s": time.perf_counter() - t0, "load_avg_end": os.getloadavg()}
    print(f"\n(benchmark wall time {result['wall_s']:.0f} s; load average at start {start['load_avg'][0]:.2f}, "
          f"end {result['load_avg_end'][0]:.2f}, {os.cpu_count()} CPUs; GOMP_SPINCOUNT {start['gomp_spincount']}, "
          f"OMP_WAIT_POLICY {start['omp_wait_policy']}; code measured: {start['saltation']})")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
