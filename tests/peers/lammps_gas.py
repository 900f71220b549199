"""LAMMPS input for the granular-gas comparison (issue 4): the same set-up written for
``lmp`` by the cooling test (tests/test_lammps_cooling.py) and the contact-kernel
benchmark (benchmarks/bench_contacts_lammps.py).

Equal spheres of diameter 1 and mass 1 (LAMMPS ``units lj``; density 6/π) in a periodic
cube of side ``length``, ``pair_style gran/hooke/history`` with the stiffness, damping and
friction of a ``contacts.pairs.ContactModel``, ``fix nve/sphere``, ``neighbor SKIN bin`` checked
every step. Values are written with ``repr`` so that LAMMPS reads the same doubles.
"""
from __future__ import annotations

import math


def write_gas_data(path, pos, vel, spin, length) -> None:
    """LAMMPS data file (atom_style sphere) of N grains: positions, velocities, spins."""
    lines = ["saltation granular gas", "", f"{len(pos)} atoms", "1 atom types", ""]
    lines += [f"0 {float(length)!r} {a}lo {a}hi" for a in "xyz"]
    lines += ["", "Atoms # sphere", ""]
    lines += [f"{i + 1} 1 1.0 {6.0 / math.pi!r} " + " ".join(repr(float(x)) for x in p) for i, p in enumerate(pos)]
    lines += ["", "Velocities", ""]
    lines += [f"{i + 1} " + " ".join(repr(float(x)) for x in (*v, *w)) for i, (v, w) in enumerate(zip(vel, spin))]
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def gas_input(model, dt: float, n_steps: int, every: int, skin: float) -> str:
    """Input script reading ``data.gas``: gran/hooke/history with model's k_n, k_t, γ_n,
    γ_t, μ; prints translational and rotational kinetic energy every ``every`` steps."""
    dampflag = 1 if model.gamma_t > 0.0 else 0
    return f"""units lj
atom_style sphere
atom_modify map array
boundary p p p
comm_modify vel yes
read_data data.gas
set group all mass 1.0
pair_style gran/hooke/history {model.kn!r} {model.kt!r} {model.gamma_n!r} {model.gamma_t!r} {model.friction!r} {dampflag}
pair_coeff * *
neighbor {skin!r} bin
neigh_modify delay 0 every 1 check yes
fix integrate all nve/sphere
timestep {dt!r}
compute rke all erotate/sphere
thermo_style custom step ke c_rke
thermo_modify norm no format float %.17g
thermo {every}
run {n_steps}
"""
