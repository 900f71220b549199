"""A priori test of the bonded-sphere grains (seed 000 §3, Figs. 5-6).

100 random composites of the Smith (2003) mixture, Dl uniform in 0.2-2 mm, axis ratios
uniform in each Zingg class (saltation.grains.shapes.DEFAULT_RATIOS): mass and the three
moments of inertia about the geometric axes (x long, y intermediate, z short, through
the centre of mass) against (1) the ellipsoid with the same axes and (2) the elliptic
cylinder of length Dl and section Di × Ds. Writes apriori.csv, apriori_summary.json and
apriori.png (mass and inertia scatter vs both references, 1:1 and ±25 % lines) and
prints the per-class statistics.

    python benchmarks/shapes_apriori.py [--out DIR] [--n 100] [--seed 1]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from saltation.grains import shapes

DENSITY = 2650.0  # kg/m³ (quartz; the ratios do not depend on it)


def apriori(n=100, seed=1, Dl_range=(0.2e-3, 2.0e-3)) -> pd.DataFrame:
    cls, axes = shapes.draw_axes(n, Dl_range=Dl_range, seed=seed)
    rows = []
    for c, a in zip(cls, axes):
        comp = shapes.build(*a)
        me, ie = shapes.ellipsoid_properties(*a, density=DENSITY)
        mc, ic = shapes.cylinder_properties(*a, density=DENSITY)
        i = np.diag(comp.inertia_tensor(DENSITY))
        rows.append(dict(zingg_class=c, subtype=comp.subtype, n_spheres=comp.n_spheres,
                         Dl_m=a[0], Di_m=a[1], Ds_m=a[2], mass_kg=comp.mass(DENSITY),
                         mass_ellipsoid_kg=me, mass_cylinder_kg=mc,
                         **{f"I{k}_kgm2": i[j] for j, k in enumerate("xyz")},
                         **{f"I{k}_ellipsoid_kgm2": ie[j] for j, k in enumerate("xyz")},
                         **{f"I{k}_cylinder_kgm2": ic[j] for j, k in enumerate("xyz")}))
    df = pd.DataFrame(rows)
    df["mass_ratio_ellipsoid"] = df.mass_kg / df.mass_ellipsoid_kg
    df["mass_ratio_cylinder"] = df.mass_kg / df.mass_cylinder_kg
    for k in "xyz":
        df[f"I{k}_ratio_ellipsoid"] = df[f"I{k}_kgm2"] / df[f"I{k}_ellipsoid_kgm2"]
        df[f"I{k}_ratio_cylinder"] = df[f"I{k}_kgm2"] / df[f"I{k}_cylinder_kgm2"]
    return df


def summarise(df: pd.DataFrame) -> dict:
    out = {}
    groups = [("all", df)] + [(c, df[df.zingg_class == c]) for c in shapes.CLASSES]
    for name, g in groups:
        if len(g) == 0:
            continue
        ie = g[[f"I{k}_ratio_ellipsoid" for k in "xyz"]].to_numpy()
        ic = g[[f"I{k}_ratio_cylinder" for k in "xyz"]].to_numpy()
        me = g.mass_ratio_ellipsoid.to_numpy()
        out[name] = dict(
            count=int(len(g)),
            mass_ratio_ellipsoid_mean=float(me.mean()), mass_ratio_ellipsoid_min=float(me.min()),
            mass_ratio_ellipsoid_max=float(me.max()),
            mass_within_25pct=float(np.mean((me >= 0.8) & (me <= 1.25))),
            inertia_ratio_ellipsoid_min=float(ie.min()), inertia_ratio_ellipsoid_max=float(ie.max()),
            inertia_within_25pct=float(np.mean((ie >= 0.8) & (ie <= 1.25))),
            mass_above_cylinder=int((g.mass_ratio_cylinder > 1.0).sum()),
            inertia_above_cylinder=int((ic > 1.0).any(axis=1).sum()),
            mass_ratio_cylinder_max=float(g.mass_ratio_cylinder.max()),
            inertia_ratio_cylinder_max=float(ic.max()),
        )
    return out


def figure(df: pd.DataFrame, path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(10, 9))
    colours = dict(disk="tab:blue", blade="tab:orange", rod="tab:green", equant="tab:red")
    for row, ref in enumerate(("ellipsoid", "cylinder")):
        for col, what in enumerate(("mass", "I")):
            a = ax[row, col]
            for c in shapes.CLASSES:
                g = df[df.zingg_class == c]
                if what == "mass":
                    a.loglog(g[f"mass_{ref}_kg"], g.mass_kg, "o", ms=4, color=colours[c], label=c)
                else:
                    for k, m in zip("xyz", "o^s"):
                        a.loglog(g[f"I{k}_{ref}_kgm2"], g[f"I{k}_kgm2"], m, ms=3, mfc="none",
                                 color=colours[c], label=f"{c} I{k}" if c == "disk" or k == "x" else None)
            lo = min(a.get_xlim()[0], a.get_ylim()[0])
            hi = max(a.get_xlim()[1], a.get_ylim()[1])
            x = np.array([lo, hi])
            a.plot(x, x, "k-", lw=1)
            a.plot(x, 0.8 * x, "k--", lw=0.8)
            a.plot(x, 1.25 * x, "k--", lw=0.8)
            unit = "kg" if what == "mass" else "kg m²"
            a.set_xlabel(f"{'mass' if what == 'mass' else 'moment of inertia'} of the {ref} ({unit})")
            a.set_ylabel(f"composite ({unit})")
            a.legend(fontsize=7)
    fig.suptitle("Bonded-sphere grains vs ellipsoid (top) and elliptic cylinder (bottom); lines 1:1, ×0.8, ×1.25")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="apriori")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    df = apriori(args.n, args.seed)
    df.to_csv(out / "apriori.csv", index=False)
    s = summarise(df)
    (out / "apriori_summary.json").write_text(json.dumps(s, indent=1))
    figure(df, out / "apriori.png")
    print(f"{'class':<7} {'n':>3} {'m/m_ell mean [min,max]':>24} {'m in 25%':>8} {'I/I_ell [min,max]':>18} "
          f"{'I in 25%':>8} {'m>cyl':>5} {'I>cyl':>5}")
    for k, v in s.items():
        print(f"{k:<7} {v['count']:3d} {v['mass_ratio_ellipsoid_mean']:8.3f} [{v['mass_ratio_ellipsoid_min']:.2f},"
              f"{v['mass_ratio_ellipsoid_max']:.2f}] {100 * v['mass_within_25pct']:7.0f}% "
              f"[{v['inertia_ratio_ellipsoid_min']:.2f},{v['inertia_ratio_ellipsoid_max']:.2f}] "
              f"{100 * v['inertia_within_25pct']:7.0f}% {v['mass_above_cylinder']:5d} {v['inertia_above_cylinder']:5d}")
    print(f"wrote {out / 'apriori.csv'}, {out / 'apriori_summary.json'}, {out / 'apriori.png'}")


if __name__ == "__main__":
    main()
