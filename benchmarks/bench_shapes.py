"""Cost of composite grains per component sphere vs the point-particle (sphere) cost per
particle, same flow (the shipped LES), same forces (all on), one thread by default.

Prints JSON: ns per particle-step (spheres), ns per component-step (composites of the
Smith mixture), their ratio (target ≤ 1.5), mean components per grain. Compile time is
excluded (one warm-up call first).

    python benchmarks/bench_shapes.py [--grains 200] [--steps 1000] [--threads 1]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numba
import numpy as np

from flowfields import open_dataset
from saltation.bed.virtual import bed_parameters
from saltation.flight import composites as clusters
from saltation.flight import spheres as integrator
from saltation.grains import shapes
from saltation.physics import history
from saltation.physics.forces import CM, make_coefficients

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "peers"))
from sphere_advance import advance  # noqa: E402  (tests/peers: the flight-and-bed loop without contacts)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--grains", type=int, default=200)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    numba.set_num_threads(a.threads)
    ds = open_dataset()
    re_star = 10.0
    coef = make_coefficients(tau_star=0.06, R=1.65, re_star=re_star)
    dt, nw = 0.01, 10
    hc = history.make_history_coefficients(dt, nw)
    bed = bed_parameters(0.65, 0.1, np.radians(30))
    top = float(ds.y[-1]) / re_star
    n = a.grains
    rng = np.random.default_rng(0)
    pos = np.column_stack([rng.uniform(0, 100, n), rng.uniform(1.5, 3, n), rng.uniform(0, 100, n)])
    vel = np.column_stack([rng.uniform(1, 4, n), rng.uniform(0.5, 2, n), rng.uniform(-.5, .5, n)])
    spin = np.zeros((n, 3))
    f = ds.arrays
    st = integrator.make_state(pos, vel, spin, 0.0, nw)
    w = integrator.make_workspace(n)
    advance(f, coef, bed, 0, st, w, hc, 0.0, dt, 1, top)
    t0 = time.perf_counter()
    advance(f, coef, bed, 0, st, w, hc, dt, dt, a.steps, top)
    t_sph = time.perf_counter() - t0
    comps = [c.scaled(1.0 / c.nominal_diameter) for c in shapes.mixture(n, Dn=1e-3, seed=1)]
    quat = rng.normal(size=(n, 4))
    cst = clusters.make_cluster_state(comps, pos, vel, quat, spin, 0.0, nw, R=1.65, Cm=coef[CM], re_star=re_star)
    cw = clusters.make_cluster_work(cst)
    clusters.advance_clusters(f, coef, bed, 0, cst, cw, hc, 0.0, dt, 1, top)
    t0 = time.perf_counter()
    clusters.advance_clusters(f, coef, bed, 0, cst, cw, hc, dt, dt, a.steps, top)
    t_cl = time.perf_counter() - t0
    k = int(cst.cstart[-1])
    ns_sph = 1e9 * t_sph / (n * a.steps)
    ns_comp = 1e9 * t_cl / (k * a.steps)
    print(json.dumps(dict(threads=a.threads, grains=n, steps=a.steps, components=k,
                          components_per_grain=k / n, ns_per_sphere_step=ns_sph,
                          ns_per_component_step=ns_comp, ns_per_composite_step=1e9 * t_cl / (n * a.steps),
                          ratio_component_to_sphere=ns_comp / ns_sph, target=1.5), indent=1))


if __name__ == "__main__":
    main()
