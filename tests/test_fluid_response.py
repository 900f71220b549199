"""The fluid's response to a contact inside its step (contacts/fluid_response.py): a grain
whose velocity a contact changed by δu at a time τ before the step's end gets the drag of
its new velocity over τ, which the contact phase's held fluid force leaves out, and the
Basset impulse of the slip step over τ, dated where it happened."""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from saltation.contacts.fluid_response import fluid_response
from saltation.physics.forces import BASSET_PREFACTOR, make_coefficients, weight_and_drag
from saltation.physics.history import AGE_TICKS, META_COUNT, META_PENDING, allocate_history_state

TAU_STAR, RE_STAR = 0.0573, 17.5  # quartz d = 0.69 mm in water, τ*/τ*c = 1.79


def _coef(basset):
    return make_coefficients(tau_star=TAU_STAR, re_star=RE_STAR, lift=False, magnus=False, added_mass=False,
                             fluid_acceleration=False, basset=basset, spin=False)


def _drag_flight(coef, u, uf, t):
    """du/dt = weight + drag from u over t, in still or uniform fluid (accurate ODE solve)."""
    rhs = lambda _t, v: np.array(weight_and_drag(coef, v[0], v[1], v[2], *uf))  # noqa: E731
    return solve_ivp(rhs, (0.0, t), u, rtol=1e-11, atol=1e-12).y[:, -1]


def _one_grain(coef, keep, u_contact, du, uf, tau, dt):
    """Grain 0 after a contact that changed its velocity by du at τ before the step's end:
    the contact phase leaves it with the free-flight end velocity plus du (and δx = du τ)."""
    u_free_end = _drag_flight(coef, u_contact, uf, tau)
    vel = (u_free_end + du)[None, :].copy()
    dev = np.concatenate([du * tau, du])[None, :]
    meta = allocate_history_state(1, 10).meta
    meta[0, META_COUNT] = -5  # the contact phase marked the slip step (history_mark_impact)
    fluid_response(coef, keep, vel, uf[None, :].copy(), dev, meta, np.zeros(1, np.int64), np.zeros(1, np.int64),
                   1, dt)
    return u_free_end, vel[0], meta[0]


def test_the_drag_of_the_new_velocity_acts_from_the_contact_on():
    coef = _coef(basset=False)
    uf = np.array([9.0, 0.0, 0.2])
    u_contact = np.array([7.5, -2.0, 0.1])  # descending onto the bed
    du = np.array([-1.0, 3.3, 0.4])  # the rebound
    dt, tau = 0.02, 0.013
    exact = _drag_flight(coef, u_contact + du, uf, tau)  # the grain's true velocity at the step's end
    held, got, _ = _one_grain(coef, False, u_contact, du, uf, tau, dt)
    held = held + du  # what the contact phase alone gives
    err_held = np.abs(held - exact).max()
    err_got = np.abs(got - exact).max()
    assert err_held > 0.03  # the split's first-order error: ~0.05 u* here
    assert err_got < 0.02 * err_held, (err_held, err_got)


def test_the_slip_step_is_dated_at_the_contact_with_its_impulse_since():
    coef = _coef(basset=True)
    uf = np.array([9.0, 0.0, 0.0])
    u_contact = np.array([7.5, -2.0, 0.0])
    du = np.array([-1.0, 3.3, 0.0])
    dt, tau = 0.02, 0.013
    _, without, _ = _one_grain(_coef(basset=False), False, u_contact, du, uf, tau, dt)
    _, got, meta = _one_grain(coef, True, u_contact, du, uf, tau, dt)
    np.testing.assert_allclose(got - without, -coef[BASSET_PREFACTOR] * 2.0 * math.sqrt(tau) * du, rtol=1e-12,
                               atol=1e-14)
    assert meta[META_PENDING] == round(tau / dt * AGE_TICKS)
    # "restart": no impulse, the history starts afresh at the next step
    _, restart, meta_r = _one_grain(coef, False, u_contact, du, uf, tau, dt)
    np.testing.assert_array_equal(restart, without)
    assert meta_r[META_PENDING] == 0


def test_a_grain_without_a_contact_is_left_alone():
    coef = _coef(basset=True)
    vel = np.array([[7.0, 1.0, 0.0]])
    dev = np.array([[0.1, 0.0, 0.0, 2.0, 0.0, 0.0]])  # stale row of an earlier step
    meta = allocate_history_state(1, 10).meta
    fluid_response(coef, True, vel, np.zeros((1, 3)), dev, meta, np.ones(1, np.int64), np.zeros(1, np.int64), 1,
                   0.02)
    np.testing.assert_array_equal(vel, [[7.0, 1.0, 0.0]])
