"""Sediment transport rate of a run and the Ackers–White (1973/1993) capacity formula
(issue 6 item 5; seed 000 §4.4, eqs. 11–15).

Transport rate of a run
-----------------------
The volumetric transport per unit width (m²/s) of the grains in a periodic bed of area
Lx·Lz is

    q = ⟨ Σ_p V_p u_p ⟩_t / (Lx Lz),

V_p the grain's solid volume (m³), u_p its streamwise velocity (centre of mass), ⟨⟩_t the
average over the sampled times (the volume flux through a spanwise plane, averaged along
x, equals the volume-weighted grain velocity per bed area: ∫ c u dy = Σ V_p u_p / A).
The Einstein number is

    q* = q / √(R g D³),     R = ρp/ρ − 1, D the (nominal) grain diameter.

In particle units (lengths in D, velocities in u*) Σ V u/(Lx Lz) is q/(u* D), so
q* = q_particle · √τ*. **q here is proportional to the number of grains per bed area**
(areal concentration N/(Lx Lz)): the run prescribes how many grains move, it does not
find the equilibrium load. Shapes must therefore be compared at the same number of
grains (and the same nominal diameter), and q* is not a capacity.

Ackers & White (1973), revised coefficients (HR Wallingford 1990, Ackers 1993)
-----------------------------------------------------------------------------
As in the seed paper's eqs. 11–15 (their typesetting lost; the standard form):

    D_gr = D [g (s − 1)/ν²]^{1/3}                                       (11)
    n    = 1 − 0.56 log10 D_gr           (transition exponent; 0 for D_gr > 60)
    A    = 0.23/√D_gr + 0.14             (initial motion; 0.17 for D_gr > 60)   (14)
    m    = 6.83/D_gr + 1.67              (1993; 9.66/D_gr + 1.34 in 1973; 1.78 > 60) (15b)
    log10 C = −3.46 + 2.79 log10 D_gr − 0.98 (log10 D_gr)²
                                          (1993; 2.86, −1, −3.53 in 1973; C = 0.025 > 60) (15a)
    F_gr = u*^n / √(g D (s − 1)) · [ V / (√32 log10(10 h/D)) ]^{1−n}          (13)
    G_gr = C (F_gr/A − 1)^m              (0 when F_gr ≤ A)
    G_gr = X h/(s D) (u*/V)^n            (X: sediment flux by weight per weight of fluid flux)

so the volumetric transport per unit width (q = X V h/s) is

    q = G_gr D V (V/u*)^n = C (F_gr/A − 1)^m D V (V/u*)^n                 (12)

with V the depth-averaged velocity, h the flow depth, s = ρp/ρ. Valid for
1 ≤ D_gr (silt to gravel), Froude < 0.8. It is a **total-load capacity** (equilibrium
transport of an alluvial bed), so the ratio q/q_AW of a run depends on the number of
grains the run holds: it is reported, not tuned.

For the channel LES the depth is the half height h (= Re_τ ν/u*) and V the bulk velocity
of the channel (by symmetry that of the half channel), V = U_b⁺ u*: the dataset's own
U_b⁺ (:func:`bulk_velocity_plus`).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..case.schema import GRAVITY

__all__ = ["ackers_white", "bulk_velocity_plus", "transport_rate", "einstein_number"]

SQRT32 = math.sqrt(32.0)


def ackers_white(D, *, u_star, velocity, depth, s=2.65, nu=1.0e-6, g=GRAVITY, revised=True) -> dict:
    """Ackers–White transport capacity (module docstring, eqs. 11–15).

    D: grain diameter (m); u_star: shear velocity (m/s); velocity: depth-averaged V (m/s);
    depth: h (m); s = ρp/ρ; nu: kinematic viscosity (m²/s). ``revised``: the 1990/1993
    coefficients (default), else the 1973 ones. Returns dict with D_gr, n, A, m, C, F_gr,
    G_gr, q (m²/s, volume per unit width), q_star = q/√((s−1) g D³)."""
    for name, v in (("D", D), ("u_star", u_star), ("velocity", velocity), ("depth", depth), ("nu", nu)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise ValueError(f"ackers_white: {name} = {v!r} must be a positive finite number (SI units)")
    if not s > 1.0:
        raise ValueError(f"ackers_white: s = {s!r} must exceed 1 (grains denser than the fluid)")
    if not depth > D:
        raise ValueError(f"ackers_white: depth = {depth!r} m must exceed the grain diameter D = {D!r} m")
    R = s - 1.0
    dgr = D * (g * R / nu**2) ** (1.0 / 3.0)
    if dgr < 1.0:
        raise ValueError(f"ackers_white: D_gr = {dgr:.4g} < 1 is outside the formula's range (D_gr >= 1)")
    lg = math.log10(dgr)
    if dgr > 60.0:
        n, A, m, C = 0.0, 0.17, (1.78 if revised else 1.50), 0.025
    else:
        n = 1.0 - 0.56 * lg
        A = 0.23 / math.sqrt(dgr) + 0.14
        if revised:
            m = 6.83 / dgr + 1.67
            C = 10.0 ** (-3.46 + 2.79 * lg - 0.98 * lg * lg)
        else:
            m = 9.66 / dgr + 1.34
            C = 10.0 ** (-3.53 + 2.86 * lg - lg * lg)
    fgr = u_star**n / math.sqrt(g * D * R) * (velocity / (SQRT32 * math.log10(10.0 * depth / D))) ** (1.0 - n)
    ggr = C * (fgr / A - 1.0) ** m if fgr > A else 0.0
    q = ggr * D * velocity * (velocity / u_star) ** n
    return {"D_gr": dgr, "n": n, "A": A, "m": m, "C": C, "F_gr": fgr, "G_gr": ggr, "q": q,
            "q_star": q / math.sqrt(R * g * D**3), "revised": bool(revised)}


def bulk_velocity_plus(ds) -> float:
    """The LES's bulk (depth-averaged) velocity U_b⁺ = U_b/u_τ in its own wall units.

    From the generator's provenance when present (the solver held U_b fixed:
    U_b⁺ = U_b h/(Re_τ ν), Re_τ the dataset's own); otherwise the stored mean profile
    integrated to its top and the log law u⁺ = ln(y⁺)/0.41 + B (B matched at the top)
    integrated from there to y⁺ = Re_τ."""
    prov = (ds.meta.get("provenance") or {}) if hasattr(ds, "meta") else {}
    params, derived = prov.get("params") or {}, prov.get("derived") or {}
    if derived.get("ubar_m_s") and params.get("nu") and params.get("h"):
        u_tau = ds.re_tau * params["nu"] / params["h"]
        return float(derived["ubar_m_s"] / u_tau)
    # mean profile of the stored snapshots (u⁺ = y⁺ below the first point), trapezoids
    y = np.concatenate([[0.0], np.asarray(ds.y, float)])
    u = np.mean([ds.snapshot(k)[..., 0].mean(axis=(0, 2)) for k in range(ds.n_snapshots)], axis=0)
    u = np.concatenate([[0.0], u])
    top, h = y[-1], float(ds.re_tau)
    integral = float(np.sum(0.5 * (u[1:] + u[:-1]) * np.diff(y)))
    if h > top:  # log law above the stored top: ∫ (ln y/κ + B) dy = [y (ln y − 1)/κ + B y]
        kappa = 0.41
        B = u[-1] - math.log(top) / kappa
        prim = lambda yy: yy * (math.log(yy) - 1.0) / kappa + B * yy  # noqa: E731
        integral += prim(h) - prim(top)
    return integral / max(h, top)


def _skip_time(jumps: pd.DataFrame | None, discarded: int) -> float:
    """Median over grains of the start time of their jump number ``discarded`` (the first
    counted jump): the transient the jump statistics drop, dropped from q as well."""
    if jumps is None or len(jumps) == 0:
        return 0.0
    first = jumps[jumps["jump"] == discarded]
    return float(first["t_start"].median()) if len(first) else float(jumps["t_start"].max())


def transport_rate(tracks: pd.DataFrame, volumes, area, *, t_from=None, jumps=None, discarded=10) -> dict:
    """q = ⟨Σ_p V_p u_p⟩_t /(Lx Lz) in particle units (module docstring).

    tracks: tracks.parquet (particle, t, u, … in particle units); volumes: (N,) grain
    volumes in d³ indexed by particle; area: Lx·Lz in d². Samples at t ≥ t_from are
    averaged; t_from None: the median start of each grain's first counted jump (from
    ``jumps``), 0 without jumps. Returns dict(q_particle, t_from, samples, volume_total,
    u_volume_mean) — volume_total = Σ V of the grains in ``tracks``, u_volume_mean =
    ⟨Σ V u⟩/Σ V, their volume-weighted mean streamwise velocity (u*)."""
    vol = np.asarray(volumes, float)
    if t_from is None:
        t_from = _skip_time(jumps, discarded)
    tr = tracks[tracks["t"] >= t_from - 1e-12]
    if len(tr) == 0:
        raise ValueError(f"transport_rate: no track samples at t >= {t_from:.4g} d/u*; run longer")
    part = tr["particle"].to_numpy()
    flux = vol[part] * tr["u"].to_numpy()
    per_t = pd.Series(flux).groupby(tr["t"].to_numpy()).sum()
    q = float(per_t.mean()) / float(area)
    volume = float(vol[np.unique(part)].sum())  # of the grains in ``tracks`` (a class: its own)
    return {"q_particle": q, "t_from": float(t_from), "samples": int(len(per_t)),
            "volume_total": volume, "u_volume_mean": float(per_t.mean()) / volume,
            "units": "q_particle in u* d (volume per unit width); t_from in d/u*; volumes in d³"}


def einstein_number(q_particle: float, tau_star: float) -> float:
    """q* = q/√(R g d³) from q in particle units (u* d): q* = q_particle √τ*."""
    return float(q_particle) * math.sqrt(tau_star)
