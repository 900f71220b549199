"""Settling of bonded-sphere grains in still water (seed 000 §4.1) and the references.

``terminal_velocity(composite, ...)`` drops one composite grain from rest in quiescent
fluid (flow source "still": every force of flight/composites.py on, the lift and fluid
acceleration vanish) and integrates until the vertical velocity has settled; it returns
the terminal velocity (m/s) and the orientation history.

References:

* Haider & Levenspiel (1989), Powder Technol. 58:63, their eq. (10) for isometric and
  non-spherical particles of sphericity ψ, Re = w d_v/ν with d_v the volume-equivalent
  diameter:
      C_D = 24/Re (1 + A Re^B) + C/(1 + D/Re),
      A = exp(2.3288 − 6.4581ψ + 2.4486ψ²),  B = 0.0964 + 0.5565ψ,
      C = exp(4.905 − 13.8944ψ + 18.4222ψ² − 10.2599ψ³),
      D = exp(1.4681 + 12.2584ψ − 20.7322ψ² + 15.8855ψ³);
  terminal velocity from the force balance w² = (4/3) g R d_v / C_D (solved by
  bisection). Here d_v = Dn = (Dl Di Ds)^{1/3} and ψ is the sphericity of the
  **ellipsoid with the grain's axes** (the natural grain the composite stands for;
  ``shapes.sphericity_ellipsoid``) — the composite's own sphericity is reported too.
* the sphere of the same volume as the composite, with the drag law of the sphere
  model (Yen 1992), by the same force balance.

Non-dimensional numbers of the paper's eqs. (9)-(10): w* = w (ρ²/(g μ (ρs − ρ)))^{1/3},
d* = Dn (g ρ (ρs − ρ)/μ²)^{1/3}.
"""
from __future__ import annotations

import math

import numpy as np

from ..bed.virtual import bed_parameters
from ..case.schema import GRAVITY

RHO_F = 1000.0
NU = 1.0e-6


def haider_levenspiel_cd(re, psi):
    a = math.exp(2.3288 - 6.4581 * psi + 2.4486 * psi**2)
    b = 0.0964 + 0.5565 * psi
    c = math.exp(4.905 - 13.8944 * psi + 18.4222 * psi**2 - 10.2599 * psi**3)
    d = math.exp(1.4681 + 12.2584 * psi - 20.7322 * psi**2 + 15.8855 * psi**3)
    return 24.0 / re * (1.0 + a * re**b) + c / (1.0 + d / re)


def yen_cd(re):
    s = math.sqrt(re)
    return 24.0 / re * (1.0 + 0.15 * s + 0.017 * re) - 0.208 / (1.0 + 1.0e4 / s)


def _terminal(cd, d, R, nu=NU, g=GRAVITY):
    # w² C_D(w d/ν) = (4/3) g R d, bisection on w (m/s)
    lo, hi = 1e-9, 10.0
    target = 4.0 / 3.0 * g * R * d
    for _ in range(200):
        w = 0.5 * (lo + hi)
        if w * w * cd(w * d / nu) < target:
            lo = w
        else:
            hi = w
    return 0.5 * (lo + hi)


def terminal_haider_levenspiel(dv, psi, R=1.65, nu=NU):
    """Terminal velocity (m/s) of a grain of volume-equivalent diameter dv (m)."""
    return _terminal(lambda re: haider_levenspiel_cd(re, psi), dv, R, nu)


def terminal_sphere_yen(d, R=1.65, nu=NU):
    """Terminal velocity (m/s) of a sphere of diameter d (m) with Yen's C_D."""
    return _terminal(yen_cd, d, R, nu)


def dimensionless(w, dn, R=1.65, nu=NU, g=GRAVITY):
    """(w*, d*) of the paper's eqs. (9)-(10)."""
    return w * (1.0 / (g * nu * R)) ** (1.0 / 3.0), dn * (g * R / nu**2) ** (1.0 / 3.0)


def terminal_velocity(composite, *, density=2650.0, nu=NU, quat=(1.0, 0.0, 0.0, 0.0),
                      duration=80.0, dt=0.01, basset=True, n_window=10, wake_shielding=True):
    """Drop ``composite`` (shapes.Composite, lengths in m) from rest in still water.

    Particle units: length Dn, velocity √(g R Dn) (config's "still" rule: τ* = 1,
    Re* = Rp). Returns dict(w_m_s, w_particle, t, vy, tilt) where ``tilt`` is
    |cos| of the angle between the body z axis (short axis) and the vertical, sampled
    over the run, ``long_axis`` the same for the body x axis (long axis; 0 = horizontal),
    and w is the mean −v_y over the last 10 % of the run. The largest projection is
    across the fall when tilt → 1 (disks, blades) or long_axis → 0 (rods)."""
    from flowfields import profile_dataset

    from ..flight import composites as clusters
    from ..physics import history
    from ..physics.forces import CM, make_coefficients

    R = density / RHO_F - 1.0
    dn = composite.nominal_diameter
    rp = math.sqrt(GRAVITY * R * dn**3) / nu
    coef = make_coefficients(tau_star=1.0, R=R, re_star=rp, lift=False, basset=basset)
    flow = profile_dataset("still", y_top_plus=1e7 * rp)
    g = composite.scaled(1.0 / dn)
    n_steps = int(round(duration / dt))
    start = 10.0 * duration  # far above the bed: it never lands
    st = clusters.make_cluster_state([g], [[0.0, start, 0.0]], [[0.0, 0.0, 0.0]], [quat],
                                     [[0.0, 0.0, 0.0]], 0.0, n_window, R=R, Cm=coef[CM], re_star=rp,
                                     wake_shielding=wake_shielding)
    w = clusters.make_cluster_work(st)
    hc = history.make_history_coefficients(dt, n_window)
    chunk = max(1, n_steps // 200)
    ts, vy, tilt, long_axis = [], [], [], []
    done = 0
    bed = bed_parameters(0.65, 0.1, math.radians(30.0))
    while done < n_steps:
        k = min(chunk, n_steps - done)
        clusters.advance_clusters(flow.arrays, coef, bed, 0, st, w, hc, done * dt, dt, k, 1e30)
        done += k
        rot = clusters.quat_to_matrix_py(st.quat[0])
        ts.append(done * dt)
        vy.append(st.vel[0, 1])
        tilt.append(abs(rot[1, 2]))
        long_axis.append(abs(rot[1, 0]))
    vy = np.array(vy)
    tail = vy[int(0.9 * len(vy)):]
    wp = float(-tail.mean())
    scale = math.sqrt(GRAVITY * R * dn)
    return dict(w_m_s=wp * scale, w_particle=wp, steady=float(np.ptp(tail) / max(wp, 1e-30)),
                t=np.array(ts), vy=vy, tilt=np.array(tilt), long_axis=np.array(long_axis), omega_end=st.omega[0].copy())
