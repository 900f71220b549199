"""Case files: TOML tables → frozen dataclasses, units resolved once (SPEC §9).

A case file has the tables ``[particle] [fluid] [flow] [forces] [bed] [collisions]
[run] [output]``. Every key is SI unless its documentation says otherwise (``in d``:
particle diameters; ``in d/u*``: particle time units; ``in u*``: shear velocities;
``deg``: degrees). The tables hold what the user wrote plus the defaults; everything
derived from them — Shields number, shear velocity, particle Reynolds numbers, the time
step in seconds and in d/u*, the bed coefficients of a named set, the contact stiffness
— is a read-only property of :class:`Case`, computed from the tables and nowhere else.
Read resolved values from the :class:`Case` properties, not from the tables (a table
field may be ``None`` meaning "derived" or "default").

Entry points
------------
``load_case(source, overrides=None) -> Case``
    ``source``: a path, a dict of tables (as ``tomllib`` returns), or a ``Case``.
    ``overrides``: ``{"table.key": value}`` or ``["table.key=value", ...]`` (the
    ``--set`` syntax; values parse as TOML values, bare words as strings).
``loads_case(text, overrides=None) -> Case``  — the same from TOML text.
``dump_toml(case) -> str`` — a reloadable TOML file with every value the run uses.
``resolve_domain(case, les_box_m=None) -> Case`` — the SPEC §9 domain rules.

Choices made here (the SPEC leaves them open)
---------------------------------------------
* ``flow.slope`` is in **degrees**, positive when the bed descends in +x (the weight
  then has a +x component, SPEC §2).
* ``flow.tau_c`` defaults to 0.032, the paper's value for Rp = 73 (not computed from Rp).
* Time step: ``run.dt`` (s) or ``run.dt_particle`` (d/u*), at most one; neither gives
  ``dt_particle = 0.02``, the largest step whose jump statistics (H, L, U) were within
  1 % of the converged ones in the convergence study of SPEC §5 (docs/studies/
  stiffness_dt.md: free flight at τ*/τ*c = 1.79, 3 000 grains, 0.02 is +0.4 % in H and U,
  0.04 is +1.8 % in H; with the second-order bed impact, flight/spheres._bed_impact. Before
  it the default was 0.005: 0.02 was 4 % off). It resolves τ_p/5 (rule 1) for quartz
  grains down to 0.1 mm in water.
  Two rules, checked before any run:
  (1) ``dt ≤ τ_p / 5`` where τ_p = (ρp/ρ + Cm) d² / (18 ν f) is the grain's drag response
  time with Yen's (1992) drag correction f = C_D Re_p / 24 taken at a slip of 10 u*
  (Re_p = 10 Re*); the Stokes value (f = 1) alone is too lax for coarse grains;
  (2) ``dt ≤ 0.05 d/u*``, so a grain at 10 u* moves at most half a diameter per step and
  no bed or grain contact is stepped over.
* ``forces.added_mass = false`` removes the added mass completely: Cm = 0 in α as well.
* ``source = "still"`` with neither ``tau_ratio`` nor ``shear_velocity``: the velocity
  scale of the particle units is √(g R d), so τ* = 1, Re* = Rp and τ*/τ*c = 1/τ*c.
* Bed coefficients: a named set (default Schmeeckle et al. 2001), or ``"user"`` with
  both ``restitution`` and ``friction``; giving those two without ``coefficients``
  means ``"user"``; a named set together with explicit values is an error.
* Concentration is a volume **fraction** (0.0394, not 3.94) and at most 0.05: the flow is
  one-way coupled, valid for dilute suspensions only (SPEC §3).
* Domain (``run.domain = [Lx, Lz, H]`` m): absent means the LES box at the run's u*
  (passed to :func:`resolve_domain` by the run loop); for the analytic and still sources,
  the paper's box [0.176, 0.088, 0.028] m.
* Grain–grain contacts default to ``"soft"`` (SPEC §5; a single grain never meets one, so
  it costs nothing there); the single-grain validation cases say ``"off"`` explicitly.
* Soft contacts: stiffness absent means the smallest stiffness that keeps the overlap
  at ``max_overlap`` d for a relative normal speed of ``impact_speed`` u*; a given
  stiffness below it is an error. The contact (duration π√(m_eff/k)) is resolved in 20
  sub-steps; ``Case.contact_substeps`` says how many per hydrodynamic step.
* Output intervals absent: tracks every 0.5 d/u*, VTK 100 frames per run.
* Checkpoints (``output.checkpoint_every`` s of wall time, ``output.checkpoint_steps``
  steps) are taken at the run loop's chunk ends only, so a resumed run is bit for bit
  the uninterrupted one; neither key changes the physics.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from flowfields.dataset import SHIPPED_DATASETS

from ..physics.forces import yen_drag_coefficient

__all__ = [
    "GRAVITY",
    "PAPER_DOMAIN_M",
    "MAX_CONCENTRATION",
    "BED_COEFFICIENT_SETS",
    "CaseError",
    "ParticleConfig",
    "FluidConfig",
    "FlowConfig",
    "ForcesConfig",
    "BedConfig",
    "CollisionsConfig",
    "RunConfig",
    "OutputConfig",
    "Case",
    "load_case",
    "loads_case",
    "dump_toml",
    "resolve_domain",
    "parse_overrides",
]

GRAVITY = 9.81  # m/s², SPEC §1
PAPER_DOMAIN_M = (0.176, 0.088, 0.028)  # [Lx, Lz, H] of Moreno-Casas et al. (2022)
MAX_CONCENTRATION = 0.05  # one-way coupling limit (SPEC §3)
DEFAULT_DT_PARTICLE = 0.02  # d/u*: within 1 % of converged jump statistics (docs/studies/stiffness_dt.md)
MAX_DT_PARTICLE = 0.05  # d/u*: a grain at 10 u* moves ≤ d/2 per step
RESPONSE_TIME_STEPS = 5  # dt ≤ τ_p / 5
RESPONSE_SLIP = 10.0  # u*: slip at which the drag correction of τ_p is taken
CONTACT_STEPS = 20  # a soft contact is resolved in ≥ 20 (sub-)steps, SPEC §5
TRACKS_INTERVAL_PARTICLE = 0.5  # d/u*, default track sampling
VTK_FRAMES = 100  # default number of ParaView frames per run
VARIANCE_INTERVAL_PARTICLE = 0.1  # d/u*, default sampling of the diffusion variances

# Paper Table 2: restitution e and Coulomb friction f of the bed rebound (SPEC §4).
# Niño & García (1994): e = 0.75 − 0.25 τ*/τ*c.
BED_COEFFICIENT_SETS = {
    "schmeeckle-2001": (0.65, 0.10),
    "nino-garcia-1994": (None, 0.89),
    "tsuji-1987": (0.80, 0.40),
}

_REQUIRED = "required"
# particle.shape: the point-particle sphere, a natural mixture, or one Zingg class
SHAPES = ("sphere", "mixture", "disk", "blade", "rod", "equant")
# particle.construction: shapes.build's method (shapes.METHODS)
CONSTRUCTIONS = ("seed", "fitted")


class CaseError(ValueError):
    """A case that cannot run. The message names the table, the key and what is allowed.

    ``table`` and ``key`` hold the offending names where one key is to blame.
    ``override`` is the override (``"table.key"``, as given) to blame when the bad value
    came from an override (``--set``, a keyword of ``run``) rather than from the case
    file; ``reason`` is the message without the "where it came from" prefix.
    """

    def __init__(self, message: str, table: str | None = None, key: str | None = None, *,
                 override: str | None = None, reason: str | None = None):
        super().__init__(message)
        self.table = table
        self.key = key
        self.override = override
        self.reason = message if reason is None else reason


# --------------------------------------------------------------------------- schema


def _key(default: Any = None, *, kind: str, doc: str, unit: str = "", required: bool = False,
         gt: float | None = None, ge: float | None = None, lt: float | None = None,
         le: float | None = None, choices: tuple[str, ...] | None = None,
         aliases: Mapping[str, str] | None = None):
    """One case-file key: a dataclass field whose metadata is its schema entry.

    kind: "float" | "int" | "bool" | "str" | "path" | "choice" | "vec3" | "fractions" | "ratios".
    """
    meta = dict(kind=kind, doc=doc, unit=unit, required=required, gt=gt, ge=ge, lt=lt,
                le=le, choices=choices, aliases=dict(aliases or {}))
    return field(default=default, metadata=meta)


def _range_text(m: Mapping[str, Any]) -> str:
    parts = []
    if m["gt"] is not None:
        parts.append(f"> {m['gt']:g}")
    if m["ge"] is not None:
        parts.append(f">= {m['ge']:g}")
    if m["lt"] is not None:
        parts.append(f"< {m['lt']:g}")
    if m["le"] is not None:
        parts.append(f"<= {m['le']:g}")
    unit = f" {m['unit']}" if m["unit"] else ""
    return " and ".join(parts) + unit


def _normalise(table: str, name: str, m: Mapping[str, Any], value: Any) -> Any:
    """Type-check, convert and range-check one value; None passes (absent)."""
    where = f"{table}.{name}"
    kind = m["kind"]
    if value is None:
        if m["required"]:
            raise CaseError(f"{where} is required but missing: {m['doc']}", table, name)
        return None

    def wrong(expected: str) -> CaseError:
        return CaseError(f"{where} must be {expected}, got {value!r} "
                         f"({type(value).__name__})", table, name)

    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise wrong("a number")
        value = float(value)
        if not math.isfinite(value):
            raise wrong("a finite number")
    elif kind == "int":
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise wrong("an integer")
    elif kind == "bool":
        if not isinstance(value, bool):
            raise wrong("true or false")
    elif kind in ("str", "path"):
        if not isinstance(value, str) or not value.strip():
            raise wrong("a non-empty string")
    elif kind == "choice":
        allowed = ", ".join(f'"{c}"' for c in m["choices"])
        if not isinstance(value, str):
            raise wrong(f"one of {allowed}")
        word = value.strip().lower().replace("_", "-").replace(" ", "-")
        word = m["aliases"].get(word, word)
        if word not in m["choices"]:
            guess = _closest(word, m["choices"])
            hint = f' (did you mean "{guess}"?)' if guess else ""
            raise CaseError(f"{where} = {value!r} is not allowed: must be one of "
                            f"{allowed}{hint}", table, name)
        value = word
    elif kind in ("fractions", "ratios"):
        return _class_table(where, table, name, kind, value)
    elif kind == "vec3":
        if (not isinstance(value, (list, tuple)) or len(value) != 3
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)):
            raise wrong("a list of three numbers [Lx, Lz, H]")
        value = tuple(float(v) for v in value)
        if not all(math.isfinite(v) and v > 0 for v in value):
            raise CaseError(f"{where} = {list(value)!r} is out of range: every entry must be "
                            f"> 0 {m['unit']}", table, name)
        return value
    else:  # pragma: no cover - schema error
        raise AssertionError(kind)

    if kind in ("float", "int"):
        bad = ((m["gt"] is not None and not value > m["gt"])
               or (m["ge"] is not None and not value >= m["ge"])
               or (m["lt"] is not None and not value < m["lt"])
               or (m["le"] is not None and not value <= m["le"]))
        if bad:
            raise CaseError(f"{where} = {value!r} is out of range: must be {_range_text(m)}",
                            table, name)
    return value


def _class_table(where: str, table: str, name: str, kind: str, value: Any) -> dict:
    """particle.fractions / particle.ratios: a table keyed by Zingg class, checked by
    saltation.grains.shapes (fractions in [0, 1] summing to 1; ratio ranges inside the class)."""
    from ..grains.shapes import CLASSES, _check_ratios, check_fractions

    if not isinstance(value, Mapping) or not value:
        what = ("{disk = 0.43, blade = 0.09, rod = 0.14, equant = 0.34}" if kind == "fractions"
                else "{disk = [[0.7, 1.0], [0.3, 0.6]], ...}")
        raise CaseError(f"{where} must be an inline table keyed by Zingg class "
                        f"({', '.join(CLASSES)}), e.g. {what}; got {value!r}", table, name)
    try:
        if kind == "fractions":
            full = check_fractions({str(k): v for k, v in value.items()})
            return {k: full[k] for k in CLASSES if k in value}
        _check_ratios({str(k): v for k, v in value.items()})
    except ValueError as err:
        raise CaseError(f"{where}: {err}", table, name) from None
    return {str(k): [[float(x) for x in v[0]], [float(x) for x in v[1]]] for k, v in value.items()}


class _Table:
    """Base of the table dataclasses: validates and converts every field on creation."""

    TABLE: ClassVar[str] = ""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = _normalise(self.TABLE, f.name, f.metadata, getattr(self, f.name))
            object.__setattr__(self, f.name, value)
        self._check()

    def _check(self) -> None:
        """Rules that involve several keys of the same table."""

    def _error(self, message: str, key: str | None = None) -> CaseError:
        return CaseError(message, self.TABLE, key)

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    def to_dict(self) -> dict[str, Any]:
        """The table as TOML values; absent (None) keys are left out."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is not None:
                out[f.name] = list(value) if isinstance(value, tuple) else value
        return out


@dataclass(frozen=True)
class ParticleConfig(_Table):
    TABLE: ClassVar[str] = "particle"
    diameter: float = _key(kind="float", unit="m", gt=0.0, required=True,
                           doc="grain diameter d (m)")
    density: float = _key(2650.0, kind="float", unit="kg/m³", gt=0.0,
                          doc="grain density ρp (kg/m³); default quartz")
    # Irregular grains as bonded spheres (issue 6, seed 000 §2.4; saltation.grains.shapes):
    # ``diameter`` is then the nominal diameter Dn = (Dl Di Ds)^{1/3} of every grain.
    shape: str = _key("sphere", kind="choice", choices=SHAPES,
                      aliases={"spheres": "sphere", "natural": "mixture", "mix": "mixture",
                               "disc": "disk", "disks": "disk", "blades": "blade",
                               "rods": "rod", "equants": "equant"},
                      doc='grain shape: "sphere" (point-particle model), "mixture" (Zingg '
                          'classes drawn with particle.fractions) or one Zingg class '
                          '"disk" | "blade" | "rod" | "equant" (bonded spheres, '
                          'saltation.engine.composites); diameter is the nominal Dn')
    fractions: dict | None = _key(kind="fractions",
                                  doc='Zingg class fractions of shape = "mixture", an inline '
                                      'table {disk, blade, rod, equant} summing to 1; absent: '
                                      'Smith (2003) 0.43, 0.09, 0.14, 0.34')
    ratios: dict | None = _key(kind="ratios",
                               doc='axis-ratio ranges per Zingg class, {class = [[Di/Dl lo, hi], '
                                   '[Ds/Di lo, hi]]}, uniform draws within the class; absent: '
                                   'shapes.DEFAULT_RATIOS')
    construction: str | None = _key(kind="choice", choices=CONSTRUCTIONS,
                                    doc='how each grain is built from its axes: "seed" (the seed '
                                        'paper\'s spheres) or "fitted" (the same layout, sphere '
                                        'sizes and spacings fitted per grain to the volume and '
                                        'moments of inertia of the same-axes ellipsoid); absent: '
                                        '"seed" (saltation.grains.shapes.build)')

    def _check(self):
        if self.shape == "sphere":
            for k in ("fractions", "ratios", "construction"):
                if getattr(self, k) is not None:
                    raise self._error(f'particle.{k} is given but particle.shape = "sphere": it '
                                      f'applies to bonded-sphere shapes only ("mixture", '
                                      f'{", ".join(chr(34) + c + chr(34) for c in SHAPES[2:])})', k)
        if self.fractions is not None and self.shape != "mixture":
            raise self._error(f'particle.fractions applies to shape = "mixture" only, got '
                              f'shape = "{self.shape}" (a single class has fraction 1)', "fractions")

    @property
    def construction_method(self) -> str:
        """shapes.build's method for the grains: particle.construction, "seed" if absent."""
        return self.construction or "seed"

    @property
    def shape_fractions(self) -> dict[str, float]:
        """Zingg class fractions in use: Smith (2003) for a mixture unless given; 1 for a
        single class; {} for spheres."""
        from ..grains.shapes import CLASSES, SMITH_2003

        if self.shape == "sphere":
            return {}
        if self.shape != "mixture":
            return {c: float(c == self.shape) for c in CLASSES}
        return dict(self.fractions) if self.fractions is not None else dict(SMITH_2003)


@dataclass(frozen=True)
class FluidConfig(_Table):
    TABLE: ClassVar[str] = "fluid"
    density: float = _key(1000.0, kind="float", unit="kg/m³", gt=0.0,
                          doc="fluid density ρ (kg/m³); default water")
    viscosity: float = _key(1.0e-6, kind="float", unit="m²/s", gt=0.0,
                            doc="kinematic viscosity ν (m²/s); default water at 20 °C")


@dataclass(frozen=True)
class FlowConfig(_Table):
    TABLE: ClassVar[str] = "flow"
    source: str = _key("les", kind="choice", choices=("les", "loglaw", "still"),
                       aliases={"log-law": "loglaw", "log": "loglaw", "analytic": "loglaw"},
                       doc='flow source: "les" (stored snapshots), "loglaw" (analytic mean '
                           'profile) or "still" (quiescent fluid, settling)')
    dataset: str | None = _key(kind="path",
                               doc="LES dataset path (relative paths: to the case file), or the name "
                                   'of a shipped one: "sandbed395" (a sand bed inside the LES, grain '
                                   'd+ = 19.5) or "channel395" (smooth walls, the paper\'s set-up); '
                                   "absent: channel395")
    bed: str = _key("auto", kind="choice", choices=("auto", "smooth", "rough"),
                    doc='what the LES dataset must carry: "rough" (a sand bed inside the LES; a '
                        'smooth-wall dataset is refused), "smooth", or "auto" (as the dataset is); '
                        "over a rough bed the grains' Re* must lie within 20 % of the bed grain's d+")
    tau_ratio: float | None = _key(kind="float", gt=0.0,
                                   doc="flow intensity τ*/τ*c (give this or shear_velocity)")
    shear_velocity: float | None = _key(kind="float", unit="m/s", gt=0.0,
                                        doc="shear velocity u* (m/s) (give this or tau_ratio)")
    tau_c: float = _key(0.032, kind="float", gt=0.0, lt=1.0,
                        doc="critical Shields number τ*c")
    slope: float = _key(0.0, kind="float", unit="deg", gt=-90.0, lt=90.0,
                        doc="bed slope θ in degrees, positive descending in +x")
    profile: str = _key("loglaw", kind="choice", choices=("loglaw", "rough", "composite"),
                        aliases={"log-law": "loglaw", "smooth": "loglaw",
                                 "reichardt": "composite", "spalding": "composite"},
                        doc='analytic profile (source "loglaw" only): "loglaw" (smooth), '
                            '"rough" (2.5 ln(30 y/k_s)) or "composite" (continuous from y⁺=0)')
    roughness: float = _key(2.5, kind="float", unit="d", gt=0.0,
                            doc='roughness height k_s in d (profile "rough" only); '
                                'default 2.5 d (Engelund & Hansen)')

    def _check(self):
        given = [k for k in ("tau_ratio", "shear_velocity") if getattr(self, k) is not None]
        if len(given) == 2:
            raise self._error("flow.tau_ratio and flow.shear_velocity are both given: give "
                              "exactly one (τ*/τ*c, or u* in m/s)", "tau_ratio")
        if not given and self.source != "still":
            raise self._error(f'flow.tau_ratio or flow.shear_velocity is required (missing) '
                              f'for source = "{self.source}": give exactly one (τ*/τ*c, or '
                              f'u* in m/s); only source = "still" may have neither',
                              "tau_ratio")

    @property
    def slope_radians(self) -> float:
        return math.radians(self.slope)


@dataclass(frozen=True)
class ForcesConfig(_Table):
    TABLE: ClassVar[str] = "forces"
    drag: bool = _key(True, kind="bool", doc="drag, Yen (1992) C_D")
    lift: bool = _key(True, kind="bool", doc="shear lift")
    magnus: bool = _key(True, kind="bool", doc="Magnus (spin) force")
    added_mass: bool = _key(True, kind="bool",
                            doc="added mass (false also removes Cm from the inertia)")
    fluid_acceleration: bool = _key(True, kind="bool",
                                    doc="fluid acceleration / pressure gradient")
    basset: bool = _key(True, kind="bool", doc="Basset history force")
    weight: bool = _key(True, kind="bool", doc="submerged weight")
    spin: bool = _key(True, kind="bool",
                      doc="spin law in free flight: rotational drag relaxing the grain's spin "
                          "toward half the fluid vorticity (SPEC §2, physics/spin.py); false: spin "
                          "changes only at contacts")
    wake_shielding: bool = _key(True, kind="bool",
                                doc="bonded-sphere grains: a component sphere in the wake of "
                                    "another sphere of the same grain feels less drag "
                                    "(flight.composites.wake_factor); no effect on spheres")
    added_mass_coefficient: float = _key(0.5, kind="float", ge=0.0, doc="Cm")
    lift_coefficient: float = _key(0.2, kind="float", ge=0.0, doc="C_L")
    magnus_coefficient: float = _key(1.0, kind="float", ge=0.0, doc="C_Ω")
    basset_impacts: str = _key("keep", kind="choice", choices=("keep", "restart"),
                               doc='Basset history at bed impacts and grain contacts: "keep" (the '
                                   'impulsive slip change enters the history exactly, Lukerchenko '
                                   'et al. 2012; SPEC §2) or "restart" (the memory restarts at every '
                                   'impact, the first round\'s choice; for comparison)')
    basset_window: int = _key(10, kind="int", ge=2,
                              doc="steps in the exact quadrature window of the history "
                                  "integral (van Hinsberg et al. 2011)")


@dataclass(frozen=True)
class BedConfig(_Table):
    TABLE: ClassVar[str] = "bed"
    model: str = _key("virtual", kind="choice", choices=("virtual", "packed"),
                      doc='"virtual" (random contact angles) or "packed" (hexagonal layer)')
    coefficients: str | None = _key(
        kind="choice", choices=("schmeeckle-2001", "nino-garcia-1994", "tsuji-1987", "user"),
        aliases={"schmeeckle": "schmeeckle-2001", "nino-garcia": "nino-garcia-1994",
                 "niño-garcía-1994": "nino-garcia-1994", "niño-garcía": "nino-garcia-1994",
                 "tsuji": "tsuji-1987"},
        doc='restitution/friction set: "schmeeckle-2001" (default), "nino-garcia-1994", '
            '"tsuji-1987" or "user"')
    restitution: float | None = _key(kind="float", ge=0.0, le=1.0,
                                     doc='bed restitution e (coefficients = "user")')
    friction: float | None = _key(kind="float", ge=0.0,
                                  doc='bed Coulomb friction f (coefficients = "user")')
    max_tilt: float = _key(30.0, kind="float", unit="deg", gt=0.0, lt=90.0,
                           doc="largest tilt of the contact normal (virtual bed), degrees")

    def __post_init__(self):
        if self.coefficients is None:
            own = self.restitution is not None or self.friction is not None
            object.__setattr__(self, "coefficients", "user" if own else "schmeeckle-2001")
        super().__post_init__()

    def _check(self):
        if self.coefficients == "user":
            for k in ("restitution", "friction"):
                if getattr(self, k) is None:
                    raise self._error(f'bed.{k} is required (missing) with user coefficients: '
                                      f'give both bed.restitution (0 to 1) and bed.friction '
                                      f'(>= 0), or a named bed.coefficients set', k)
        else:
            for k in ("restitution", "friction"):
                if getattr(self, k) is not None:
                    raise self._error(
                        f'bed.{k} conflicts with bed.coefficients = "{self.coefficients}", '
                        f'which sets it: use coefficients = "user" to give your own values', k)

    @property
    def max_tilt_radians(self) -> float:
        return math.radians(self.max_tilt)


@dataclass(frozen=True)
class CollisionsConfig(_Table):
    TABLE: ClassVar[str] = "collisions"
    model: str = _key("soft", kind="choice", choices=("soft", "hard", "off"),
                      doc='particle–particle contacts: "soft" (spring–dashpot, sub-stepped; '
                          'the default and the reference), "hard" (binary impulse at step ends, '
                          'overlaps pushed apart; measured 9–17 % lower H and L than soft at '
                          '0.52–3.94 %: a cheap approximation) or "off"')
    restitution: float = _key(0.65, kind="float", ge=0.0, le=1.0,
                              doc="grain–grain restitution e (Schmeeckle et al. 2001)")
    friction: float = _key(0.10, kind="float", ge=0.0,
                           doc="grain–grain Coulomb friction f (Schmeeckle et al. 2001)")
    stiffness: float | None = _key(kind="float", unit="N/m", gt=0.0,
                                   doc="normal spring stiffness k_n (N/m); absent: the "
                                       "smallest that keeps overlaps at max_overlap")
    tangential_stiffness_ratio: float = _key(2.0 / 7.0, kind="float", gt=0.0, le=1.0,
                                             doc="k_t/k_n (2/7: equal normal and "
                                                 "tangential periods)")
    max_overlap: float = _key(0.01, kind="float", unit="d", gt=0.0, le=0.1,
                              doc="largest overlap in d at impact_speed (SPEC §5: ≲ 1 %)")
    impact_speed: float = _key(10.0, kind="float", unit="u*", gt=0.0,
                               doc="relative normal speed in u* for the overlap rule")
    steps_per_contact: int = _key(CONTACT_STEPS, kind="int", ge=10,
                                  doc="contact sub-steps per (undamped) soft-contact duration "
                                      "(SPEC §5: >= 20; 10 is the least accepted)")
    skin: float | None = _key(kind="float", unit="d", gt=0.0, le=5.0,
                              doc="Verlet neighbour skin in d (soft contacts); absent: twice "
                                  "the distance a grain at 20 u* covers in one step, x1.2, "
                                  ">= 0.1 d (stepping.default_skin); bonded-sphere grains: "
                                  "2 impact_speed dt, >= 0.1 d (contacts.composites.default_skin)")

    def _check(self):
        if self.model == "soft" and self.restitution == 0.0:
            raise self._error('collisions.restitution = 0.0 is out of range for model = "soft": '
                              'must be > 0 (the dashpot of e = 0 is infinitely damped)',
                              "restitution")


@dataclass(frozen=True)
class RunConfig(_Table):
    TABLE: ClassVar[str] = "run"
    name: str | None = _key(kind="str", doc="case name (absent: the case file's stem)")
    n_particles: int | None = _key(kind="int", ge=1,
                                   doc="number of grains (absent: from concentration, or 1)")
    concentration: float | None = _key(kind="float", gt=0.0, le=MAX_CONCENTRATION,
                                       doc="volume fraction C = N (π/6) d³ / (Lx Lz H), "
                                           "a fraction, not a percentage")
    duration: float = _key(kind="float", unit="s", gt=0.0, required=True,
                           doc="simulated time (s)")
    dt: float | None = _key(kind="float", unit="s", gt=0.0,
                            doc="time step (s) (or dt_particle)")
    dt_particle: float | None = _key(kind="float", unit="d/u*", gt=0.0,
                                     doc="time step in d/u* (or dt); default 0.02 (jump "
                                         "statistics within 1 % of converged, SPEC §5 study)")
    seed: int = _key(0, kind="int", ge=0, doc="random seed")
    domain: tuple[float, float, float] | None = _key(
        kind="vec3", unit="m",
        doc="[Lx, Lz, H] (m): streamwise, spanwise extent, reference height of C; "
            "absent: the LES box (analytic sources: the paper's [0.176, 0.088, 0.028])")
    threads: int = _key(0, kind="int", ge=0,
                        doc="worker threads (0: all cores, or one below 2 000 grains, below 256 with soft sphere "
                            "contacts)")
    release_height: float | None = _key(kind="float", unit="d", ge=0.5,
                                        doc="centre height above the bed top, in d, where "
                                            "every grain starts at rest (settling runs)")
    start: str = _key("flight", kind="choice", choices=("flight", "rest"),
                      doc='how grains start: "flight" (near-bed layer, take-off velocities; '
                          'grains/initial.py) or "rest" (each at rest in a hollow of the packed '
                          'bed: bed load, incipient motion; needs bed.model = "packed" and '
                          'collisions.model = "soft"; spheres or bonded-sphere grains)')

    def __post_init__(self):
        if self.dt is None and self.dt_particle is None:
            object.__setattr__(self, "dt_particle", DEFAULT_DT_PARTICLE)
            object.__setattr__(self, "dt_defaulted", True)  # (said so in the time-step errors)
        super().__post_init__()

    def _check(self):
        if self.dt is not None and self.dt_particle is not None:
            raise self._error("run.dt and run.dt_particle are both given: give one (dt in s, "
                              "or dt_particle in d/u*)", "dt")


@dataclass(frozen=True)
class OutputConfig(_Table):
    TABLE: ClassVar[str] = "output"
    directory: str | None = _key(kind="path",
                                 doc="run directory when no --out is given "
                                     "(absent: runs/<run.name>)")
    tracks: bool = _key(True, kind="bool", doc="write tracks.parquet")
    tracks_interval: float | None = _key(kind="float", unit="s", gt=0.0,
                                         doc="track sampling interval (s); absent: 0.5 d/u*")
    vtk: bool = _key(True, kind="bool", doc="write ParaView particles.pvd + VTU pieces")
    vtk_interval: float | None = _key(kind="float", unit="s", gt=0.0,
                                      doc="ParaView frame interval (s); absent: duration/100")
    variance: bool = _key(True, kind="bool",
                          doc="accumulate the displacement variances of the diffusion analysis "
                              "during the run (variance.parquet, SPEC §6; needs >= 2 grains)")
    variance_interval: float | None = _key(kind="float", unit="s", gt=0.0,
                                           doc="sampling interval of the displacement variances "
                                               "(s); absent: 0.1 d/u*")
    variance_origins: int = _key(8, kind="int", ge=1,
                                 doc="time origins the displacement variances are averaged over")
    checkpoint_every: float = _key(600.0, kind="float", unit="s", ge=0.0,
                                   doc="wall-clock seconds between checkpoints (engine/simulation.py; "
                                       "0: none by time); every 5 % of the steps and SIGINT/SIGTERM "
                                       "always write one")
    checkpoint_steps: int = _key(0, kind="int", ge=0,
                                 doc="also checkpoint every this many time steps (0: none "
                                     "by steps)")


TABLES: dict[str, type[_Table]] = {
    "particle": ParticleConfig,
    "fluid": FluidConfig,
    "flow": FlowConfig,
    "forces": ForcesConfig,
    "bed": BedConfig,
    "collisions": CollisionsConfig,
    "run": RunConfig,
    "output": OutputConfig,
}


def _yen_drag_factor(re_p: float) -> float:
    """C_D Re_p / 24 of the Yen (1992) drag law of SPEC §2 (physics/forces.py; 1 in the Stokes limit)."""
    return yen_drag_coefficient.py_func(re_p) * re_p / 24.0


# --------------------------------------------------------------------------- the case


@dataclass(frozen=True)
class Case:
    """A resolved case: the eight tables plus derived quantities (SPEC §1) as properties.

    Units: SI unless a name ends in ``_particle`` (particle units: d, u*, d/u*) or the
    docstring says otherwise. Constructing a Case (also with ``dataclasses.replace``)
    validates the whole case and raises :class:`CaseError` on impossible physics.
    """

    particle: ParticleConfig
    flow: FlowConfig
    run: RunConfig
    fluid: FluidConfig = field(default_factory=FluidConfig)
    forces: ForcesConfig = field(default_factory=ForcesConfig)
    bed: BedConfig = field(default_factory=BedConfig)
    collisions: CollisionsConfig = field(default_factory=CollisionsConfig)
    output: OutputConfig = field(default_factory=OutputConfig)

    def __post_init__(self):
        for name, cls in TABLES.items():
            if not isinstance(getattr(self, name), cls):
                raise TypeError(f"Case.{name} must be a {cls.__name__}")
        self._check()

    # -- material and flow ---------------------------------------------------------

    @property
    def gravity(self) -> float:
        """g (m/s²)."""
        return GRAVITY

    @property
    def density_ratio(self) -> float:
        """ρp/ρ."""
        return self.particle.density / self.fluid.density

    @property
    def submerged_specific_gravity(self) -> float:
        """R = ρp/ρ − 1."""
        return self.density_ratio - 1.0

    R = submerged_specific_gravity

    @property
    def particle_reynolds(self) -> float:
        """Rp = √(g R d³)/ν, the explicit particle Reynolds number."""
        d = self.particle.diameter
        return math.sqrt(GRAVITY * self.R * d**3) / self.fluid.viscosity

    Rp = particle_reynolds

    @property
    def shields_number(self) -> float:
        """τ* = u*²/(g R d): tau_ratio·tau_c, or from flow.shear_velocity.

        For a still fluid with neither, 1 (the velocity scale is then √(g R d)).
        """
        flow = self.flow
        if flow.tau_ratio is not None:
            return flow.tau_ratio * flow.tau_c
        if flow.shear_velocity is not None:
            return flow.shear_velocity**2 / (GRAVITY * self.R * self.particle.diameter)
        return 1.0

    tau_star = shields_number

    @property
    def shear_velocity(self) -> float:
        """u* (m/s), the velocity scale of the particle units (√(τ* g R d))."""
        if self.flow.shear_velocity is not None:
            return self.flow.shear_velocity
        return math.sqrt(self.shields_number * GRAVITY * self.R * self.particle.diameter)

    @property
    def tau_ratio(self) -> float:
        """τ*/τ*c."""
        if self.flow.tau_ratio is not None:
            return self.flow.tau_ratio
        return self.shields_number / self.flow.tau_c

    @property
    def shear_reynolds(self) -> float:
        """Re* = u* d/ν = √τ*·Rp, also the grain diameter in wall units d⁺."""
        return self.shear_velocity * self.particle.diameter / self.fluid.viscosity

    re_star = shear_reynolds

    @property
    def added_mass_coefficient(self) -> float:
        """Cm in use: forces.added_mass_coefficient, or 0 with forces.added_mass off."""
        return self.forces.added_mass_coefficient if self.forces.added_mass else 0.0

    Cm = added_mass_coefficient

    @property
    def inertia_factor(self) -> float:
        """α = 1/(1 + R + Cm)."""
        return 1.0 / (1.0 + self.R + self.Cm)

    alpha = inertia_factor

    @property
    def length_scale(self) -> float:
        """d (m)."""
        return self.particle.diameter

    @property
    def time_scale(self) -> float:
        """d/u* (s)."""
        return self.particle.diameter / self.shear_velocity

    @property
    def viscous_length(self) -> float:
        """ν/u* (m): x⁺ = x / viscous_length."""
        return self.fluid.viscosity / self.shear_velocity

    @property
    def particle_volume(self) -> float:
        """(π/6) d³ (m³)."""
        return math.pi / 6.0 * self.particle.diameter**3

    @property
    def particle_mass(self) -> float:
        """ρp (π/6) d³ (kg)."""
        return self.particle.density * self.particle_volume

    @property
    def stokes_response_time(self) -> float:
        """(ρp/ρ + Cm) d²/(18 ν) (s): response time in Stokes drag."""
        d = self.particle.diameter
        return (self.density_ratio + self.Cm) * d * d / (18.0 * self.fluid.viscosity)

    @property
    def response_time(self) -> float:
        """Drag response time (s): the Stokes value over Yen's C_D Re_p/24 at a slip of 10 u*."""
        return self.stokes_response_time / _yen_drag_factor(RESPONSE_SLIP * self.re_star)

    # -- time -------------------------------------------------------------------------

    @property
    def dt(self) -> float:
        """Time step (s)."""
        if self.run.dt is not None:
            return self.run.dt
        return self.run.dt_particle * self.time_scale

    @property
    def dt_particle(self) -> float:
        """Time step in d/u*."""
        if self.run.dt_particle is not None:
            return self.run.dt_particle
        return self.run.dt / self.time_scale

    @property
    def duration(self) -> float:
        """Simulated time (s)."""
        return self.run.duration

    @property
    def duration_particle(self) -> float:
        """Simulated time in d/u*."""
        return self.run.duration / self.time_scale

    @property
    def n_steps(self) -> int:
        """Steps to cover the duration (the last may end past it by less than dt)."""
        return max(1, math.ceil(self.duration / self.dt - 1e-9))

    def _steps_per(self, interval: float) -> int:
        return max(1, round(interval / self.dt))

    @property
    def tracks_every(self) -> int:
        """Steps between track samples (output.tracks_interval, or 0.5 d/u*)."""
        given = self.output.tracks_interval
        return self._steps_per(given if given is not None
                               else TRACKS_INTERVAL_PARTICLE * self.time_scale)

    @property
    def tracks_interval(self) -> float:
        """Track sampling interval (s), a whole number of steps."""
        return self.tracks_every * self.dt

    @property
    def variance_every(self) -> int:
        """Steps between samples of the diffusion variances (output.variance_interval, or 0.1 d/u*)."""
        given = self.output.variance_interval
        return self._steps_per(given if given is not None
                               else VARIANCE_INTERVAL_PARTICLE * self.time_scale)

    @property
    def vtk_every(self) -> int:
        """Steps between ParaView frames (output.vtk_interval, or duration/100)."""
        given = self.output.vtk_interval
        return self._steps_per(given if given is not None else self.duration / VTK_FRAMES)

    @property
    def vtk_interval(self) -> float:
        """ParaView frame interval (s), a whole number of steps."""
        return self.vtk_every * self.dt

    # -- bed and contacts ---------------------------------------------------------------

    @property
    def bed_restitution(self) -> float:
        """Bed restitution e in use (named set or user value)."""
        if self.bed.coefficients == "user":
            return self.bed.restitution
        if self.bed.coefficients == "nino-garcia-1994":
            return 0.75 - 0.25 * self.tau_ratio
        return BED_COEFFICIENT_SETS[self.bed.coefficients][0]

    @property
    def bed_friction(self) -> float:
        """Bed Coulomb friction f in use (named set or user value)."""
        if self.bed.coefficients == "user":
            return self.bed.friction
        return BED_COEFFICIENT_SETS[self.bed.coefficients][1]

    def _auto_stiffness(self) -> float:
        c = self.collisions
        speed = c.impact_speed * self.shear_velocity
        overlap = c.max_overlap * self.particle.diameter
        return 0.5 * self.particle_mass * (speed / overlap) ** 2

    @property
    def collision_stiffness(self) -> float:
        """Normal contact stiffness k_n (N/m): given, or the overlap rule's value.

        Overlap rule: an undamped contact of two equal grains (m_eff = m/2) at relative
        normal speed v = impact_speed·u* peaks at δ = v √(m_eff/k) = max_overlap·d.
        """
        return self.collisions.stiffness or self._auto_stiffness()

    @property
    def contact_duration(self) -> float:
        """π √(m_eff/k_n) (s), the undamped (shortest) soft-contact duration."""
        return math.pi * math.sqrt(0.5 * self.particle_mass / self.collision_stiffness)

    @property
    def contact_substeps(self) -> int:
        """Contact sub-steps per time step so a soft contact spans ≥ 20 of them (1 if not soft)."""
        if self.collisions.model != "soft":
            return 1
        steps = self.collisions.steps_per_contact
        return max(1, math.ceil(steps * self.dt / self.contact_duration - 1e-9))

    # -- domain and number of grains -------------------------------------------------

    def _domain_solution(self, les_box_m=None):
        """(domain, n_particles, concentration) by the SPEC §9 rules; None where unknown."""
        run = self.run
        vp = self.particle_volume
        base = run.domain or (tuple(les_box_m) if les_box_m is not None else None)
        if base is None and self.flow.source != "les":
            base = PAPER_DOMAIN_M
        n, c = run.n_particles, run.concentration
        if base is None:
            if c is None:
                return None, n or 1, None
            return None, n, c
        volume = base[0] * base[1] * base[2]
        if n is not None and c is not None:
            scale = (n * vp / c / volume) ** (1.0 / 3.0)
            return tuple(scale * x for x in base), n, c
        if c is not None:
            n = round(c * volume / vp)
            if n < 1:
                raise CaseError(f"run.concentration = {c!r} puts fewer than one grain in the "
                                f"domain {list(base)!r} m: raise it, or give run.n_particles",
                                "run", "concentration")
            return base, n, n * vp / volume
        n = n or 1
        return base, n, n * vp / volume

    @property
    def domain(self) -> tuple[float, float, float] | None:
        """[Lx, Lz, H] (m), or None while the LES box is unknown (see resolve_domain)."""
        return self._domain_solution()[0]

    @property
    def n_particles(self) -> int | None:
        """Number of grains, or None while it depends on an unknown LES box."""
        return self._domain_solution()[1]

    @property
    def concentration(self) -> float | None:
        """C = N (π/6) d³/(Lx Lz H), a volume fraction; None while the domain is unknown."""
        return self._domain_solution()[2]

    # -- checks ---------------------------------------------------------------------

    def _check(self) -> None:
        if self.particle.density <= self.fluid.density:
            raise CaseError(
                f"particle.density = {self.particle.density!r} kg/m³ must exceed "
                f"fluid.density = {self.fluid.density!r} kg/m³ (ρp/ρ > 1: the grain must "
                f"settle)", "particle", "density")

        dt_key = "dt" if self.run.dt is not None else "dt_particle"
        given = f"run.{dt_key} = {getattr(self.run, dt_key)!r}"
        if getattr(self.run, "dt_defaulted", False):
            given = f"run.dt_particle (not in the case: the default, {DEFAULT_DT_PARTICLE:g} d/u*)"
        limit = self.response_time / RESPONSE_TIME_STEPS
        if self.dt > limit * (1 + 1e-12):
            raise CaseError(
                f"{given} does not resolve the grain's response time: dt = {self.dt:.4g} s must "
                f"be <= τ_p/{RESPONSE_TIME_STEPS} = {limit:.4g} s "
                f"({limit / self.time_scale:.4g} d/u*), τ_p = (ρp/ρ + Cm) d²/(18 ν f) with "
                f"Yen's drag factor f at a slip of {RESPONSE_SLIP:g} u*; give run.dt_particle <= "
                f"{limit / self.time_scale:.4g} (or run.dt <= {limit:.4g})", "run", dt_key)
        if self.dt_particle > MAX_DT_PARTICLE * (1 + 1e-12):
            raise CaseError(
                f"{given} is too coarse: dt = {self.dt_particle:.4g} d/u* must be <= "
                f"{MAX_DT_PARTICLE:g} d/u* = {MAX_DT_PARTICLE * self.time_scale:.4g} s "
                f"(a grain at 10 u* must move at most d/2 per step)", "run", dt_key)
        if self.dt > self.duration:
            raise CaseError(f"run.duration = {self.duration!r} s is shorter than one time step "
                            f"dt = {self.dt:.4g} s: must be >= dt", "run", "duration")
        for key in ("tracks_interval", "vtk_interval", "variance_interval"):
            value = getattr(self.output, key)
            if value is not None and value < self.dt * (1 - 1e-9):
                raise CaseError(f"output.{key} = {value!r} s is out of range: must be >= the "
                                f"time step dt = {self.dt:.4g} s", "output", key)

        if self.bed.coefficients == "nino-garcia-1994":
            e = self.bed_restitution
            if not 0.0 <= e <= 1.0:
                raise CaseError(
                    f'bed.coefficients = "nino-garcia-1994" gives restitution '
                    f'e = 0.75 - 0.25 τ*/τ*c = {e:.4g} at τ*/τ*c = {self.tau_ratio:.4g}, '
                    f'outside [0, 1]: that set holds for τ*/τ*c <= 3 only; choose another '
                    f'bed.coefficients set', "bed", "coefficients")

        if self.run.start == "rest":
            need = [(f'bed.model = "{self.bed.model}"', self.bed.model == "packed", '"packed" (hollows to rest in)'),
                    (f'collisions.model = "{self.collisions.model}"', self.collisions.model == "soft",
                     '"soft" (resting contacts are soft contacts with the bed spheres)')]
            for given, ok, want in need:
                if not ok:
                    raise CaseError(f'run.start = "rest" needs {want}, got {given}', "run", "start")
            if self.run.release_height is not None:
                raise CaseError('run.start = "rest" and run.release_height are both given: give one '
                                '(rest: in a hollow of the bed; release_height: at rest at that height)',
                                "run", "start")

        c = self.collisions
        if c.model == "soft" and c.stiffness is not None:
            needed = self._auto_stiffness()
            if c.stiffness < needed * (1 - 1e-12):
                raise CaseError(
                    f"collisions.stiffness = {c.stiffness!r} N/m is out of range: must be >= "
                    f"{needed:.4g} N/m to keep overlaps <= collisions.max_overlap = "
                    f"{c.max_overlap:g} d at {c.impact_speed:g} u* (or leave it out)",
                    "collisions", "stiffness")

        domain, n, conc = self._domain_solution()
        if domain is not None:
            d = self.particle.diameter
            key = "domain" if self.run.domain is not None else "n_particles"
            if min(domain[0], domain[1]) < 3 * d or domain[2] < d:
                raise CaseError(
                    f"run.domain = {[float(f'{x:.6g}') for x in domain]!r} m is too small "
                    f"for d = {d:g} m: Lx and Lz must be >= 3 d and H >= d", "run", key)
        if conc is not None and conc > MAX_CONCENTRATION * (1 + 1e-9):
            raise CaseError(
                f"run.n_particles = {n!r} in run.domain = {list(domain)!r} m gives a "
                f"concentration of {conc:.4g}, out of range: must be <= {MAX_CONCENTRATION:g} "
                f"(one-way coupling, SPEC §3)", "run", "n_particles")

    # -- output ---------------------------------------------------------------------

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """The case as tables of TOML values (absent keys left out); reloads to an equal Case."""
        return {name: getattr(self, name).to_dict() for name in TABLES}

    def derived(self) -> dict[str, Any]:
        """The derived numbers (for summaries and the header of dump_toml)."""
        out = {
            "R": self.R,
            "tau_star": self.tau_star,
            "tau_ratio": self.tau_ratio,
            "shear_velocity_m_s": self.shear_velocity,
            "Rp": self.Rp,
            "re_star": self.re_star,
            "alpha": self.alpha,
            "Cm": self.Cm,
            "time_scale_s": self.time_scale,
            "dt_s": self.dt,
            "dt_particle": self.dt_particle,
            "duration_particle": self.duration_particle,
            "n_steps": self.n_steps,
            "response_time_s": self.response_time,
            "bed_restitution": self.bed_restitution,
            "bed_friction": self.bed_friction,
            "collision_stiffness_N_m": self.collision_stiffness,
            "contact_substeps": self.contact_substeps,
            "tracks_every": self.tracks_every,
            "vtk_every": self.vtk_every,
            "variance_every": self.variance_every,
        }
        domain, n, conc = self._domain_solution()
        out.update(domain_m=list(domain) if domain else None, n_particles=n,
                   concentration=conc)
        return out


# --------------------------------------------------------------------------- loading


def _closest(word: str, options: Iterable[str]) -> str | None:
    hits = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return hits[0] if hits else None


def _check_names(tables: Mapping[str, Any]) -> None:
    """Unknown tables and keys, with the closest valid name."""
    for name, content in tables.items():
        if name in TABLES and not isinstance(content, Mapping):
            raise CaseError(f"[{name}] must be a table of keys, got {content!r}", name)
        if name not in TABLES:
            if not isinstance(content, Mapping):
                homes = [t for t, cls in TABLES.items() if name in cls.keys()]
                hint = f"; put it in [{homes[0]}]" if homes else ""
                raise CaseError(f"top-level key {name!r} is outside any table{hint}. "
                                f"Tables: {', '.join(TABLES)}", None, name)
            guess = _closest(name, TABLES)
            hint = f"; did you mean [{guess}]?" if guess else "."
            raise CaseError(f"unknown table [{name}]{hint} Tables: {', '.join(TABLES)}", name)
        valid = TABLES[name].keys()
        for key in content:
            if key not in valid:
                guess = _closest(key, valid)
                hint = f"; did you mean {name}.{guess}?" if guess else "."
                raise CaseError(f"unknown key {name}.{key}{hint} Keys of [{name}]: "
                                f"{', '.join(valid)}", name, key)


def _path_keys() -> list[tuple[str, str]]:
    return [(t, f.name) for t, cls in TABLES.items() for f in dataclasses.fields(cls)
            if f.metadata["kind"] == "path" and f.name != "directory"]


def _resolve_paths(tables: dict[str, dict[str, Any]], base: Path) -> None:
    """Relative dataset paths → absolute, against ``base`` (case-file folder or cwd)."""
    for table, key in _path_keys():
        value = tables.get(table, {}).get(key)
        if isinstance(value, str) and value.strip():
            if key == "dataset" and value in SHIPPED_DATASETS:
                continue  # a shipped dataset's name
            p = Path(value).expanduser()
            tables[table][key] = os.path.normpath(p if p.is_absolute() else base / p)


def _parse_value(text: str) -> Any:
    """A TOML value; a bare word that is not one is taken as a string."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_overrides(overrides) -> dict[str, dict[str, Any]]:
    """``{"table.key": v}`` or ``["table.key=value", ...]`` → ``{table: {key: v}}``.

    ``table__key`` is accepted for ``table.key`` (keyword arguments cannot hold dots).
    """
    if overrides is None:
        return {}
    if isinstance(overrides, str):
        overrides = [overrides]
    if isinstance(overrides, Mapping):
        items = list(overrides.items())
    else:
        items = []
        for item in overrides:
            if not isinstance(item, str) or "=" not in item:
                raise CaseError(f"override {item!r} must read table.key=value")
            name, _, text = item.partition("=")
            items.append((name, _parse_value(text)))
    out: dict[str, dict[str, Any]] = {}
    for name, value in items:
        name = name.strip().replace("__", ".")
        table, dot, key = name.partition(".")
        if not dot or not table or not key or "." in key:
            raise CaseError(f"override {name!r} must name table.key (e.g. run.seed)")
        out.setdefault(table, {})[key] = value
    return out


# Override one key of an either-or pair and the other leaves the base case.
_EXCLUSIVE = {
    ("flow", "tau_ratio"): ("shear_velocity",),
    ("flow", "shear_velocity"): ("tau_ratio",),
    ("run", "dt"): ("dt_particle",),
    ("run", "dt_particle"): ("dt",),
    ("run", "n_particles"): ("concentration",),
    ("run", "concentration"): ("n_particles",),
    ("bed", "restitution"): ("coefficients",),
    ("bed", "friction"): ("coefficients",),
    ("bed", "coefficients"): ("restitution", "friction"),
}


def _apply_overrides(tables: dict[str, dict[str, Any]], extra: dict[str, dict[str, Any]]):
    for table, keys in extra.items():
        base = tables.setdefault(table, {})
        for key, value in keys.items():
            drops = _EXCLUSIVE.get((table, key), ())
            if (table, key) == ("bed", "coefficients") and str(value).lower() == "user":
                drops = ()
            for other in drops:
                if other not in keys:
                    base.pop(other, None)
            base[key] = value


def _build(tables: dict[str, dict[str, Any]]) -> Case:
    _check_names(tables)
    built = {name: cls(**dict(tables.get(name, {}))) for name, cls in TABLES.items()
             if name in tables or name not in ("particle", "run")}
    for required in ("particle", "run"):
        if required not in built:
            first = "diameter" if required == "particle" else "duration"
            raise CaseError(f"table [{required}] is required (missing): it needs at least "
                            f"{required}.{first}", required, first)
    return Case(**built)


def _override_names(overrides) -> dict[tuple[str, str], tuple[str, Any]]:
    """{(table, key): (name as given, value)} of the overrides that parse."""
    if overrides is None:
        return {}
    if isinstance(overrides, str):
        overrides = [overrides]
    if isinstance(overrides, Mapping):
        items = [(str(k), v) for k, v in overrides.items()]
    else:
        items = [(i.partition("=")[0], _parse_value(i.partition("=")[2])) for i in overrides
                 if isinstance(i, str) and "=" in i]
    out = {}
    for name, value in items:
        table, _, key = name.strip().replace("__", ".").partition(".")
        out[(table, key)] = (name.strip(), value)
    return out


def _blame_override(err: CaseError, name: str, value: Any) -> CaseError:
    shown = "" if value is _NO_VALUE else f" = {value!r}"
    return CaseError(f"override {name}{shown}: {err.reason}", err.table, err.key,
                     override=name, reason=err.reason)


_NO_VALUE = object()


def _from_tables(tables: Mapping[str, Any], overrides, base_dir: Path | None,
                 name: str | None, origin: str | None) -> Case:
    """A Case from tables plus overrides. An error is blamed on the override that gave
    the bad value (``CaseError.override``), else on ``origin`` (the case file)."""
    given = _override_names(overrides)
    try:
        extra = parse_overrides(overrides)
        _resolve_paths(extra, Path.cwd())
        _check_names(extra)
    except CaseError as err:  # the overrides themselves are malformed or name no key
        hit = given.get((err.table or "", err.key or ""))
        if hit is None and err.table is not None:
            hit = next((v for (t, _k), v in given.items() if t == err.table), None)
        if hit is None:  # a name that is not table.key
            hit = next((v for (t, k), v in given.items() if not t or not k or "." in k), None)
        if hit is not None:
            raise _blame_override(err, *hit) from None
        raise CaseError(str(err), err.table, err.key, override="", reason=err.reason) from None
    try:
        raw = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in tables.items()}
        if base_dir is not None:
            _resolve_paths(raw, base_dir)
        _apply_overrides(raw, extra)
        if name is not None and isinstance(raw.get("run"), dict):
            raw["run"].setdefault("name", name)
        return _build(raw)
    except CaseError as err:
        hit = given.get((err.table or "", err.key or ""))
        if hit is not None:
            raise _blame_override(err, *hit) from None
        if origin is None and not given:
            raise
        where = origin or "case"
        if given:  # a check across keys: the case file's key, but overrides in effect
            where += " with override(s) " + ", ".join(f"{n} = {v!r}" for n, v in given.values())
        raise CaseError(f"{where}: {err.reason}", err.table, err.key, reason=err.reason) from None


def load_case(source, overrides=None) -> Case:
    """Load a case from a TOML path, a dict of tables or a Case, then apply overrides.

    Relative ``flow.dataset`` paths are taken from the case file's folder (from the
    working directory for dicts and overrides) and stored absolute. ``run.name``
    defaults to the file's stem.
    """
    if isinstance(source, Case):
        return _from_tables(source.to_dict(), overrides, None, None, None)
    if isinstance(source, Mapping):
        return _from_tables(source, overrides, Path.cwd(), None, None)
    path = Path(source)
    try:
        with open(path, "rb") as fh:
            tables = tomllib.load(fh)
    except FileNotFoundError:
        raise CaseError(f"case file {str(path)!r} not found") from None
    except tomllib.TOMLDecodeError as err:
        raise CaseError(f"{path}: not valid TOML: {err}") from None
    return _from_tables(tables, overrides, path.parent.absolute(), path.stem, str(path))


def loads_case(text: str, overrides=None) -> Case:
    """Load a case from TOML text (relative paths: from the working directory)."""
    try:
        tables = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise CaseError(f"not valid TOML: {err}") from None
    return _from_tables(tables, overrides, Path.cwd(), None, None)


def resolve_domain(case: Case, les_box_m=None) -> Case:
    """The SPEC §9 domain rules: a Case with run.domain and run.n_particles fixed.

    ``les_box_m``: (Lx, Lz, h) of the LES box in m at the run's u* (h the half height),
    used when run.domain is absent; the analytic and still sources fall back on the
    paper's box. n_particles or concentration fills the domain (N = round(C V/(π/6 d³)));
    both given: the domain is scaled, aspect ratio kept, to hold N grains at C. The
    result has concentration absent (it is ``case.concentration``) and resolves to itself.
    """
    domain, n, _ = case._domain_solution(les_box_m)
    if domain is None:
        raise CaseError('run.domain is absent and no LES box was given: pass les_box_m '
                        '(Lx, Lz, h in m) or set run.domain = [Lx, Lz, H] (m)', "run", "domain")
    run = dataclasses.replace(case.run, domain=tuple(domain), n_particles=n,
                              concentration=None)
    return dataclasses.replace(case, run=run)


# --------------------------------------------------------------------------- writing


def _toml_string(s: str) -> str:
    out = []
    for ch in s:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch in "\b\t\n\f\r":
            out.append({"\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write {value!r} to a case file")
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):  # inline table (particle.fractions, particle.ratios)
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML form for {value!r}")


def _resolved_comment(case: Case, table: str, key: str) -> str | None:
    """What an absent or derived key resolves to, for the comment beside it."""
    if table == "flow" and key in ("tau_ratio", "shear_velocity"):
        return f"τ*/τ*c = {case.tau_ratio:.6g}, u* = {case.shear_velocity:.6g} m/s"
    if table == "run" and key in ("dt", "dt_particle"):
        return f"dt = {case.dt:.6g} s = {case.dt_particle:.6g} d/u*"
    if table == "bed" and key in ("restitution", "friction"):
        value = case.bed_restitution if key == "restitution" else case.bed_friction
        return f"{value:.6g} from {case.bed.coefficients}"
    if table == "collisions" and key == "stiffness":
        return f"{case.collision_stiffness:.6g} N/m"
    if table == "output" and key in ("tracks_interval", "vtk_interval"):
        return f"{getattr(case, key):.6g} s"
    if table == "output" and key == "variance_interval":
        return f"{case.variance_every * case.dt:.6g} s"
    return None


def dump_toml(case: Case) -> str:
    """The case as TOML: every key with the value in use, reloading to an equal Case.

    Keys left absent (derived or defaulted by a rule) are written as comments with the
    value they resolve to; a header lists the derived numbers.
    """
    lines = ["# saltation case: every value in use (units: SI unless noted).", "# derived:"]
    for name, value in case.derived().items():
        if isinstance(value, float):
            value = f"{value:.6g}"
        elif isinstance(value, list):
            value = "[" + ", ".join(f"{v:.6g}" for v in value) + "]"
        lines.append(f"#   {name} = {value}")
    for name, cls in TABLES.items():
        table = getattr(case, name)
        lines += ["", f"[{name}]"]
        for f in dataclasses.fields(cls):
            value = getattr(table, f.name)
            resolved = _resolved_comment(case, name, f.name)
            note = f"{resolved}; " if resolved else ""
            if value is None:
                lines.append(f"# {f.name} (absent): {note}{f.metadata['doc']}")
            else:
                lines.append(f"{f.name} = {_toml_value(value)}  # {note}{f.metadata['doc']}")
    return "\n".join(lines) + "\n"
