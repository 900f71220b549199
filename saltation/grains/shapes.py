"""Irregular grains as rigidly bonded spheres (SPEC §8, seed 000 §2.4 and appendix).

Two constructions, ``build(Dl, Di, Ds, method=...)``:

* ``"seed"`` (the default): the seed paper's (seed 000, §2.4 and appendix), below;
* ``"fitted"``: the same layout per class, its spheres sized and placed per grain so
  that the volume and the moments of inertia match the ellipsoid with the same axes
  (*Fitted construction*, at the end of this text).

A grain is described by its long, intermediate and short axes Dl ≥ Di ≥ Ds and built
from as few component spheres as the paper allows, in the **geometric body frame**:
x along the long axis, y along the intermediate axis, z along the short axis, origin at
the centre of mass.

Zingg (1935) classes, p = Di/Dl, q = Ds/Di, threshold 2/3 (paper Fig. 2):

=========  ================  ================  =========================================
class      p = Di/Dl         q = Ds/Di         component spheres
=========  ================  ================  =========================================
disk       ≥ 2/3             < 2/3             d = Ds, hexagonal lattice [Dl/d] × [Di/d]
blade      < 2/3             < 2/3             same as disk
rod        < 2/3             ≥ 2/3             d = √(Ds Di), [Dl/d] in a row along x
equant     ≥ 2/3             ≥ 2/3             main sphere + 0–3 auxiliary (appendix)
=========  ================  ================  =========================================

[·] rounds to the nearest integer (at least 1). On the boundary p = 2/3 or q = 2/3 the
grain goes to the class with the larger ratio (the thresholds are closed above).

Disk/blade lattice: ni = [Di/d] rows parallel to x, spaced d·√3/2 in y (close packing),
holding alternately nl = [Dl/d] and nl − 1 touching spheres (the shorter rows shifted
by d/2 in x, so every row fits in the length nl·d of the first; nl = 1: single file). All
centres lie in z = 0 (the spheres' diameter is the short axis).

Equant sub-types (appendix, ε = 0.1):

1. Ds ≈ Di ≈ Dl ((1-ε)Dl < Di and (1-ε)Di < Ds): one sphere d = (Dl Di Ds)^{1/3}.
2. Ds ≈ Di < Dl: main d_m = √(Ds Di) and one auxiliary d_a = Dl − d_m, touching on the
   x axis (overall length d_m + d_a = Dl).
3. Ds < Di ≈ Dl: main d_m = Ds and two auxiliary d_a = Dl − Ds touching it at centre
   distance Dl/2, in the x–y plane at ±θe/2 about +x with θe = 2 asin((Di+Ds−Dl)/Dl);
   this makes the extent along y exactly Di (2·(Dl/2)·sin(θe/2) + d_a = Di).
4. Ds < Di < Dl: main d_m = Ds, three auxiliary d_a = (Dl − Ds)/2: two touching it on
   ±x (overall length Ds + 2 d_a = Dl), the third touching it in the x–y plane at angle
   θe = 2 asin((2Di+Ds−Dl)/(Dl+Ds)) from the first.

The appendix gives ratios only up to the equality cases; where Di ≈ Dl holds with
Ds ≈ Di failing *and* the paper's text is ambiguous we follow the list above.

Mass properties
---------------
Component spheres of the seed construction touch but never overlap (checked), so volume, centre of
mass and inertia tensor are **exact** sums of sphere terms with the parallel-axis
theorem (I_sphere = m d²/10). For user-given sphere sets (:meth:`Composite.from_spheres`)
that overlap, the union is integrated on a voxel grid (midpoint rule, spacing
h = min(d)/``VOXEL_PER_DIAMETER``); the relative error of the volume is ≲ 0.5 % at the
default 48 voxels per smallest diameter (tests compare a two-sphere lens with the exact
formula), and the mass properties are those of the union, not the sum. The fitted
construction's spheres overlap; their centres share the plane z = 0, so the union is
integrated exactly in z and on a fine grid in x, y instead (see below); ``exact`` is then
False.

Fitted construction
-------------------
The a priori test (benchmarks/shapes_apriori.py; seed 000 §3, 100 grains) finds the
seed equants of sub-types 2–4 15–56 % lighter than the same-axes ellipsoid (mass ratio
0.75–0.85, 0.63–0.71, 0.44–0.66), and moments off by up to a factor 2.5 (a rectangular lattice carries its mass further out than an
ellipse; the rounding of [Dl/d] makes rows short or long). ``method="fitted"`` keeps the
seed layout of the grain — the same number of spheres, the same pairs touching, all
centres in the plane z = 0, the same mirror symmetries — and changes a few numbers p:

* disk, blade, rod: centres (x_k, y_k) → (s_x x_k, s_y y_k) about the centre of the
  layout, radii r_k → g r_k (1 − t e_k²), e_k² = (x_k/x_max)² + (y_k/y_max)² normalised to
  max_k e_k² = 1 (t > 0 makes the outer spheres smaller, as the ellipsoid thins to its rim);
  p = (s_x, s_y, g, t), without s_y for a rod (one row);
* equant: the auxiliary spheres' centres scaled by (s_x, s_y) about the main sphere,
  main radius × g_m, auxiliary radii × g_a; p = (s_x, s_y, g_m, g_a) (sub-type 2: no s_y;
  sub-type 1 is one sphere of the ellipsoid's volume and stays as it is).

p minimises the sum of squares of the relative errors against the ellipsoid of the same
axes (m_e = ρ π Dl Di Ds/6, I_e,x = m_e (b² + c²)/5, …; :func:`ellipsoid_properties`)

    F(p) = (V/V_e − 1)² + Σ_{j = x, y, z} (I_jj/I_e,j − 1)² + (I_xy/√(I_e,x I_e,y))²

(I_xy only differs from 0 for equant sub-type 4, whose third auxiliary sphere breaks the
mirror symmetry: the term keeps the body axes principal), subject to

* every pair that touches in the seed layout overlaps or touches: |c_i − c_j| ≤ r_i + r_j
  (the grain stays one connected body); radii ≥ 0.06 of the seed's (bounds on g, t);
* the extent along each body axis E_j ≤ max((1 + τ) D_j, E_j^seed) — within the box
  Dl × Di × Ds enlarged by τ, or no wider than the seed grain where that is already wider
  (rods and equant sub-type 2, whose circular sections have diameter √(Di Ds) > Ds).

τ is tried as 0, 0.1, 0.2, 0.3 in turn (``FIT_BOX_TOLS``; each fit starting from the
previous one, the first from the seed layout) and the first fit reaching |V/V_e − 1| ≤ 5 %
and every |I_jj/I_e,j − 1| ≤ 10 % (``FIT_GOAL``) is kept, else the one with the smallest F:
a grain leaves its box only as far as the fixed number of spheres requires it (a disk of
3 spheres of diameter Ds cannot hold the ellipsoid's volume inside the box). The
minimiser is SLSQP (scipy) on ≤ 4 parameters; V and I of the overlapping union are
integrated exactly in z and by the midpoint rule in x, y (:func:`_planar_properties`,
``FIT_PER_RADIUS`` = 10 points per smallest radius in the fit, relative error ~2·10⁻³;
``PLANAR_PER_RADIUS`` = 60 for the grain's mass properties, ~10⁻⁴ against the voxel
integral). Nothing is fitted to anything but the grain's own ellipsoid. Fits are cached
per axes (:func:`fit_record` tells what a fit did); 100 grains take ~6 s of CPU.

Units: whatever length unit the axes are given in (m in the code base); volume in that
unit³; ``inertia_tensor(density)`` in density·unit⁵ (kg m² for kg/m³ and m).
"""
from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass, field

import numpy as np

CLASSES = ("disk", "blade", "rod", "equant")
ZINGG_THRESHOLD = 2.0 / 3.0
EQUANT_EPS = 0.1
# Smith (2003), calcareous beach sand of Oahu (Smith & Cheung 2003): class fractions
SMITH_2003 = {"disk": 0.43, "blade": 0.09, "rod": 0.14, "equant": 0.34}
# default axis-ratio ranges per class, uniform draws of (p = Di/Dl, q = Ds/Di); the
# lower bound 0.3 covers the scatter of the paper's Fig. 4 and keeps disks to ≤ 17
# component spheres
MIN_RATIO = 0.3
DEFAULT_RATIOS = {
    "disk": ((ZINGG_THRESHOLD, 1.0), (MIN_RATIO, ZINGG_THRESHOLD)),
    "blade": ((MIN_RATIO, ZINGG_THRESHOLD), (MIN_RATIO, ZINGG_THRESHOLD)),
    "rod": ((MIN_RATIO, ZINGG_THRESHOLD), (ZINGG_THRESHOLD, 1.0)),
    "equant": ((ZINGG_THRESHOLD, 1.0), (ZINGG_THRESHOLD, 1.0)),
}
VOXEL_PER_DIAMETER = 48
METHODS = ("seed", "fitted")  # construction of build(..., method=...)
# fitted construction (module text): quadrature points per smallest radius in the fit and
# for the final mass properties; weight of the constraint residuals
FIT_PER_RADIUS = 10
PLANAR_PER_RADIUS = 60
FIT_PENALTY = 100.0
# box tolerances tried in turn (continuation): the fitted grain's extent along each axis
# is at most max((1 + τ) D, the seed grain's extent); the first τ whose fit reaches the
# goal (|mass error| ≤ 5 %, each moment ≤ 10 %) is kept, else the best of them
FIT_BOX_TOLS = (0.0, 0.1, 0.2, 0.3)
FIT_GOAL = (0.05, 0.10)
_TOUCH_TOL = 1e-9


def zingg_class(Dl: float, Di: float, Ds: float) -> str:
    """'disk' | 'blade' | 'rod' | 'equant' from the axes (checked: Dl ≥ Di ≥ Ds > 0)."""
    _check_axes(Dl, Di, Ds)
    p = Di / Dl
    q = Ds / Di
    if p >= ZINGG_THRESHOLD:
        return "equant" if q >= ZINGG_THRESHOLD else "disk"
    return "rod" if q >= ZINGG_THRESHOLD else "blade"


def _check_axes(Dl, Di, Ds):
    for name, v in (("Dl", Dl), ("Di", Di), ("Ds", Ds)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
            raise ValueError(f"axis {name} must be a number, got {v!r}")
        if not math.isfinite(v) or not v > 0:
            raise ValueError(f"axis {name} = {v!r} must be a positive finite length")
    if not (Dl >= Di >= Ds):
        raise ValueError(f"axes must be ordered Dl >= Di >= Ds, got Dl = {Dl!r}, Di = {Di!r}, "
                         f"Ds = {Ds!r}")


def _nint(x: float) -> int:
    # nearest integer, halves up, at least 1
    return max(1, int(math.floor(x + 0.5)))


# --------------------------------------------------------------------- mass properties
def _sum_properties(centres, radii):
    """Exact volume, centroid and second-moment tensor (about the centroid, per unit
    density) of non-overlapping spheres."""
    vol_k = 4.0 / 3.0 * math.pi * radii**3
    vol = float(vol_k.sum())
    com = (vol_k[:, None] * centres).sum(axis=0) / vol
    r = centres - com
    inertia = np.zeros((3, 3))
    for v, rk, a in zip(vol_k, r, radii):
        inertia += v * (0.4 * a * a * np.eye(3) + (rk @ rk) * np.eye(3) - np.outer(rk, rk))
    return vol, com, inertia


def _voxel_properties(centres, radii, per_diameter=VOXEL_PER_DIAMETER):
    """Volume, centroid and inertia (per unit density) of the union of spheres by
    midpoint voxel integration, spacing h = 2 min(r)/per_diameter."""
    h = 2.0 * radii.min() / per_diameter
    lo = (centres - radii[:, None]).min(axis=0)
    hi = (centres + radii[:, None]).max(axis=0)
    n = np.ceil((hi - lo) / h).astype(int)
    axes = [lo[i] + h * (np.arange(n[i]) + 0.5) for i in range(3)]
    vol = 0.0
    m1 = np.zeros(3)
    m2 = np.zeros((3, 3))
    yy, zz = np.meshgrid(axes[1], axes[2], indexing="ij")
    for x in axes[0]:  # slab by slab keeps memory small
        inside = np.zeros(yy.shape, dtype=bool)
        for c, a in zip(centres, radii):
            dx2 = (x - c[0]) ** 2
            if dx2 > a * a:
                continue
            inside |= (yy - c[1]) ** 2 + (zz - c[2]) ** 2 <= a * a - dx2
        k = int(inside.sum())
        if k == 0:
            continue
        p = np.column_stack([np.full(k, x), yy[inside], zz[inside]])
        vol += k
        m1 += p.sum(axis=0)
        m2 += p.T @ p
    dv = h**3
    vol *= dv
    com = m1 * dv / vol
    second = m2 * dv - vol * np.outer(com, com)  # ∫ r r^T about the centroid
    inertia = np.trace(second) * np.eye(3) - second
    return vol, com, inertia


def _overlapping(centres, radii) -> bool:
    n = len(radii)
    for i in range(n):
        for j in range(i + 1, n):
            if np.linalg.norm(centres[i] - centres[j]) < (radii[i] + radii[j]) * (1.0 - _TOUCH_TOL):
                return True
    return False


@dataclass(frozen=True)
class Composite:
    """A rigid cluster of spheres in its body frame, centred on its centre of mass.

    centres (n, 3) and radii (n,) in the axes' length unit; ``volume`` of the union;
    ``second_moment`` (3, 3): the inertia tensor per unit density about the centre of
    mass, ∫(|r|² I − r rᵀ) dV; ``exact``: False when the union was voxel-integrated.
    """

    zingg_class: str
    subtype: int  # equant sub-type 1-4 (0 for the other classes)
    axes: tuple  # (Dl, Di, Ds) as given
    centres: np.ndarray
    radii: np.ndarray
    volume: float
    second_moment: np.ndarray
    exact: bool = True
    _principal: tuple = field(default=None, repr=False, compare=False)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_spheres(cls, centres, radii, zingg="custom", subtype=0, axes=None):
        """Composite of arbitrary spheres (body frame): shifted to the centre of mass
        of their union (overlaps integrated on a voxel grid, see the module text)."""
        c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
        r = np.atleast_1d(np.asarray(radii, dtype=np.float64))
        if c.shape != (len(r), 3) or len(r) == 0:
            raise ValueError(f"centres must be (n, 3) and radii (n,), got {c.shape} and {r.shape}")
        if not np.all(np.isfinite(c)) or not np.all(r > 0):
            raise ValueError(f"radii must be positive and centres finite, got radii {r.tolist()}")
        overlap = _overlapping(c, r)
        vol, com, inertia = (_voxel_properties if overlap else _sum_properties)(c, r)
        return cls(zingg, subtype, tuple(axes) if axes is not None else (), c - com, r, vol,
                   inertia, not overlap)

    # ------------------------------------------------------------------ properties
    @property
    def n_spheres(self) -> int:
        return len(self.radii)

    @property
    def diameters(self) -> np.ndarray:
        return 2.0 * self.radii

    @property
    def nominal_diameter(self) -> float:
        """Dn = (Dl Di Ds)^{1/3} (paper §4.1); for custom clusters the volume-equivalent
        diameter."""
        if self.axes:
            Dl, Di, Ds = self.axes
            return (Dl * Di * Ds) ** (1.0 / 3.0)
        return self.volume_equivalent_diameter

    @property
    def volume_equivalent_diameter(self) -> float:
        return (6.0 * self.volume / math.pi) ** (1.0 / 3.0)

    def mass(self, density: float) -> float:
        return density * self.volume

    def inertia_tensor(self, density: float) -> np.ndarray:
        """Inertia tensor about the centre of mass, body frame (density × unit⁵)."""
        return density * self.second_moment

    def _eig(self):
        if self._principal is None:
            w, v = np.linalg.eigh(self.second_moment)
            if np.linalg.det(v) < 0:
                v[:, 2] *= -1.0
            object.__setattr__(self, "_principal", (w, v))
        return self._principal

    def principal_moments(self, density: float) -> np.ndarray:
        """Principal moments (ascending) about the centre of mass."""
        return density * self._eig()[0]

    @property
    def principal_axes(self) -> np.ndarray:
        """Columns: unit principal axes in the body frame (right-handed)."""
        return self._eig()[1].copy()

    def extent(self) -> np.ndarray:
        """Extent of the cluster along the body x, y, z axes."""
        lo = (self.centres - self.radii[:, None]).min(axis=0)
        hi = (self.centres + self.radii[:, None]).max(axis=0)
        return hi - lo

    def scaled(self, factor: float) -> Composite:
        """The same cluster scaled by ``factor`` (lengths)."""
        f = float(factor)
        return Composite(self.zingg_class, self.subtype, tuple(a * f for a in self.axes),
                         self.centres * f, self.radii * f, self.volume * f**3,
                         self.second_moment * f**5, self.exact)

    def surface_area(self, samples: int = 20000, seed: int = 0) -> float:
        """Exposed surface of the union (Monte Carlo on each sphere's surface;
        exact for non-overlapping clusters, whose spheres only touch)."""
        area_k = 4.0 * math.pi * self.radii**2
        if self.exact:
            return float(area_k.sum())
        rng = np.random.default_rng(seed)
        total = 0.0
        for k, (c, a) in enumerate(zip(self.centres, self.radii)):
            u = rng.normal(size=(samples, 3))
            p = c + a * u / np.linalg.norm(u, axis=1)[:, None]
            covered = np.zeros(samples, dtype=bool)
            for j, (cj, aj) in enumerate(zip(self.centres, self.radii)):
                if j != k:
                    covered |= ((p - cj) ** 2).sum(axis=1) < aj * aj
            total += area_k[k] * (1.0 - covered.mean())
        return total


# --------------------------------------------------------------------- construction
def _lattice(Dl, Di, d):
    """Hexagonal close-packed layer: [Di/d] rows along x (spacing d√3/2), each of
    [Dl/d] touching spheres, odd rows shifted by d/2."""
    nl = _nint(Dl / d)
    ni = _nint(Di / d)
    pts = []
    for j in range(ni):
        odd = j % 2 == 1 and nl > 1
        for i in range(nl - 1 if odd else nl):
            pts.append((i * d + (0.5 * d if odd else 0.0), j * d * math.sqrt(3.0) / 2.0, 0.0))
    return np.array(pts), np.full(len(pts), 0.5 * d)


def _rod(Dl, Di, Ds):
    d = math.sqrt(Ds * Di)
    nl = _nint(Dl / d)
    return np.array([(i * d, 0.0, 0.0) for i in range(nl)]), np.full(nl, 0.5 * d)


def equant_subtype(Dl, Di, Ds, eps=EQUANT_EPS) -> int:
    """Appendix sub-type 1-4 of an equant grain (axes assumed equant)."""
    long_eq = Di > (1.0 - eps) * Dl   # Di ≈ Dl
    short_eq = Ds > (1.0 - eps) * Di  # Ds ≈ Di
    if long_eq and short_eq:
        return 1
    if short_eq:
        return 2
    if long_eq:
        return 3
    return 4


def _equant(Dl, Di, Ds):
    sub = equant_subtype(Dl, Di, Ds)
    if sub == 1:
        d = (Dl * Di * Ds) ** (1.0 / 3.0)
        return sub, np.zeros((1, 3)), np.array([0.5 * d])
    if sub == 2:
        dm = math.sqrt(Ds * Di)
        da = Dl - dm
        return sub, np.array([(0.0, 0.0, 0.0), (0.5 * (dm + da), 0.0, 0.0)]), \
            np.array([0.5 * dm, 0.5 * da])
    if sub == 3:
        dm = Ds
        da = Dl - Ds
        half = math.asin(min(1.0, (Di + Ds - Dl) / Dl))  # θe/2
        rc = 0.5 * (dm + da)  # = Dl/2, touching
        c = [(0.0, 0.0, 0.0),
             (rc * math.cos(half), rc * math.sin(half), 0.0),
             (rc * math.cos(half), -rc * math.sin(half), 0.0)]
        return sub, np.array(c), np.array([0.5 * dm, 0.5 * da, 0.5 * da])
    dm = Ds
    da = 0.5 * (Dl - Ds)
    rc = 0.5 * (dm + da)
    theta = 2.0 * math.asin(min(1.0, (2.0 * Di + Ds - Dl) / (Dl + Ds)))
    c = [(0.0, 0.0, 0.0), (rc, 0.0, 0.0), (-rc, 0.0, 0.0),
         (rc * math.cos(theta), rc * math.sin(theta), 0.0)]
    return sub, np.array(c), np.array([0.5 * dm, da * 0.5, da * 0.5, da * 0.5])


def check_method(method) -> str:
    """The construction name if it is one of METHODS, else ValueError naming them."""
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"unknown construction method {method!r}: allowed "
                         f"{', '.join(repr(m) for m in METHODS)}")
    return method


def _seed_layout(Dl, Di, Ds):
    """(class, equant sub-type, centres, radii) of the seed construction."""
    cls = zingg_class(Dl, Di, Ds)
    sub = 0
    if cls in ("disk", "blade"):
        c, r = _lattice(Dl, Di, Ds)
    elif cls == "rod":
        c, r = _rod(Dl, Di, Ds)
    else:
        sub, c, r = _equant(Dl, Di, Ds)
    return cls, sub, c, r


def build(Dl: float, Di: float, Ds: float, method: str = "seed") -> Composite:
    """The bonded-sphere grain for axes Dl ≥ Di ≥ Ds > 0 (SPEC §9 entry point).

    ``method``: "seed" (default) — the seed paper's construction (module text);
    "fitted" — the same layout with sphere sizes and spacings fitted per grain to the
    volume and moments of the same-axes ellipsoid (module text, *Fitted construction*).

    Returns a :class:`Composite` with ``.zingg_class``, ``.centres`` (n, 3) about the
    centre of mass in the body frame (x long, y intermediate, z short), ``.radii``,
    ``.volume`` and ``.inertia_tensor(density)``. Raises ValueError naming the value for
    non-positive or unordered axes or an unknown method."""
    check_method(method)
    _check_axes(Dl, Di, Ds)
    Dl, Di, Ds = float(Dl), float(Di), float(Ds)
    if method == "fitted":
        return _fitted(Dl, Di, Ds)
    cls, sub, c, r = _seed_layout(Dl, Di, Ds)
    comp = Composite.from_spheres(c, r, zingg=cls, subtype=sub, axes=(Dl, Di, Ds))
    return comp


# --------------------------------------------------------------------- fitted construction
def _planar_properties(centres, radii, per_radius=PLANAR_PER_RADIUS, n=None):
    """Volume, centroid and inertia (per unit density) of the union of spheres whose
    centres all lie in the plane z = 0: exact in z (the union's section at (x, y) is
    |z| ≤ H = max_k √(r_k² − (x − x_k)² − (y − y_k)²)), midpoint rule in x and y with
    spacing ≈ min(r)/per_radius, or ``n`` = (nx, ny) cells on the bounding rectangle.
    H is continuous, so with a fixed ``n`` the result varies continuously with the
    centres and radii (what the fit needs)."""
    lo = (centres[:, :2] - radii[:, None]).min(axis=0)
    hi = (centres[:, :2] + radii[:, None]).max(axis=0)
    if n is None:
        n = np.maximum(1, np.ceil((hi - lo) / (radii.min() / per_radius)).astype(int))
    n = np.asarray(n)
    step = (hi - lo) / n
    x = lo[0] + step[0] * (np.arange(n[0]) + 0.5)
    y = lo[1] + step[1] * (np.arange(n[1]) + 0.5)
    h2 = np.full((n[0], n[1]), 0.0)
    for c, a in zip(centres, radii):
        # only the window of the grid under this sphere
        i0, i1 = np.searchsorted(x, [c[0] - a, c[0] + a])
        j0, j1 = np.searchsorted(y, [c[1] - a, c[1] + a])
        if i1 <= i0 or j1 <= j0:
            continue
        w = a * a - (x[i0:i1, None] - c[0]) ** 2 - (y[None, j0:j1] - c[1]) ** 2
        np.maximum(h2[i0:i1, j0:j1], w, out=h2[i0:i1, j0:j1])
    hz = np.sqrt(h2)
    da = step[0] * step[1]
    col = 2.0 * hz * da  # column volumes
    vol = float(col.sum())
    cx = col.sum(axis=1)
    cy = col.sum(axis=0)
    mx, my = float(cx @ x), float(cy @ y)
    sxx, syy = float(cx @ (x * x)), float(cy @ (y * y))
    sxy = float(x @ col @ y)
    szz = float((hz**3).sum() * da * 2.0 / 3.0)
    com = np.array([mx / vol, my / vol, 0.0])
    second = np.array([[sxx, sxy, 0.0], [sxy, syy, 0.0], [0.0, 0.0, szz]]) - vol * np.outer(com, com)
    inertia = np.trace(second) * np.eye(3) - second
    return vol, com, inertia


def _touching_pairs(centres, radii):
    n = len(radii)
    return [(i, j) for i in range(n) for j in range(i + 1, n)
            if np.linalg.norm(centres[i] - centres[j]) <= (radii[i] + radii[j]) * (1.0 + 1e-9)]


def _fit_model(cls, c0, r0):
    """Seed layout -> (names of the free parameters, their bounds, spheres(p)). The
    layout (number of spheres, who touches whom, symmetry) is the seed's; p scales the
    centre coordinates along x and y and the radii (module text)."""
    if cls == "equant":
        # main sphere at the origin, auxiliaries scaled about it; radii of the main
        # sphere and of the auxiliaries scaled separately
        ref = np.zeros(3)
        groups = np.array([0] + [1] * (len(r0) - 1))
        taper = np.zeros(len(r0))
    else:
        ref = 0.5 * (c0.min(axis=0) + c0.max(axis=0))
        groups = np.zeros(len(r0), dtype=int)
        rel = c0 - ref
        span = np.abs(rel).max(axis=0)
        e2 = sum((rel[:, k] / span[k]) ** 2 for k in (0, 1) if span[k] > 0)
        taper = e2 / e2.max() if e2.max() > 0 else np.zeros(len(r0))
    rel = c0 - ref
    bounds = []  # (parameter, lower, upper)
    if np.ptp(rel[:, 0]) > 0:
        bounds.append(("sx", 0.2, 3.0))
    if np.ptp(rel[:, 1]) > 0:
        bounds.append(("sy", 0.2, 3.0))
    for g in sorted(set(groups.tolist())):
        bounds.append((f"g{g}", 0.2, 5.0))
    if np.ptp(taper) > 0:
        bounds.append(("t", 0.0, 0.7))
    names = [b[0] for b in bounds]
    lo = [b[1] for b in bounds]
    hi = [b[2] for b in bounds]

    def spheres(p):
        v = dict(zip(names, p))
        c = rel * np.array([v.get("sx", 1.0), v.get("sy", 1.0), 1.0])
        g = np.array([v[f"g{k}"] for k in groups])
        r = r0 * g * (1.0 - v.get("t", 0.0) * taper)
        return c, r

    return names, (np.array(lo), np.array(hi)), spheres


def _extent(c, r):
    return (c + r[:, None]).max(axis=0) - (c - r[:, None]).min(axis=0)


@functools.lru_cache(maxsize=4096)
def _fitted_spheres(Dl, Di, Ds):
    """(class, sub-type, centres, radii, fit record) of the fitted construction (cached
    per axes; the arrays are copied by the caller)."""
    from scipy.optimize import minimize

    cls, sub, c0, r0 = _seed_layout(Dl, Di, Ds)
    names, bounds, spheres = _fit_model(cls, c0, r0)
    p0 = np.ones(len(names))
    if "t" in names:
        p0[names.index("t")] = 0.0
    m_e, i_e = ellipsoid_properties(Dl, Di, Ds)
    axes = np.array([Dl, Di, Ds])
    limit = _extent(c0, r0)  # set per box tolerance below
    bonds = _touching_pairs(c0, r0)
    bi = np.array([b[0] for b in bonds], dtype=int)
    bj = np.array([b[1] for b in bonds], dtype=int)
    scale_ij = math.sqrt(i_e[0] * i_e[1])

    grid = np.maximum(1, np.ceil(_extent(c0, r0)[:2] / (r0.min() / FIT_PER_RADIUS)).astype(int))

    def errors(c, r):
        """relative errors of volume and Ixx, Iyy, Izz; Ixy over √(Ix Iy) of the ellipsoid"""
        vol, _, inertia = _planar_properties(c, r, n=grid)
        return np.array([vol / m_e - 1.0, *(np.diag(inertia) / i_e - 1.0), inertia[0, 1] / scale_ij])

    def objective(p):
        return float((errors(*spheres(p)) ** 2).sum())

    def slack(p):  # ≥ 0: inside the limits, bonded pairs overlapping or touching
        c, r = spheres(p)
        out = [1.0 - _extent(c, r) / limit]
        if len(bonds):
            out.append(1.0 - np.linalg.norm(c[bi] - c[bj], axis=1) / (r[bi] + r[bj]))
        return np.concatenate(out)

    record = dict(parameters=names, seed_errors=errors(c0, r0).tolist())
    if not names or len(r0) == 1:  # one sphere (equant sub-type 1): kept, its volume is exact
        record.update(parameters=[], values=[], box_tol=0.0, errors=record["seed_errors"], success=True)
        return cls, sub, c0, r0, record
    best = None
    p = p0
    for tol in FIT_BOX_TOLS:
        limit[:] = np.maximum(axes * (1.0 + tol), _extent(c0, r0))
        sol = minimize(objective, p, method="SLSQP", bounds=list(zip(*bounds)),
                       constraints=[dict(type="ineq", fun=slack)],
                       options=dict(maxiter=200, ftol=1e-10, eps=1e-7))
        p = sol.x
        # hard feasibility: close what the solver's tolerance left apart or outside
        c, r = spheres(p)
        if len(bonds):
            gap = (np.linalg.norm(c[bi] - c[bj], axis=1) / (r[bi] + r[bj])).max()
            if gap > 1.0:
                c = c / gap
        over = (_extent(c, r) / limit).max()
        if over > 1.0:
            c, r = c / over, r / over
        err = errors(c, r)
        cost = float((err**2).sum())
        if best is None or cost < best[0]:
            best = (cost, c, r, dict(values=p.tolist(), box_tol=tol, errors=err.tolist(),
                                     success=bool(sol.success)))
        if abs(err[0]) <= FIT_GOAL[0] and np.abs(err[1:4]).max() <= FIT_GOAL[1]:
            break
    _, c, r, rec = best
    record.update(rec)
    return cls, sub, c, r, record


def fit_record(Dl: float, Di: float, Ds: float) -> dict:
    """What the fitted construction did for these axes: the free ``parameters`` and
    their ``values`` (scale factors, see the module text), the box tolerance ``box_tol``
    τ it settled on, the relative ``errors`` (volume, Ixx, Iyy, Izz, Ixy/√(Ix Iy)) against
    the ellipsoid at the fit's quadrature, the ``seed_errors`` of the seed layout and the
    solver's ``success``."""
    _check_axes(Dl, Di, Ds)
    return copy.deepcopy(_fitted_spheres(float(Dl), float(Di), float(Ds))[4])


def _fitted(Dl, Di, Ds) -> Composite:
    cls, sub, c, r, _ = _fitted_spheres(Dl, Di, Ds)
    c = np.array(c, dtype=np.float64)
    r = np.array(r, dtype=np.float64)
    if not _overlapping(c, r):
        return Composite.from_spheres(c, r, zingg=cls, subtype=sub, axes=(Dl, Di, Ds))
    vol, com, inertia = _planar_properties(c, r)
    return Composite(cls, sub, (Dl, Di, Ds), c - com, r, vol, inertia, False)


# --------------------------------------------------------------------- reference shapes
def ellipsoid_properties(Dl, Di, Ds, density=1.0):
    """Mass and principal moments (about x=long, y, z) of the solid ellipsoid with
    full axes Dl, Di, Ds: m = ρ π Dl Di Ds/6, I_x = m (b² + c²)/5 with semi-axes."""
    a, b, c = 0.5 * Dl, 0.5 * Di, 0.5 * Ds
    m = density * math.pi / 6.0 * Dl * Di * Ds
    return m, np.array([m * (b * b + c * c) / 5, m * (a * a + c * c) / 5, m * (a * a + b * b) / 5])


def cylinder_properties(Dl, Di, Ds, density=1.0):
    """Mass and principal moments of the elliptic cylinder of length Dl (along x) and
    elliptic section with full axes Di, Ds: m = ρ π Di Ds Dl/4,
    I_x = m (b² + c²)/4, I_y = m (c²/4 + Dl²/12), I_z = m (b²/4 + Dl²/12)."""
    b, c = 0.5 * Di, 0.5 * Ds
    m = density * math.pi * b * c * Dl
    return m, np.array([m * (b * b + c * c) / 4, m * (c * c / 4 + Dl * Dl / 12),
                        m * (b * b / 4 + Dl * Dl / 12)])


def sphericity_ellipsoid(Dl, Di, Ds):
    """Wadell sphericity ψ = (area of the volume-equivalent sphere)/(area) of the
    ellipsoid with the same axes; area by the Knud Thomsen formula (p = 1.6075,
    ≤ 1.061 % error)."""
    a, b, c = 0.5 * Dl, 0.5 * Di, 0.5 * Ds
    p = 1.6075
    area = 4 * math.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3.0) ** (1.0 / p)
    dn = (Dl * Di * Ds) ** (1.0 / 3.0)
    return math.pi * dn * dn / area


# --------------------------------------------------------------------- mixtures
def check_fractions(fractions) -> dict:
    """Validate class fractions: known classes, each in [0, 1], summing to 1 (±1e-6)."""
    if not isinstance(fractions, dict) or not fractions:
        raise ValueError(f"fractions must be a mapping class -> fraction, got {fractions!r}")
    out = {}
    for k, v in fractions.items():
        if k not in CLASSES:
            raise ValueError(f"unknown Zingg class {k!r} in fractions: allowed {', '.join(CLASSES)}")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
            raise ValueError(f"fraction of {k} = {v!r} must be a number in [0, 1]")
        out[k] = float(v)
    total = sum(out.values())
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"class fractions must sum to 1, got {total:.6g} from {out}")
    return {k: out.get(k, 0.0) for k in CLASSES}


def _check_ratios(ratios):
    full = {k: tuple(tuple(map(float, r)) for r in v) for k, v in DEFAULT_RATIOS.items()}
    for k, v in (ratios or {}).items():
        if k not in CLASSES:
            raise ValueError(f"unknown Zingg class {k!r} in axis ratios: allowed {', '.join(CLASSES)}")
        try:
            (p0, p1), (q0, q1) = v
        except (TypeError, ValueError):
            raise ValueError(f"axis ratios of {k} must be ((Di/Dl lo, hi), (Ds/Di lo, hi)), got {v!r}") from None
        dp, dq = DEFAULT_RATIOS[k]
        plo = 0.0 if dp[0] == MIN_RATIO else dp[0]
        qlo = 0.0 if dq[0] == MIN_RATIO else dq[0]
        for name, lo, hi, a, b in (("Di/Dl", p0, p1, plo, dp[1]), ("Ds/Di", q0, q1, qlo, dq[1])):
            if not (a <= lo <= hi <= b) or not lo > 0:
                raise ValueError(f"{k} {name} range ({lo}, {hi}) must lie within the class's "
                                 f"({a:.4g}, {b:.4g}] and be positive")
        full[k] = ((float(p0), float(p1)), (float(q0), float(q1)))
    return full


def draw_axes(n, *, fractions=None, ratios=None, Dl_range=None, Dn=None, seed=0):
    """Axes of n grains of a natural mixture: classes drawn with ``fractions`` (default
    Smith 2003), (Di/Dl, Ds/Di) uniform in the class's ``ratios`` range (default
    DEFAULT_RATIOS), size either Dl uniform in ``Dl_range`` or a fixed nominal diameter
    ``Dn`` = (Dl Di Ds)^{1/3}. Returns (classes, axes (n, 3)). Seeded (PCG64)."""
    fr = check_fractions(SMITH_2003 if fractions is None else fractions)
    rt = _check_ratios(ratios)
    if (Dl_range is None) == (Dn is None):
        raise ValueError("give exactly one of Dl_range=(lo, hi) or Dn")
    rng = np.random.default_rng(seed)
    names = np.array(CLASSES)
    cls = names[rng.choice(len(CLASSES), size=n, p=[fr[c] for c in CLASSES])]
    axes = np.zeros((n, 3))
    for i, c in enumerate(cls):
        (p0, p1), (q0, q1) = rt[c]
        p = rng.uniform(p0, p1)
        q = rng.uniform(q0, q1)
        # keep the drawn class on a closed upper threshold: p, q < 2/3 stay below it
        if Dn is not None:
            dl = Dn / (p * p * q) ** (1.0 / 3.0)
        else:
            dl = rng.uniform(*Dl_range)
        axes[i] = (dl, p * dl, q * p * dl)
    return [str(c) for c in cls], axes


def mixture(n, *, fractions=None, ratios=None, Dl_range=None, Dn=None, seed=0, method="seed"):
    """n composites of a natural mixture (see :func:`draw_axes`), built with ``method``
    ("seed" | "fitted", see :func:`build`)."""
    check_method(method)
    _, axes = draw_axes(n, fractions=fractions, ratios=ratios, Dl_range=Dl_range, Dn=Dn, seed=seed)
    return [build(*a, method=method) for a in axes]
