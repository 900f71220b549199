"""The fluid's response to a contact within the step it happened in (the operator split of
contacts/phase.py, second order).

The contact phase moves a grain as a deviation (δx, δu) from its free-flight path with
the fluid force *held* at what the free flight gave it: after a contact the grain flies
on to the step's end with the drag of its old velocity. Over the rest of the step the
drag of its new velocity would have acted instead, which the split leaves out: an error
of (∂a/∂u) δu τ per contact, τ the time from the contact to the step's end — first order
in Δt. At C = 2.07 % (benchmarks/study_dt.py, contacts on, weight and drag only) it made
the mean jump height 6.6 ± 2.0 % higher at Δt = 0.02 d/u* than at 0.005: a grain leaving
the bed kept the upward drag of its descent for the rest of the step.

After the phase, for each grain with a contact (``ph.deviation``):

* the time since the contact, τ = (δx · δu)/|δu|² (clamped to [0, Δt]): exact for one
  impulsive contact, where δx = δu τ; a weighted mean time for several;
* the drag's response, Δa τ with Δa = a(u₁ + δu) − a(u₁) (weight and drag at the grain's
  new and free-flight velocities against the fluid sampled at its free-flight end, the
  secant of the drag law: exact for one impulsive contact up to the fluid's change along
  the path), added to its velocity. Its position would move by ½ Δa τ², ≤ 3·10⁻⁴ d at
  Δt = 0.02 d/u*: left alone, so that no grain is pushed into a neighbour;
* the Basset history (``forces.basset_impacts = "keep"``): the slip step δu dated τ before
  the step's end (physics/history.py, ``history_mark_impact_at``), and its impulse over
  that time, −P δu · 2√τ, added to its velocity, as at a virtual-bed impact
  (flight/spheres.flight_remainder).

The other fluid forces (lift, added mass, fluid acceleration, Magnus) respond to δu too;
drag is by far the largest part of the response for sand in water and the only one
corrected here.
"""
from __future__ import annotations

import math

from numba import njit, prange

from ..physics.forces import BASSET_PREFACTOR, ON_BASSET, weight_and_drag
from ..physics.history import history_mark_impact_at

__all__ = ["fluid_response"]


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _respond(coef, keep, vel, uf, deviation, hist_meta, g, dt):
    dx0, dx1, dx2 = deviation[g, 0], deviation[g, 1], deviation[g, 2]
    du0, du1, du2 = deviation[g, 3], deviation[g, 4], deviation[g, 5]
    uu = du0 * du0 + du1 * du1 + du2 * du2
    if uu == 0.0:
        return
    tau = min(max((dx0 * du0 + dx1 * du1 + dx2 * du2) / uu, 0.0), dt)
    v0, v1, v2 = vel[g, 0], vel[g, 1], vel[g, 2]
    a0, a1, a2 = weight_and_drag(coef, v0 - du0, v1 - du1, v2 - du2, uf[g, 0], uf[g, 1], uf[g, 2])
    b0, b1, b2 = weight_and_drag(coef, v0, v1, v2, uf[g, 0], uf[g, 1], uf[g, 2])
    v0 += (b0 - a0) * tau
    v1 += (b1 - a1) * tau
    v2 += (b2 - a2) * tau
    if keep:
        kick = coef[BASSET_PREFACTOR] * 2.0 * math.sqrt(tau)
        v0 -= kick * du0
        v1 -= kick * du1
        v2 -= kick * du2
        history_mark_impact_at(hist_meta[g], tau / dt)
    vel[g, 0], vel[g, 1], vel[g, 2] = v0, v1, v2


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def fluid_response(coef, keep_impacts, vel, uf, deviation, hist_meta, fresh, act, n_act, dt):
    """The module docstring's corrections for the grains act[:n_act] (the sub-stepped ones)
    that had a contact: fresh[g] = 0 (the contact phase sets it for them; the free flight
    leaves every grain at 1). keep_impacts: the history keeps slip steps
    (physics/history.HistoryCoefficients)."""
    keep = keep_impacts and coef[ON_BASSET] != 0.0
    for k in prange(n_act):
        g = act[k]
        if fresh[g] == 0:
            _respond(coef, keep, vel, uf, deviation, hist_meta, g, dt)
