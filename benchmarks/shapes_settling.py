"""Settling of composite grains in still water (seed 000 §4.1): table + figure.

For each Zingg class, composites of nominal diameter Dn = 0.7 ... 5.5 mm (axis ratios
given below), quartz (2650 kg/m³) in water (ν = 1e-6 m²/s), dropped from rest at a
tilted orientation; terminal velocity against Haider & Levenspiel (1989) at the
sphericity of the ellipsoid with the same axes, and against the sphere of the
composite's own volume (Yen drag); orientation at the start and the end (|cos| of the
short and of the long body axis with the vertical: a grain falling with its largest
projection across the fall has short ≈ 1 (disk, blade) or long ≈ 0 (rod)). Writes
settling.csv, settling.png (third panel: the long axis in time); prints the table.

    python benchmarks/shapes_settling.py [--out DIR] [--quick]
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd

from saltation.grains import shapes
from saltation.studies import settling

# (class, Di/Dl, Ds/Di): one representative grain per class and equant sub-type
SHAPES = [("disk", 0.85, 0.4), ("blade", 0.5, 0.45), ("rod", 0.45, 0.85),
          ("equant-2", 0.8, 0.95), ("equant-3", 0.95, 0.75), ("equant-4", 0.8, 0.75)]
DN_MM = (0.7, 1.5, 3.0, 5.5)
TILT_QUAT = (math.cos(0.35), math.sin(0.35) * 0.6, 0.0, math.sin(0.35) * 0.8)  # ≈ 40° off


def table(dn_list=DN_MM, duration=60.0, series=None):
    rows = []
    for name, p, q in SHAPES:
        for dn_mm in dn_list:
            dn = dn_mm * 1e-3
            dl = dn / (p * p * q) ** (1 / 3)
            axes = (dl, p * dl, q * p * dl)
            comp = shapes.build(*axes)
            res = settling.terminal_velocity(comp, quat=TILT_QUAT, duration=duration)
            psi_e = shapes.sphericity_ellipsoid(*axes)
            dv_c = comp.volume_equivalent_diameter
            psi_c = math.pi * dv_c**2 / comp.surface_area()
            w_hl = settling.terminal_haider_levenspiel(dn, psi_e)
            w_sph = settling.terminal_sphere_yen(dv_c)
            w_sph_dn = settling.terminal_sphere_yen(dn)
            ws, ds = settling.dimensionless(res["w_m_s"], dn)
            rows.append(dict(shape=name, zingg_class=comp.zingg_class, subtype=comp.subtype,
                             n_spheres=comp.n_spheres, Dn_mm=dn_mm, d_star=ds,
                             psi_ellipsoid=psi_e, psi_composite=psi_c,
                             w_composite_m_s=res["w_m_s"], w_star=ws,
                             w_haider_levenspiel_m_s=w_hl, ratio_to_HL=res["w_m_s"] / w_hl,
                             w_sphere_same_volume_m_s=w_sph, ratio_to_sphere=res["w_m_s"] / w_sph,
                             w_sphere_Dn_m_s=w_sph_dn,
                             short_axis_vertical_start=res["tilt"][0], short_axis_vertical_end=res["tilt"][-1],
                             long_axis_vertical_start=res["long_axis"][0],
                             long_axis_vertical_end=res["long_axis"][-1],
                             unsteadiness=res["steady"]))
            if series is not None:
                series.append((name, dn_mm, res["t"], res["long_axis"]))
    return pd.DataFrame(rows)


def figure(df, path, series=()):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(16, 4.5))
    for name, g in df.groupby("shape"):
        ax[0].plot(g.Dn_mm, g.w_composite_m_s * 100, "o-", label=f"{name} (composite)")
        ax[0].plot(g.Dn_mm, g.w_haider_levenspiel_m_s * 100, "x:", color=ax[0].lines[-1].get_color())
        ax[1].plot(g.psi_ellipsoid, g.ratio_to_HL, "o", label=name)
    d = np.linspace(0.7, 5.5, 50)
    ax[0].plot(d, [settling.terminal_sphere_yen(x * 1e-3) * 100 for x in d], "k-", label="sphere of Dn (Yen)")
    ax[0].set_xlabel("Dn (mm)")
    ax[0].set_ylabel("terminal velocity (cm/s); x: Haider & Levenspiel at ψ_ellipsoid")
    ax[0].legend(fontsize=7)
    ax[1].axhline(1.0, color="k", lw=0.8)
    ax[1].set_xlabel("sphericity ψ of the ellipsoid")
    ax[1].set_ylabel("w_composite / w_HL")
    ax[1].legend(fontsize=7)
    dn_show = max(s[1] for s in series) if series else None
    for name, dn_mm, t, la in series:
        if dn_mm == dn_show:
            ax[2].plot(t, la, label=name)
    ax[2].set_xlabel("t (Dn / √(g R Dn))")
    ax[2].set_ylabel(f"|cos| long axis vs vertical (Dn = {dn_show} mm; 0 = horizontal)")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="settling")
    ap.add_argument("--quick", action="store_true", help="two diameters only")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    series = []
    df = table((0.7, 5.5) if args.quick else DN_MM, series=series)
    df.to_csv(out / "settling.csv", index=False)
    figure(df, out / "settling.png", series)
    cols = ["shape", "n_spheres", "Dn_mm", "psi_ellipsoid", "psi_composite", "w_composite_m_s",
            "w_haider_levenspiel_m_s", "ratio_to_HL", "w_sphere_same_volume_m_s", "ratio_to_sphere",
            "short_axis_vertical_start", "short_axis_vertical_end", "long_axis_vertical_start",
            "long_axis_vertical_end"]
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.precision", 3):
        print(df[cols].to_string(index=False))
    print(f"wrote {out / 'settling.csv'}, {out / 'settling.png'}")


if __name__ == "__main__":
    main()
