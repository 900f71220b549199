"""Rigid-body integrator of saltation.flight.composites against LAMMPS ``fix rigid`` (no fluid).

Two checks on the same clump (an asymmetric equant of sub-type 4, four spheres, three
distinct principal moments, non-diagonal inertia in its geometric frame; scaled to
Dn = 1; density (1+R) = 2.65 in LAMMPS lj units, g = 1 where gravity is on):

1. torque-free rotation: no gravity, initial Ω = (1.0, 2.0, 0.5), random orientation;
   angular velocity components vs time (LAMMPS: ``fix rigid single``, dt = 1e-3,
   per-atom omega = the body's Ω; ours: RK4, dt = 0.01).
2. a drop onto a plane: gravity, initial height 2, tumbling; LAMMPS ``fix wall/gran
   hooke`` on y = 0 with k_n = 2·10⁶, no damping, no friction (elastic, frictionless:
   the soft contact is then the limit of our hard impulse, e = 1, f = 0, flat bed),
   dt = 2e-5 (≈ 60 steps per contact); ours: dt = 0.002 with the rigid-body impulse at
   the lowest component. Centre-of-mass height and Ω vs time.

Prints the largest differences (absolute, in units of the initial |Ω| or Dn) and writes
lammps_rigid.csv/.json and lammps_rigid.png.

    python benchmarks/shapes_lammps.py [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from saltation.bed.virtual import bed_parameters
from saltation.flight import composites as clusters
from saltation.grains import shapes
from saltation.physics import history
from saltation.physics.forces import make_coefficients

R = 1.65
TAU_STAR = 1.0 / (1.0 + R)  # g_eff = 1/((1+R) τ*) = 1


def clump():
    g = shapes.build(1.0, 0.8, 0.6)
    return g.scaled(1.0 / g.nominal_diameter)


def initial(seed=2):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _lammps_input(comp, pos, vel, quat, omega, *, gravity, wall, dt, steps, every, dump, kn=2.0e6):
    rot = clusters.quat_to_matrix_py(np.asarray(quat, float))
    rw = comp.centres @ rot.T
    lines = ["units lj", "atom_style sphere", "boundary f f f", "comm_modify vel yes",
             "region box block -50 50 -1 60 -50 50", "create_box 1 box"]
    for r in rw:
        x = np.asarray(pos) + r
        lines.append(f"create_atoms 1 single {x[0]:.17g} {x[1]:.17g} {x[2]:.17g}")
    for k, r in enumerate(rw):
        v = np.asarray(vel) + np.cross(omega, r)
        lines += [f"set atom {k + 1} diameter {comp.diameters[k]:.17g} density {1 + R:.17g}",
                  f"set atom {k + 1} vx {v[0]:.17g} vy {v[1]:.17g} vz {v[2]:.17g}",
                  f"set atom {k + 1} omega {omega[0]:.17g} {omega[1]:.17g} {omega[2]:.17g}"]
    lines += ["neighbor 0.3 bin", "neigh_modify exclude type 1 1", f"timestep {dt}",
              "thermo_style custom step", "thermo 1000000"]
    if gravity:
        lines.append("fix g all gravity 1.0 vector 0 -1 0")
    lines.append("fix r all rigid single")
    if wall:
        lines.append(f"fix w all wall/gran hooke {kn:g} NULL 0.0 NULL 0.0 0 yplane 0.0 NULL")
    lines += ["variable ycm equal xcm(all,y)", "variable xcm equal xcm(all,x)",
              "variable wx equal omega(all,x)", "variable wy equal omega(all,y)", "variable wz equal omega(all,z)",
              f"fix p all print {every} \"${{xcm}} ${{ycm}} ${{wx}} ${{wy}} ${{wz}}\" file {dump} screen no",
              f"run {steps}"]
    return "\n".join(lines) + "\n"


def run_lammps(comp, pos, vel, quat, omega, *, gravity, wall, dt, t_end, every_t, kn=2.0e6):
    exe = shutil.which("lmp")
    if exe is None:
        raise FileNotFoundError("lmp not on PATH")
    steps = int(round(t_end / dt))
    every = int(round(every_t / dt))
    with tempfile.TemporaryDirectory() as tmp:
        dump = Path(tmp) / "out.txt"
        (Path(tmp) / "in.rigid").write_text(_lammps_input(comp, pos, vel, quat, omega, gravity=gravity, wall=wall,
                                                         dt=dt, steps=steps, every=every, dump=dump, kn=kn))
        subprocess.run([exe, "-in", "in.rigid", "-log", "none", "-screen", "none"], cwd=tmp, check=True,
                       timeout=600)
        data = np.loadtxt(dump, comments="#")
    t = np.arange(len(data)) * every * dt
    return t, data  # columns x_cm, y_cm, Ω_x, Ω_y, Ω_z


def run_ours(comp, pos, vel, quat, omega, *, gravity, wall, dt, t_end, every_t):
    from flowfields import profile_dataset

    coef = make_coefficients(tau_star=TAU_STAR, R=R, re_star=10.0, Cm=0.0, weight=gravity, drag=False,
                             lift=False, magnus=False, added_mass=False, fluid_acceleration=False, basset=False)
    still = profile_dataset("still", y_top_plus=1e6)
    st = clusters.make_cluster_state([comp], [pos], [vel], [quat], [omega], 0.0, 10, R=R, Cm=0.0, re_star=10.0,
                                     spin_drag=False, jump_capacity=1000)
    w = clusters.make_cluster_work(st)
    hc = history.make_history_coefficients(dt, 10)
    bed = bed_parameters(1.0, 0.0, 1e-12)  # elastic, frictionless, flat
    every = int(round(every_t / dt))
    n = int(round(t_end / every_t))
    rows = [[st.pos[0, 0], st.pos[0, 1], *st.omega[0]]]
    hits = [0]
    for i in range(n):
        if not wall:
            st.pos[0, 1] = 1e6  # never near the bed
        clusters.advance_clusters(still.arrays, coef, bed, 0, st, w, hc, i * every * dt, dt, every, 1e30)
        y = st.pos[0, 1] if wall else pos[1]
        rows.append([st.pos[0, 0], y, *st.omega[0]])
        hits.append(int(st.impacts[0]))
    return np.arange(n + 1) * every_t, np.array(rows), np.array(hits)


def compare(out=None):
    comp = clump()
    q = initial()
    res = {}
    # 1. torque-free rotation
    om = np.array([1.0, 2.0, 0.5])
    kw = dict(gravity=False, wall=False, t_end=20.0, every_t=0.1)
    tl, dl = run_lammps(comp, [0, 30, 0], [0.0, 0, 0], q, om, dt=1e-3, **kw)
    to, do, _ = run_ours(comp, [0, 30, 0], [0.0, 0, 0], q, om, dt=0.01, **kw)
    m = min(len(tl), len(to))
    dw = np.abs(dl[:m, 2:5] - do[:m, 2:5]).max()
    res["free_rotation"] = dict(t_end=20.0, max_abs_omega_diff=float(dw),
                                omega_norm=float(np.linalg.norm(om)),
                                omega_range=[float(do[:, 2:5].min()), float(do[:, 2:5].max())])
    free = (tl[:m], dl[:m], do[:m])
    # 2. drop onto a plane
    om2 = np.array([0.5, -1.0, 2.0])
    kw = dict(gravity=True, wall=True, t_end=6.0, every_t=0.02)
    to2, do2, hits = run_ours(comp, [0, 2.0, 0], [0.3, 0, 0], q, om2, dt=0.002, **kw)
    # samples whose preceding interval holds an impact may catch LAMMPS inside its
    # (finite) soft contact: left out of the comparison
    hit = np.concatenate([[False], np.diff(hits) != 0])
    free_of_contact = ~(hit | np.concatenate([hit[1:], [False]]))  # and the sample before
    res["drop"] = dict(t_end=6.0, impacts_ours=int(hits[-1]), omega_norm=float(np.linalg.norm(om2)))
    for kn, dtl in ((2.0e6, 2e-5), (2.0e7, 5e-6)):
        tl2, dl2 = run_lammps(comp, [0, 2.0, 0], [0.3, 0, 0], q, om2, dt=dtl, kn=kn, **kw)
        m2 = min(len(tl2), len(to2))
        ok = free_of_contact[:m2]
        res["drop"][f"kn={kn:g}"] = dict(
            lammps_dt=dtl, contact_time=math.pi * math.sqrt((1 + R) * comp.volume / kn),
            max_abs_ycm_diff=float(np.abs(dl2[:m2, 1] - do2[:m2, 1])[ok].max()),
            max_abs_xcm_diff=float(np.abs(dl2[:m2, 0] - do2[:m2, 0])[ok].max()),
            max_abs_omega_diff=float(np.abs(dl2[:m2, 2:5] - do2[:m2, 2:5])[ok].max()),
            samples_compared=int(ok.sum()), samples=int(m2))
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "lammps_rigid.json").write_text(json.dumps(res, indent=1))
        hdr = "t,lmp_x,lmp_y,lmp_wx,lmp_wy,lmp_wz,our_x,our_y,our_wx,our_wy,our_wz"
        np.savetxt(out / "lammps_rigid_free.csv", np.column_stack([free[0], free[1], free[2]]), delimiter=",",
                   header=hdr, comments="")
        np.savetxt(out / "lammps_rigid_drop.csv", np.column_stack([tl2[:m2], dl2[:m2], do2[:m2]]), delimiter=",",
                   header=hdr, comments="")
        _figure(free, (tl2[:m2], dl2[:m2], do2[:m2]), out / "lammps_rigid.png")
    return res


def _figure(free, drop, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for j, c in enumerate("xyz"):
        ax[0].plot(free[0], free[1][:, 2 + j], "-", lw=2, alpha=0.5, label=f"LAMMPS Ω{c}")
        ax[0].plot(free[0], free[2][:, 2 + j], "k:", lw=1)
        ax[2].plot(drop[0], drop[1][:, 2 + j], "-", lw=2, alpha=0.5, label=f"LAMMPS Ω{c}")
        ax[2].plot(drop[0], drop[2][:, 2 + j], "k:", lw=1)
    ax[0].set_title("torque-free rotation (dotted: ours)")
    ax[1].plot(drop[0], drop[1][:, 1], "-", lw=2, alpha=0.5, label="LAMMPS y_cm")
    ax[1].plot(drop[0], drop[2][:, 1], "k:", label="ours")
    ax[1].set_title("drop onto a plane: centre-of-mass height")
    ax[2].set_title("drop: angular velocity")
    for a in ax:
        a.set_xlabel("t")
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="lammps_rigid")
    args = ap.parse_args(argv)
    print(json.dumps(compare(args.out), indent=1))


if __name__ == "__main__":
    main()
