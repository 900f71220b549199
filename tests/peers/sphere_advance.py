"""Spheres in free flight over the virtual bed, without grain–grain contacts: ``advance``,
the loop that tests and benchmarks drive directly (one RK4 step of every grain, then its
virtual-bed check, chunk by chunk in parallel). A run never calls it: a run steps through
``saltation.engine.stepping.advance_split`` (free flight → contacts → bed), which calls
the same kernels of ``saltation.flight.spheres`` (``free_flight_particles``,
``_bed_check_body``) in separate passes.

The kernels are stamped in the Numba cache like the packages' own (the hash of this file
and of everything of the packages it imports: flowfields/_numba_cache.py), so an edit to
the flight kernels is never loaded stale from here.
"""
from __future__ import annotations

from numba import njit, prange

from saltation.flight.spheres import CHUNK, OK, _bed_check_body, free_flight_particles

__all__ = ["advance", "step_particles"]


@njit(cache=True, error_model="numpy", _nrt=False)
def step_particles(f, coef, bed, seed, st, w, hc, lo, hi, t, dt, top):
    """One RK4 step from t to t + dt (saltation.flight.spheres, module docstring) of grains
    lo..hi-1 that are OK: free flight (``free_flight_particles``), then the bed check; counts steps spent
    above the stored flow."""
    free_flight_particles(f, coef, st, w, hc, lo, hi, t, dt)
    for p in range(lo, hi):
        if st.status[p] != OK:
            continue
        _bed_check_body(f, coef, hc, st, w, p, t, dt, bed, seed)
        if st.pos[p, 1] > top:
            st.above_top[p] += 1


@njit(cache=True, parallel=True, error_model="numpy")
def advance(f, coef, bed, seed, st, w, hc, t0, dt, n_steps, top):
    """Advance all grains n_steps from t0. Stops early (returning the steps done) when a
    grain's state is not finite or a jump buffer is full, so the caller can collect."""
    n = st.pos.shape[0]
    cap = st.jump_buf.shape[1]
    n_chunks = (n + CHUNK - 1) // CHUNK
    k0 = round(t0 / dt)  # the global index of the first step (t0 is always k0 * dt)
    for s in range(n_steps):
        t = (k0 + s) * dt  # from the global step index: never from where a chunk began
        for c in prange(n_chunks):
            step_particles(f, coef, bed, seed, st, w, hc, c * CHUNK, min(n, (c + 1) * CHUNK), t, dt, top)
        stop = False
        for p in range(n):
            if st.status[p] != OK or st.jump_buf_n[p] >= cap:
                stop = True
                break
        if stop:
            return s + 1
    return n_steps
