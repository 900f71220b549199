"""Counter-based random numbers for particle kernels.

Every draw is a pure function of ``(seed, particle, counter)``: a SplitMix64
finaliser (Steele, Lea & Flood 2014, the output function of Java's
``SplittableRandom``) is applied to the three integers in turn.  Nothing is
stored between calls, so the numbers a particle receives do not depend on which
thread handles it or in which order particles are processed: a run is
reproducible for a given seed whatever the thread count.

The caller owns the counter: the natural choice is a per-particle event count
(e.g. the number of bed impacts so far) or the step index, times the number of
draws needed per event.  ``uniform``, ``uniform2`` and ``normal`` hash into
separate domains, so ``uniform(s, i, c)`` and ``normal(s, i, c)`` are
independent of each other.

This is not a cryptographic generator; it passes the usual statistical
batteries (SplitMix64 passes BigCrush) and is more than adequate for contact
angles and initial perturbations.

All functions are ``@njit(cache=True, no_cfunc_wrapper=True)`` and take plain Python/NumPy integers
(seed, particle, counter >= 0); they return float64.
"""

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)

# domain separators for the public functions
_DOMAIN_UNIFORM = np.uint64(0x243F6A8885A308D3)
_DOMAIN_UNIFORM2 = np.uint64(0x13198A2E03707344)
_DOMAIN_NORMAL = np.uint64(0xA4093822299F31D0)

_TWO_M53 = 1.0 / 9007199254740992.0  # 2**-53


@njit(cache=True, no_cfunc_wrapper=True, inline="always", _nrt=False)
def _mix64(z):
    """SplitMix64 finaliser: a bijective avalanche mix of a uint64."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def random_bits(seed, particle, counter, domain=0):
    """64 random bits, a function of (seed, particle, counter, domain) only."""
    z = _mix64(np.uint64(seed) + _GOLDEN)
    z = _mix64(z ^ (np.uint64(particle) * _GOLDEN + _M1))
    z = _mix64(z ^ (np.uint64(counter) * _M2 + _GOLDEN))
    z = _mix64(z ^ np.uint64(domain))
    return z


@njit(cache=True, no_cfunc_wrapper=True, inline="always", _nrt=False)
def _bits_to_open_unit(z):
    # top 53 bits, shifted by half a unit: values in (0, 1), never 0 or 1
    return (np.float64(z >> _S11) + 0.5) * _TWO_M53


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def uniform(seed, particle, counter):
    """Uniform double in the open interval (0, 1)."""
    return _bits_to_open_unit(random_bits(seed, particle, counter, _DOMAIN_UNIFORM))


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def uniform2(seed, particle, counter):
    """Two independent uniforms in (0, 1) from one counter value (a tuple)."""
    z1 = random_bits(seed, particle, counter, _DOMAIN_UNIFORM2)
    z2 = _mix64(z1 ^ _GOLDEN)
    return _bits_to_open_unit(z1), _bits_to_open_unit(z2)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def normal(seed, particle, counter):
    """Standard normal variate (Box-Muller on two independent uniforms)."""
    z1 = random_bits(seed, particle, counter, _DOMAIN_NORMAL)
    z2 = _mix64(z1 ^ _GOLDEN)
    u1 = _bits_to_open_unit(z1)
    u2 = _bits_to_open_unit(z2)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)
