"""A priori test of the bonded-sphere grains (seed 000 §3, Figs. 5-6).

100 random composites of the Smith (2003) mixture, Dl uniform in 0.2-2 mm, axis ratios
uniform in each Zingg class (saltation.grains.shapes.DEFAULT_RATIOS), built with the
seed paper's construction and/or the fitted one (``shapes.build(..., method=)``): mass
and the three moments of inertia about the geometric axes (x long, y intermediate,
z short, through the centre of mass) against (1) the ellipsoid with the same axes and
(2) the elliptic cylinder of length Dl and section Di × Ds; besides, the principal
moments (eigenvalues of the inertia tensor, ascending) against the ellipsoid's (ascending)
and the grain's extent along each axis over the axis. Writes apriori.csv (one row per
grain and method), apriori_summary.json (per method and class: mean/min/max ratios,
fractions within 15 % in mass and within 25 % in every principal moment — and the paper's
25 % for both —, the worst errors, the build time) and apriori.png (mass and inertia
scatter vs both references, one colour per construction, 1:1 and ×0.8, ×1.25 lines;
with --method both a third row of per-grain principal-moment errors), and prints the
statistics.

    python benchmarks/shapes_apriori.py [--out DIR] [--n 100] [--seed 1] [--method seed|fitted|both]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from saltation.grains import shapes

DENSITY = 2650.0  # kg/m³ (quartz; the ratios do not depend on it)


METHODS = shapes.METHODS
COLOURS = {"seed": "tab:red", "fitted": "tab:blue"}
MASS_TOL = 0.15  # the fitted construction's target (issue 20): |m/m_ell − 1| ≤ 15 %
MOMENT_TOL = 0.25  # … and every principal moment within 25 % (the paper's a priori band)


def apriori(n=100, seed=1, Dl_range=(0.2e-3, 2.0e-3), method="seed") -> pd.DataFrame:
    """One row per grain: axes, class, mass and moments of the composite built with
    ``method`` and of the two references, and their ratios (``build_s``: wall time of
    building all n grains, the same in every row)."""
    shapes.check_method(method)
    cls, axes = shapes.draw_axes(n, Dl_range=Dl_range, seed=seed)
    t0 = time.perf_counter()
    comps = [shapes.build(*a, method=method) for a in axes]
    build_s = time.perf_counter() - t0
    rows = []
    for c, a, comp in zip(cls, axes, comps):
        me, ie = shapes.ellipsoid_properties(*a, density=DENSITY)
        mc, ic = shapes.cylinder_properties(*a, density=DENSITY)
        i = np.diag(comp.inertia_tensor(DENSITY))
        ip = comp.principal_moments(DENSITY)  # ascending
        ext = comp.extent() / a
        rows.append(dict(method=method, zingg_class=c, subtype=comp.subtype, n_spheres=comp.n_spheres,
                         Dl_m=a[0], Di_m=a[1], Ds_m=a[2], mass_kg=comp.mass(DENSITY),
                         mass_ellipsoid_kg=me, mass_cylinder_kg=mc,
                         **{f"I{k}_kgm2": i[j] for j, k in enumerate("xyz")},
                         **{f"I{k}_ellipsoid_kgm2": ie[j] for j, k in enumerate("xyz")},
                         **{f"I{k}_cylinder_kgm2": ic[j] for j, k in enumerate("xyz")},
                         **{f"I{j + 1}_principal_kgm2": ip[j] for j in range(3)},
                         **{f"extent_{k}_over_axis": ext[j] for j, k in enumerate("xyz")},
                         build_s=build_s))
    df = pd.DataFrame(rows)
    df["mass_ratio_ellipsoid"] = df.mass_kg / df.mass_ellipsoid_kg
    df["mass_ratio_cylinder"] = df.mass_kg / df.mass_cylinder_kg
    for k in "xyz":
        df[f"I{k}_ratio_ellipsoid"] = df[f"I{k}_kgm2"] / df[f"I{k}_ellipsoid_kgm2"]
        df[f"I{k}_ratio_cylinder"] = df[f"I{k}_kgm2"] / df[f"I{k}_cylinder_kgm2"]
    # the ellipsoid's principal moments ascending are Ix ≤ Iy ≤ Iz (Dl ≥ Di ≥ Ds)
    for j, k in enumerate("xyz"):
        df[f"I{j + 1}_principal_ratio_ellipsoid"] = df[f"I{j + 1}_principal_kgm2"] / df[f"I{k}_ellipsoid_kgm2"]
    return df


def both(n=100, seed=1, Dl_range=(0.2e-3, 2.0e-3), methods=METHODS) -> pd.DataFrame:
    return pd.concat([apriori(n, seed, Dl_range, m) for m in methods], ignore_index=True)


def _principal(g) -> np.ndarray:
    return g[[f"I{j}_principal_ratio_ellipsoid" for j in (1, 2, 3)]].to_numpy()


def summarise(df: pd.DataFrame) -> dict:
    """{method: {"all" | class: statistics}} (a frame without a method column: "seed")."""
    if "method" not in df:
        df = df.assign(method="seed")
    out = {}
    for method in [m for m in METHODS if m in set(df.method)]:
        dm = df[df.method == method]
        res = {}
        groups = [("all", dm)] + [(c, dm[dm.zingg_class == c]) for c in shapes.CLASSES]
        for name, g in groups:
            if len(g) == 0:
                continue
            ie = g[[f"I{k}_ratio_ellipsoid" for k in "xyz"]].to_numpy()
            ic = g[[f"I{k}_ratio_cylinder" for k in "xyz"]].to_numpy()
            ip = _principal(g)
            me = g.mass_ratio_ellipsoid.to_numpy()
            ext = g[[f"extent_{k}_over_axis" for k in "xyz"]].to_numpy()
            res[name] = dict(
                count=int(len(g)),
                mass_ratio_ellipsoid_mean=float(me.mean()), mass_ratio_ellipsoid_min=float(me.min()),
                mass_ratio_ellipsoid_max=float(me.max()),
                mass_within_25pct=float(np.mean((me >= 0.8) & (me <= 1.25))),
                inertia_ratio_ellipsoid_min=float(ie.min()), inertia_ratio_ellipsoid_max=float(ie.max()),
                inertia_within_25pct=float(np.mean((ie >= 0.8) & (ie <= 1.25))),
                # per grain: |m/m_ell − 1| ≤ 15 %; every principal moment |I/I_ell − 1| ≤ 25 %
                mass_within_15pct=float(np.mean(np.abs(me - 1.0) <= MASS_TOL)),
                principal_within_25pct=float(np.mean((np.abs(ip - 1.0) <= MOMENT_TOL).all(axis=1))),
                both_within=float(np.mean((np.abs(me - 1.0) <= MASS_TOL)
                                          & (np.abs(ip - 1.0) <= MOMENT_TOL).all(axis=1))),
                worst_mass_error=float(np.abs(me - 1.0).max()),
                worst_principal_error=float(np.abs(ip - 1.0).max()),
                worst_axis_moment_error=float(np.abs(ie - 1.0).max()),
                extent_over_axis_max=float(ext.max()),
                mass_above_cylinder=int((g.mass_ratio_cylinder > 1.0).sum()),
                inertia_above_cylinder=int((ic > 1.0).any(axis=1).sum()),
                mass_ratio_cylinder_max=float(g.mass_ratio_cylinder.max()),
                inertia_ratio_cylinder_max=float(ic.max()),
            )
        res["all"]["build_s"] = float(dm.build_s.iloc[0])
        out[method] = res
    return out


def figure(df: pd.DataFrame, path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if "method" not in df:
        df = df.assign(method="seed")
    methods = [m for m in METHODS if m in set(df.method)]
    fig, ax = plt.subplots(3, 2, figsize=(10, 13))
    markers = dict(disk="o", blade="s", rod="^", equant="D")
    for row, ref in enumerate(("ellipsoid", "cylinder")):
        for col, what in enumerate(("mass", "I")):
            a = ax[row, col]
            for m in methods:
                for c in shapes.CLASSES:
                    g = df[(df.zingg_class == c) & (df.method == m)]
                    if what == "mass":
                        a.loglog(g[f"mass_{ref}_kg"], g.mass_kg, markers[c], ms=4, color=COLOURS[m],
                                 mfc="none" if m == "seed" else COLOURS[m], alpha=0.8, label=f"{m}: {c}")
                    else:
                        x = g[[f"I{k}_{ref}_kgm2" for k in "xyz"]].to_numpy().ravel()
                        y = g[[f"I{k}_kgm2" for k in "xyz"]].to_numpy().ravel()
                        a.loglog(x, y, markers[c], ms=3, color=COLOURS[m],
                                 mfc="none" if m == "seed" else COLOURS[m], alpha=0.7,
                                 label=f"{m}: {c} (Ix, Iy, Iz)")
            lo = min(a.get_xlim()[0], a.get_ylim()[0])
            hi = max(a.get_xlim()[1], a.get_ylim()[1])
            x = np.array([lo, hi])
            a.plot(x, x, "k-", lw=1)
            a.plot(x, 0.8 * x, "k--", lw=0.8)
            a.plot(x, 1.25 * x, "k--", lw=0.8)
            unit = "kg" if what == "mass" else "kg m²"
            a.set_xlabel(f"{'mass' if what == 'mass' else 'moment of inertia'} of the {ref} ({unit})")
            a.set_ylabel(f"composite ({unit})")
            a.legend(fontsize=6, ncol=2)
    # per grain: mass error against the worst principal-moment error, with the target box
    a = ax[2, 0]
    for m in methods:
        g = df[df.method == m]
        a.plot(100 * (g.mass_ratio_ellipsoid - 1.0), 100 * np.abs(_principal(g) - 1.0).max(axis=1), "o",
               ms=4, color=COLOURS[m], mfc="none" if m == "seed" else COLOURS[m], label=m)
    a.axvspan(-100 * MASS_TOL, 100 * MASS_TOL, color="0.9", zorder=0)
    a.axhline(100 * MOMENT_TOL, color="k", ls="--", lw=0.8)
    a.set_xlabel("mass error vs ellipsoid (%)")
    a.set_ylabel("worst principal-moment error (%)")
    a.set_title(f"target: |mass| ≤ {100 * MASS_TOL:.0f} % (shaded), moments ≤ {100 * MOMENT_TOL:.0f} % (dashed)",
                fontsize=8)
    a.legend(fontsize=7)
    a = ax[2, 1]
    for m in methods:
        g = df[df.method == m]
        e = np.sort(np.maximum(np.abs(g.mass_ratio_ellipsoid - 1.0) / MASS_TOL,
                               np.abs(_principal(g) - 1.0).max(axis=1) / MOMENT_TOL))
        a.plot(e, np.arange(1, len(e) + 1) / len(e), "-", color=COLOURS[m], label=m)
    a.axvline(1.0, color="k", ls="--", lw=0.8)
    a.set_xlabel("worst error over its tolerance (mass/15 %, moments/25 %)")
    a.set_ylabel("fraction of grains")
    a.set_xscale("log")
    a.legend(fontsize=7)
    fig.suptitle("Bonded-sphere grains (" + " vs ".join(f"{m}: {COLOURS[m][4:]}" for m in methods)
                 + ") vs ellipsoid (top) and elliptic cylinder (middle); lines 1:1, ×0.8, ×1.25", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="apriori")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--method", choices=(*METHODS, "both"), default="both",
                    help="construction(s) to test (shapes.build's method); default both")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    methods = METHODS if args.method == "both" else (args.method,)
    df = both(args.n, args.seed, methods=methods)
    df.to_csv(out / "apriori.csv", index=False)
    s = summarise(df)
    (out / "apriori_summary.json").write_text(json.dumps(s, indent=1))
    figure(df, out / "apriori.png")
    for m, res in s.items():
        print(f"== {m} construction: {res['all']['count']} grains built in {res['all']['build_s']:.2f} s")
        print(f"{'class':<7} {'n':>3} {'m/m_ell mean [min,max]':>24} {'m in 15%':>8} {'I/I_ell [min,max]':>18} "
              f"{'Ip in 25%':>9} {'worst m':>7} {'worst Ip':>8} {'ext/D max':>9} {'m>cyl':>5} {'I>cyl':>5}")
        for k, v in res.items():
            print(f"{k:<7} {v['count']:3d} {v['mass_ratio_ellipsoid_mean']:8.3f} [{v['mass_ratio_ellipsoid_min']:.2f},"
                  f"{v['mass_ratio_ellipsoid_max']:.2f}] {100 * v['mass_within_15pct']:7.0f}% "
                  f"[{v['inertia_ratio_ellipsoid_min']:.2f},{v['inertia_ratio_ellipsoid_max']:.2f}] "
                  f"{100 * v['principal_within_25pct']:8.0f}% {100 * v['worst_mass_error']:6.1f}% "
                  f"{100 * v['worst_principal_error']:7.1f}% {v['extent_over_axis_max']:9.3f} "
                  f"{v['mass_above_cylinder']:5d} {v['inertia_above_cylinder']:5d}")
    print(f"wrote {out / 'apriori.csv'}, {out / 'apriori_summary.json'}, {out / 'apriori.png'}")


if __name__ == "__main__":
    main()
