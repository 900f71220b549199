"""The sand bed inside the LES: a porous layer of packed grains (SPEC §3, rough bed).

Geometry. The bed is a stack of hexagonal close-packed layers of spheres of the grain
diameter d (the same hexagonal top layer as the particle model's packed bed, SPEC §4).
Its top (the *bed top*, y = 0 of the grains) is the crest of the top layer; the top
layer's centres lie at y = −d/2, the next layer's at −d/2 − d√(2/3), and so on (HCP layer
spacing). The horizontally averaged solid fraction at height y is the areal fraction of
the spheres' cross-sections, one layer at a time:

    φ(y) = Σ_k φ_c · max(0, 1 − (2(y − y_k)/d)²),   φ_c = π/(2√3) = 0.9069

(hexagonal packing of circles of diameter d at the centre plane, n = 2/(√3 d²) spheres
per unit area). Averaged over one layer spacing, φ = π/(3√2) = 0.7405: the close-packed
porosity ε = 0.2595. A bed of another bulk porosity ε_b scales φ by (1 − ε_b)/0.7405.

Drag. Each cell layer of the bed is a porous zone with the Darcy–Forchheimer resistance
of the Ergun (1952, Chem. Eng. Prog. 48:89) relation at its own porosity ε = 1 − φ̄
(φ̄ the solid fraction averaged over the cell's height):

    −∇p/ρ = ν A U + B |U| U,   A = 150 (1 − ε)²/(ε³ d²),   B = 1.75 (1 − ε)/(ε³ d)

with U the superficial velocity. OpenFOAM's DarcyForchheimer model applies
−(ν d + ½ |U| f) U, so d = A and f = 2B. The constants 150 and 1.75 are Ergun's; nothing
is fitted. Near the crest ε → 1 and the drag vanishes smoothly; that thin, increasingly
open top of the grains is where the flow's momentum is absorbed (the roughness sublayer).

Analysis (``roughness_fit``): the mean profile above the bed top is fitted by the rough
log law with a virtual origin (zero-plane displacement) y_d below the bed top,

    u⁺ = (1/κ) ln((y⁺ + y_d⁺)) + B_s − ΔU⁺,   κ = 0.41, B_s = 5.5 (SPEC §3 smooth constant)

giving ΔU⁺ (roughness function) and y_d; the equivalent sand roughness follows from
Nikuradse's fully rough law ΔU⁺ = (1/κ) ln k_s⁺ + B_s − 8.5 and, for the transitional
regime, from Colebrook's ΔU⁺ = (1/κ) ln(1 + 0.3 k_s⁺) (both inverted for k_s).
"""
from __future__ import annotations

import math

import numpy as np

PHI_CENTRE = math.pi / (2.0 * math.sqrt(3.0))  # areal solid fraction of a hexagonal layer at its centre plane
PHI_HCP = math.pi / (3.0 * math.sqrt(2.0))  # volume solid fraction of close-packed spheres
POROSITY_HCP = 1.0 - PHI_HCP
LAYER_SPACING = math.sqrt(2.0 / 3.0)  # HCP layer spacing / d
ERGUN_VISCOUS = 150.0  # Ergun (1952)
ERGUN_INERTIAL = 1.75
POROSITY_RANGE = (0.2595, 0.476)  # close-packed … simple cubic packing
KAPPA = 0.41
B_SMOOTH = 5.5  # SPEC §3 log law u+ = (1/κ) ln y+ + 5.5
B_ROUGH = 8.5  # Nikuradse (1933) fully rough: u+ = (1/κ) ln(y/k_s) + 8.5
COLEBROOK_A = 0.3  # ΔU+ = (1/κ) ln(1 + 0.3 k_s+) (Colebrook 1939, as written by e.g. Jiménez 2004)


def check_porosity(porosity: float) -> float:
    lo, hi = POROSITY_RANGE
    if not (isinstance(porosity, (int, float)) and math.isfinite(porosity) and lo - 1e-9 <= porosity <= hi):
        raise ValueError(f"bed porosity must lie between {lo} (close-packed spheres) and {hi} (simple cubic "
                         f"packing), got {porosity!r}")
    return float(porosity)


def solid_fraction(y_d, porosity: float = POROSITY_HCP, n_layers: int = 6) -> np.ndarray:
    """Horizontally averaged solid fraction φ at heights y_d (in d, bed top = 0)."""
    y = np.asarray(y_d, dtype=float)
    scale = (1.0 - check_porosity(porosity)) / PHI_HCP
    phi = np.zeros_like(y)
    for k in range(n_layers):
        yc = -0.5 - k * LAYER_SPACING
        phi += PHI_CENTRE * np.clip(1.0 - (2.0 * (y - yc)) ** 2, 0.0, None)
    return np.clip(scale * phi, 0.0, 0.95)


def mean_solid_fraction(y0_d: float, y1_d: float, porosity: float = POROSITY_HCP, n: int = 401) -> float:
    """φ averaged over the height interval [y0, y1] (in d)."""
    ys = np.linspace(y0_d, y1_d, n)
    return float(np.trapezoid(solid_fraction(ys, porosity), ys) / (y1_d - y0_d))


def ergun_coefficients(porosity_local: float, d: float) -> tuple[float, float]:
    """OpenFOAM DarcyForchheimer (d, f) for a packing of spheres of diameter d (m) at the
    local porosity ε: d = 150(1−ε)²/(ε³d²) (1/m²), f = 2·1.75(1−ε)/(ε³d) (1/m)."""
    e = float(porosity_local)
    if not 0.0 < e <= 1.0:
        raise ValueError(f"local porosity must lie in (0, 1], got {e}")
    s = 1.0 - e
    return ERGUN_VISCOUS * s * s / (e**3 * d * d), 2.0 * ERGUN_INERTIAL * s / (e**3 * d)


def bed_layers(faces_d: np.ndarray, d: float, porosity: float = POROSITY_HCP) -> list[dict]:
    """One porous zone per cell layer of the bed. faces_d: the bed's cell faces in d,
    increasing, ending at the bed top (0). Returns per layer its extent (d), mean solid
    fraction, local porosity and Ergun (d, f) coefficients (SI)."""
    out = []
    for k in range(len(faces_d) - 1):
        lo, hi = float(faces_d[k]), float(faces_d[k + 1])
        phi = mean_solid_fraction(lo, hi, porosity)
        eps = 1.0 - phi
        dc, fc = ergun_coefficients(eps, d) if phi > 0 else (0.0, 0.0)
        out.append({"y0_d": lo, "y1_d": hi, "solid_fraction": phi, "porosity": eps,
                    "darcy_d": dc, "forchheimer_f": fc})
    return out


# ----------------------------------------------------------------------------- analysis
def colebrook_delta_u(ks_plus):
    """Colebrook's transitional roughness function ΔU⁺(k_s⁺) = (1/κ) ln(1 + 0.3 k_s⁺)."""
    return np.log1p(COLEBROOK_A * np.asarray(ks_plus, dtype=float)) / KAPPA


def nikuradse_delta_u(ks_plus):
    """Fully rough (Nikuradse 1933): ΔU⁺ = (1/κ) ln k_s⁺ + B_s − 8.5."""
    return np.log(np.asarray(ks_plus, dtype=float)) / KAPPA + B_SMOOTH - B_ROUGH


def ks_plus_from_delta_u(delta_u: float) -> dict:
    """Equivalent sand roughness k_s⁺ from a measured ΔU⁺, by both relations."""
    return {"colebrook": float(math.expm1(KAPPA * delta_u) / COLEBROOK_A),
            "nikuradse": float(math.exp(KAPPA * (delta_u - B_SMOOTH + B_ROUGH)))}


def roughness_fit(y_plus, u_plus, d_plus: float, y_range_d=(2.0, None), re_tau: float | None = None) -> dict:
    """Fit u⁺ = (1/κ) ln(y⁺ + y_d⁺) + B_s − ΔU⁺ over the log region above the bed top.

    y_plus, u_plus: mean profile (y⁺ from the bed top). The log region runs from
    y_range_d[0] grain diameters (above the roughness sublayer, ~2 roughness heights,
    Raupach et al. 1991) to 0.3 of the depth (re_tau; as the smooth-wall check) unless given. y_d (virtual origin
    below the bed top, ≥ 0) is found by a 1-D search minimising the squared residual,
    ΔU⁺ by least squares at each y_d. Returns y_d⁺, y_d/d, ΔU⁺, the fit's max relative
    deviation in the range, k_s (both relations, in wall units and d) and the range."""
    y = np.asarray(y_plus, dtype=float)
    u = np.asarray(u_plus, dtype=float)
    lo = y_range_d[0] * d_plus
    hi = (y_range_d[1] * d_plus) if y_range_d[1] is not None else 0.3 * (re_tau if re_tau else y.max())
    sel = (y >= lo) & (y <= hi)
    if sel.sum() < 3:
        raise ValueError(f"too few profile points in the log region y+ = {lo:.1f}-{hi:.1f} for a roughness fit")
    ys, us = y[sel], u[sel]

    def fit(yd):
        shift = np.log(ys + yd) / KAPPA + B_SMOOTH
        du = float(np.mean(shift - us))
        res = us - (shift - du)
        return du, float(np.sum(res**2)), res

    grid = np.linspace(0.0, d_plus, 401)
    errs = [fit(g)[1] for g in grid]
    yd = float(grid[int(np.argmin(errs))])
    du, _, res = fit(yd)
    law = np.log(ys + yd) / KAPPA + B_SMOOTH - du
    ks = ks_plus_from_delta_u(du)
    return {
        "virtual_origin_plus": yd, "virtual_origin_d": yd / d_plus,
        "delta_u_plus": du,
        "log_range_plus": [float(lo), float(hi)],
        "log_fit_max_rel_dev": float(np.max(np.abs(res / law))),
        "ks_plus_colebrook": ks["colebrook"], "ks_d_colebrook": ks["colebrook"] / d_plus,
        "ks_plus_nikuradse": ks["nikuradse"], "ks_d_nikuradse": ks["nikuradse"] / d_plus,
        "colebrook_delta_u_at_ks_d": {f"{k:g}": float(colebrook_delta_u(k * d_plus)) for k in (1.0, 2.0, 2.5)},
    }


def rough_law(y_plus, fit: dict):
    """The fitted rough log law u⁺(y⁺) of ``roughness_fit``."""
    y = np.asarray(y_plus, dtype=float)
    return np.log(y + fit["virtual_origin_plus"]) / KAPPA + B_SMOOTH - fit["delta_u_plus"]
