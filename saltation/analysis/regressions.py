"""Published regressions for bed-load saltation: jump height H, jump length L, grain velocity U.

Reference values for the validation table. Every function returns a dict
``{"H": H/d, "L": L/d, "U": U/u*}`` (``nan`` for a quantity the regression does not give),
computed in the regression's own variables from the physical inputs

    d        grain diameter [m]
    R        submerged specific gravity ρs/ρ − 1 [-]
    g        gravitational acceleration [m/s²]
    nu       kinematic viscosity [m²/s]
    tau_star Shields number τ* = u*²/(R g d) [-]
    tau_c    critical Shields number τ*c [-]

with u* = √(τ* R g d), u*c = √(τ*c R g d), u*/u*c = √(τ*/τ*c) and D* = d (R g/ν²)^(1/3).
Below threshold (τ* < τ*c) there is no saltation and every quantity is ``nan``.

Where each formula was read (address, quoted passage) is recorded in ``docs/references.md``
and, per regression, in ``REGRESSIONS[name].verified_in``. Only formulas read in a source
are implemented. None of the original papers could be read here, so every ``status`` is
``"quoted"`` (read in a paper quoting it or in code naming it). The one formula taken from
the project SPEC that no source confirmed, van Rijn's jump length, is listed in that
regression's ``spec_only`` and noted in every table row.
"""
from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

QUANTITIES = ("H", "L", "U")
COLUMNS = {"H": "H_over_d", "L": "L_over_d", "U": "U_over_ustar"}
NAN = float("nan")

# The condition of interest (Niño & García 1998 stages, SPEC): quartz in water.
NINO_GARCIA = dict(d=0.69e-3, R=2650.0 / 1000.0 - 1.0, g=9.81, nu=1.0e-6, tau_c=0.032)
NINO_GARCIA_STAGES = (1.79, 1.87, 2.43, 2.67)


# ---------------------------------------------------------------------------------------
# Shared variables
# ---------------------------------------------------------------------------------------

def dimensionless_grain_size(d, R, g, nu):
    """D* = d (R g / ν²)^(1/3) (van Rijn 1984's particle parameter)."""
    return d * (R * g / nu**2) ** (1.0 / 3.0)


def shear_velocity(tau_star, d, R, g):
    """u* = √(τ* R g d) [m/s] from the Shields number."""
    return math.sqrt(tau_star * R * g * d)


def settling_velocity_dietrich(d, R, g, nu, csf=0.8, ps=3.5):
    """Settling velocity w_s [m/s], Dietrich (1982, Water Resour. Res. 18(6):1615–1626).

    Coefficients as in the public code of Lamb et al. (2008) (file
    ``total_load_code_fct_public.m``, repository SophieRothman/waterfall_erosion_rates):
    W* = R3·10^(R1+R2), X = log10(R g d³/ν²), w_s = (R g ν W*)^(1/3); Corey shape factor
    ``csf`` = 0.8 and Powers roundness ``ps`` = 3.5 for natural grains (1 and 6 for spheres).
    """
    x = math.log10(R * g * d**3 / nu**2)
    r1 = -3.76715 + 1.92944 * x - 0.09815 * x**2 - 0.00575 * x**3 + 0.00056 * x**4
    r2 = (math.log10(1.0 - (1.0 - csf) / 0.85) - (1.0 - csf) ** 2.3 * math.tanh(x - 4.6)
          + 0.3 * (0.5 - csf) * (1.0 - csf) ** 2 * (x - 4.6))
    r3 = (0.65 - (csf / 2.83) * math.tanh(x - 4.6)) ** (1.0 + (3.5 - ps) / 2.5)
    w_star = r3 * 10.0 ** (r1 + r2)
    return (R * g * nu * w_star) ** (1.0 / 3.0)


def settling_velocity_ferguson_church(d, R, g, nu, c1=20.0, c2=1.1):
    """Settling velocity w_s [m/s], Ferguson & Church (2004, J. Sediment. Res. 74:933–937).

    w_s = R g d² / (C1 ν + √(0.75 C2 R g d³)), C1 = 20, C2 = 1.1 (natural sand), as in
    openearth/matlab-tools ``applications/vtools/general/settling_velocity.m``.
    """
    return R * g * d**2 / (c1 * nu + math.sqrt(0.75 * c2 * R * g * d**3))


SETTLING = {"dietrich": settling_velocity_dietrich, "ferguson_church": settling_velocity_ferguson_church}


def _settling(d, R, g, nu, ws):
    """``ws`` as given: a number [m/s], or the name of a settling law in ``SETTLING``."""
    if isinstance(ws, str):
        return SETTLING[ws](d, R, g, nu)
    return float(ws)


def _result(H=NAN, L=NAN, U=NAN):
    return {"H": float(H), "L": float(L), "U": float(U)}


def _below_threshold(tau_star, tau_c):
    if tau_c <= 0.0 or tau_star < 0.0:
        raise ValueError(f"need tau_c > 0 and tau_star >= 0 (got tau_star={tau_star}, tau_c={tau_c})")
    return tau_star < tau_c


# ---------------------------------------------------------------------------------------
# The regressions
# ---------------------------------------------------------------------------------------

def van_rijn_1984(d, R, g, nu, tau_star, tau_c):
    """van Rijn, L. C. (1984). Sediment transport, Part I: Bed load transport.
    J. Hydraul. Eng. 110(10), 1431–1456.

    With D* = d (R g/ν²)^(1/3) and transport stage T = τ*/τ*c − 1:
        saltation height  δ_b/d = 0.3 D*^0.7 T^0.5
        grain velocity    u_b   = 1.5 T^0.6 √(R g d)   →  U/u* = 1.5 T^0.6 / √τ*
        saltation length  λ_b/d = 3 D*^0.6 T^0.9        (SPEC only: not confirmed here)

    Equation numbers: not read (the original was not accessible). Secondary sources label
    the height/velocity pair "eq. 20b/20a" after the SEDZLJ report, which is not van Rijn's
    numbering. T: van Rijn's transport stage is T = (u*'² − u*c²)/u*c² with the grain-related
    ("particle") shear velocity u*' = √g U/C', C' = 18 log10(4 R_b/d90) (karlkastner/
    sediment-transport transport_stage_rijn.m, grain_roughness_rijn.m); the same thing as
    τ*'/τ*c − 1. Here τ* is taken as the grain shear stress, which on the flat, bedform-free
    flume bed of the validation cases is the total bed shear stress (as the TELEMAC-GAIA,
    FLOW-3D and SEDZLJ/EFDC+ codes read also use it).

    Validity: van Rijn's relations were fitted to his saltation-model computations for sand;
    the range was not stated in any source read here.
    """
    if _below_threshold(tau_star, tau_c):
        return _result()
    T = tau_star / tau_c - 1.0
    d_star = dimensionless_grain_size(d, R, g, nu)
    return _result(
        H=0.3 * d_star**0.7 * T**0.5,
        L=3.0 * d_star**0.6 * T**0.9,
        U=1.5 * T**0.6 / math.sqrt(tau_star),
    )


def fernandez_luque_van_beek_1976(tau_star, tau_c):
    """Fernandez Luque, R. & van Beek, R. (1976), J. Hydraul. Res. 14(2), 127–144 (citation as
    in the SPEC; the original was not read).

    Mean grain (transport) velocity  U_p = c_a (u* − 0.7 u*c),  c_a ≈ 11.5
        →  U/u* = 11.5 (1 − 0.7 u*c/u*),  u*c/u* = √(τ*c/τ*).

    Read as quoted by Di Cristo et al. (2016, J. Hydraul. Eng. 142(2), eq. 22); the
    original's equation number was not read.

    Validity: flume experiments over a loose bed; Di Cristo et al. note that the related
    bed-load-volume scaling from the same experiments was "deduced only for the low Shields
    parameter, i.e., θ0 ≤ 0.1". Grain-size range not stated in the source read.
    """
    if _below_threshold(tau_star, tau_c):
        return _result()
    return _result(U=11.5 * (1.0 - 0.7 * math.sqrt(tau_c / tau_star)))


def sekine_kikkawa_1992(d, R, g, nu, tau_star, tau_c, ws="dietrich"):
    """Sekine, M. & Kikkawa, H. (1992), "Mechanics of saltating grains", J. Hydraul. Eng.
    118(4) (journal/volume as in the SPEC; pages and equation number not read).

    Bed-load-layer averaged mean velocity of saltation
        U_m / √(g d R) = 8 (u*/w_s) (1 − u*c/u*)^(1/2)
        →  U/u* = 8 √(R g d) / w_s · (1 − u*c/u*)^(1/2).

    Read as quoted by Di Cristo et al. (2016, eq. 24). Needs the settling velocity w_s,
    which the quote does not define: ``ws`` is a number [m/s] or the name of a law in
    ``SETTLING`` (default Dietrich 1982 for natural grains; Ferguson & Church 2004 gives
    w_s 4 % lower and U 4 % higher for d = 0.69 mm).

    Validity: not stated in the source read (Di Cristo et al.: its dimensionless parameters
    were later confirmed for transitionally rough beds by Papanicolaou et al. 2002 and
    Ramesh et al. 2011).
    """
    if _below_threshold(tau_star, tau_c):
        return _result()
    w_s = _settling(d, R, g, nu, ws)
    return _result(U=8.0 * math.sqrt(R * g * d) / w_s * math.sqrt(1.0 - math.sqrt(tau_c / tau_star)))


def bridge_dominic_1984(d, R, g, nu, tau_star, tau_c, tan_mu_d=None, ws="dietrich"):
    """Bridge, J. S. & Dominic, D. F. (1984) (journal, pages and equation number not read;
    only Di Cristo et al.'s quote was).

    Bed grain velocity (from a theoretical force balance, not a regression)
        U_g = c_b (u* − u*c),  c_b = √(tan μ_d) w_s / u*c
        →  U/u* = √(tan μ_d) (w_s/u*c) (1 − u*c/u*).

    Read as quoted by Di Cristo et al. (2016, eq. 23). Needs the dynamic friction
    coefficient tan μ_d, for which no value was read: without ``tan_mu_d`` the result is
    ``nan``. ``ws`` as in :func:`sekine_kikkawa_1992`.

    Validity: a theoretical relation; no range stated in the source read.
    """
    if tan_mu_d is None or _below_threshold(tau_star, tau_c):
        return _result()
    w_s = _settling(d, R, g, nu, ws)
    ratio = math.sqrt(tau_c / tau_star)  # u*c/u*
    u_star_c = shear_velocity(tau_c, d, R, g)
    return _result(U=math.sqrt(tan_mu_d) * w_s / u_star_c * (1.0 - ratio))


def wiberg_rubin_1989(d, tau_star, tau_c):
    """Wiberg, P. L. & Rubin, D. M. (1989). Bed roughness produced by saltating sediment.
    J. Geophys. Res. 94(C4), 5011–5016.

    Mean saltation height, a fit to the saltation model of Wiberg & Smith (1985):
        δ_b/d = a1 T* / (1 + a2 T*),  T* = τ*/τ*c (stage, not excess stage),
        a1 = 0.68,  a2 = 0.0204 (ln D)² + 0.0220 ln D + 0.0709,  D = d in centimetres.

    Read in three public codes (USGS/Jaffe Python port, ROMS ``ssw_bbl``, karlkastner
    MATLAB after McLean); a2 is the paper's "equation 6". Two other codes disagree (one
    evaluates ln with d in metres, one misprints a1 = 0.068): the three agreeing ones, which
    state the centimetre unit explicitly, are followed.

    Validity: not stated in the sources read; it describes model output, not measurements.
    """
    if _below_threshold(tau_star, tau_c):
        return _result()
    t_star = tau_star / tau_c
    ln_d = math.log(d * 100.0)
    a2 = 0.0204 * ln_d**2 + 0.0220 * ln_d + 0.0709
    return _result(H=0.68 * t_star / (1.0 + a2 * t_star))


def lamb_2008(R, g, d, tau_star, tau_c):
    """Lamb, M. P. et al. (2008), total-load bedrock-erosion model (journal details not read;
    equation numbers as given in the authors' code).

    Bed-load height and velocity (Lamb et al. eqs. 25 and 24), with stage τ*/τ*c:
        h_b/d = 1.44 (τ*/τ*c − 1)^0.50
        U_s   = 1.56 √(R g d) (τ*/τ*c − 1)^0.56   →  U/u* = 1.56 (τ*/τ*c − 1)^0.56 / √τ*

    Read in the authors' public MATLAB code (Lamb; commented by Scheingross, 2013). They are
    thought to come from the saltation fits of Sklar & Dietrich (2004, Water Resour. Res.
    40(6), doi:10.1029/2003WR002496), but no source read here says so, and the matching
    hop-length fit was not found.

    Validity: not stated in the source read.
    """
    if _below_threshold(tau_star, tau_c):
        return _result()
    excess = tau_star / tau_c - 1.0
    return _result(H=1.44 * excess**0.50, U=1.56 * excess**0.56 / math.sqrt(tau_star))


# ---------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Regression:
    """One published regression and where it was checked."""

    func: Callable
    citation: str
    quantities: tuple  # subset of ("H", "L", "U") the regression gives
    stage_variable: str  # the transport-stage variable it is written in
    validity: str
    verified_in: str  # where the formula was read (see docs/references.md)
    status: str  # "quoted" (read in a secondary source) or "spec-only" (not confirmed)
    spec_only: tuple = ()  # quantities taken from the SPEC and not confirmed in any source read
    needs: tuple = ()  # extra inputs beyond (d, R, g, nu, tau_star, tau_c)
    max_tau_star: float | None = None  # upper bound quoted for the data, if any

    def __call__(self, d, R, g, nu, tau_star, tau_c, **extra):
        params = inspect.signature(self.func).parameters
        given = dict(d=d, R=R, g=g, nu=nu, tau_star=tau_star, tau_c=tau_c, **extra)
        return self.func(**{k: v for k, v in given.items() if k in params})

    def notes(self, tau_star, extra=None):
        """Why a value at this condition is missing or outside what the source states."""
        out = []
        missing = [n for n in self.needs if (extra or {}).get(n) is None]
        if missing:
            out.append(f"needs {', '.join(missing)} (no value read): not evaluated")
        if self.max_tau_star is not None and tau_star > self.max_tau_star:
            out.append(f"tau* = {tau_star:.3g} > {self.max_tau_star} (data range quoted)")
        if self.spec_only:
            out.append(f"{'/'.join(self.spec_only)} from SPEC, not confirmed in a source")
        return out


DI_CRISTO = ("Di Cristo, Greco, Iervolino, Leopardi & Vacca (2016), J. Hydraul. Eng. 142(2), "
             "doi:10.1061/(ASCE)HY.1943-7900.0001024, 'Model closures' section")

REGRESSIONS: dict[str, Regression] = {
    "van Rijn 1984": Regression(
        func=van_rijn_1984,
        citation="van Rijn (1984) J. Hydraul. Eng. 110(10):1431-1456",
        quantities=("H", "L", "U"),
        stage_variable="T = tau*/tau*c - 1",
        validity="fitted to van Rijn's saltation-model runs for sand; range not stated in sources read",
        verified_in="H: tomsail/telemac-conda sources/gaia/cvsp_alt_gaia.f; FLOW-3D-type Fortran "
                    "('interpretation of saltation height (van Rijn (1984))'); H and U: SEDZLJ "
                    "Python port bedload.py (van_rijn_bedload_height_cm/velocity_cm_s). L: SPEC only",
        status="quoted",
        spec_only=("L",),
    ),
    "Fernandez Luque & van Beek 1976": Regression(
        func=fernandez_luque_van_beek_1976,
        citation="Fernandez Luque & van Beek (1976) J. Hydraul. Res. 14(2):127-144 (via Di Cristo et al. 2016)",
        quantities=("U",),
        stage_variable="u*/u*c",
        validity="flume, loose bed; related relation 'deduced only for the low Shields parameter, i.e., theta0 <= 0.1' (Di Cristo et al.)",
        verified_in=DI_CRISTO + ", eq. 22",
        status="quoted",
        max_tau_star=0.1,
    ),
    "Sekine & Kikkawa 1992": Regression(
        func=sekine_kikkawa_1992,
        citation="Sekine & Kikkawa (1992) J. Hydraul. Eng. 118(4) (via Di Cristo et al. 2016)",
        quantities=("U",),
        stage_variable="u*/u*c and u*/w_s",
        validity="range not stated in source read; w_s law assumed (Dietrich 1982)",
        verified_in=DI_CRISTO + ", eq. 24",
        status="quoted",
    ),
    "Bridge & Dominic 1984": Regression(
        func=bridge_dominic_1984,
        citation="Bridge & Dominic (1984) (via Di Cristo et al. 2016)",
        quantities=("U",),
        stage_variable="u* - u*c",
        validity="theoretical; needs dynamic friction tan(mu_d) (no value read)",
        verified_in=DI_CRISTO + ", eq. 23",
        status="quoted",
        needs=("tan_mu_d",),
    ),
    "Wiberg & Rubin 1989": Regression(
        func=wiberg_rubin_1989,
        citation="Wiberg & Rubin (1989) J. Geophys. Res. 94(C4):5011-5016",
        quantities=("H",),
        stage_variable="T* = tau*/tau*c",
        validity="fit to Wiberg & Smith (1985) saltation-model output; range not stated in sources read",
        verified_in="USGS/Jaffe Python port (function zoWS, 'equation 6'); ROMS ssw_bbl "
                    "('Calculate saltation roughness according to Wiberg & Rubin (1989)'); "
                    "karlkastner MATLAB bed_layer_thickness.m ('eq 16 in Mclean')",
        status="quoted",
    ),
    "Lamb et al. 2008": Regression(
        func=lamb_2008,
        citation="Lamb et al. (2008), eqs. 24-25 (via the authors' code)",
        quantities=("H", "U"),
        stage_variable="tau*/tau*c - 1",
        validity="not stated in source read (attributed elsewhere to Sklar & Dietrich 2004 fits)",
        verified_in="SophieRothman/waterfall_erosion_rates total_load_code_fct_public.m "
                    "(Lamb's code, commented by Scheingross 2013)",
        status="quoted",
    ),
}


# ---------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------

def evaluate_all(d, R, g, nu, tau_star, tau_c, include_spec_only=True, **extra) -> pd.DataFrame:
    """Every regression's H/d, L/d and U/u* at one condition.

    One row per regression (index = name), columns ``H_over_d``, ``L_over_d``,
    ``U_over_ustar`` (``nan`` where a regression gives no value), ``status`` and ``notes``.
    ``extra`` passes regression-specific inputs (``tan_mu_d``; ``ws`` as a number [m/s] or
    ``"dietrich"`` / ``"ferguson_church"``). ``include_spec_only=False`` blanks the
    quantities that no source read here confirmed (van Rijn's L).
    """
    rows = {}
    for name, reg in REGRESSIONS.items():
        values = reg(d, R, g, nu, tau_star, tau_c, **extra)
        if not include_spec_only:
            for q in reg.spec_only:
                values[q] = NAN
        row = {COLUMNS[q]: values[q] for q in QUANTITIES}
        row["status"] = reg.status
        row["notes"] = "; ".join(reg.notes(tau_star, extra))
        rows[name] = row
    return pd.DataFrame.from_dict(rows, orient="index")


def envelope(d, R, g, nu, tau_star, tau_c, include_spec_only=True, **extra) -> pd.DataFrame:
    """Min and max over the regressions of each of H/d, L/d, U/u* at one condition.

    Rows ``H``, ``L``, ``U``; columns ``min``, ``max``, ``min_by``, ``max_by`` (the
    regression giving the extreme) and ``n`` (how many regressions gave a value).
    """
    table = evaluate_all(d, R, g, nu, tau_star, tau_c, include_spec_only=include_spec_only, **extra)
    out = {}
    for q in QUANTITIES:
        col = table[COLUMNS[q]].dropna()
        if col.empty:
            out[q] = dict(min=NAN, max=NAN, min_by=None, max_by=None, n=0)
        else:
            out[q] = dict(min=col.min(), max=col.max(), min_by=col.idxmin(), max_by=col.idxmax(), n=len(col))
    return pd.DataFrame.from_dict(out, orient="index")


def stage_table(stages=NINO_GARCIA_STAGES, d=NINO_GARCIA["d"], R=NINO_GARCIA["R"], g=NINO_GARCIA["g"],
                nu=NINO_GARCIA["nu"], tau_c=NINO_GARCIA["tau_c"], **extra) -> pd.DataFrame:
    """Every regression at each stage τ*/τ*c (default: the four Niño & García 1998 stages).

    Long table: columns ``tau_ratio``, ``tau_star``, ``u_star``, ``regression``, the three
    quantities, ``status`` and ``notes``.
    """
    frames = []
    for s in stages:
        tau_star = s * tau_c
        t = evaluate_all(d, R, g, nu, tau_star, tau_c, **extra)
        t.insert(0, "regression", t.index)
        t.insert(0, "u_star", shear_velocity(tau_star, d, R, g))
        t.insert(0, "tau_star", tau_star)
        t.insert(0, "tau_ratio", s)
        frames.append(t.reset_index(drop=True))
    return pd.concat(frames, ignore_index=True)


def format_stage_table(table: pd.DataFrame, digits=2) -> str:
    """Markdown table: one row per regression, H/d, L/d, U/u* at each stage."""
    stages = sorted(table["tau_ratio"].unique())
    head = "| regression | " + " | ".join(f"{q} @ {s:g}" for q in ("H/d", "L/d", "U/u*") for s in stages) + " |"
    sep = "|---|" + "---:|" * (3 * len(stages))
    lines = [head, sep]
    for name in dict.fromkeys(table["regression"]):
        sub = table[table["regression"] == name].set_index("tau_ratio")
        cells = []
        for col in ("H_over_d", "L_over_d", "U_over_ustar"):
            for s in stages:
                v = sub.loc[s, col]
                cells.append("–" if np.isnan(v) else f"{v:.{digits}f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


__all__ = [
    "REGRESSIONS", "Regression", "evaluate_all", "envelope", "stage_table", "format_stage_table",
    "van_rijn_1984", "fernandez_luque_van_beek_1976", "sekine_kikkawa_1992", "bridge_dominic_1984",
    "wiberg_rubin_1989", "lamb_2008", "dimensionless_grain_size", "shear_velocity",
    "settling_velocity_dietrich", "settling_velocity_ferguson_church", "NINO_GARCIA", "NINO_GARCIA_STAGES",
]
