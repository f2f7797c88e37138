"""Contact events of the vectorized simulator, with the semantics of the FMU's integrator
(``fmu_src.integrator``):

* impact: a free diaphragm reaching the coil face (x = r0) stops there, perfectly inelastic
  (x = r0, v = 0); the instant is located inside the step (here: on the step's cubic Hermite
  interpolant of x, the FMU: on its dense output);
* rest: it stays on the face while the net contact force (``fmu_src.effects.net_contact_force``)
  pulls toward the coil (>= 0); at an impact where it pushes away the diaphragm is free at once;
* release: when the net contact force changes sign, located inside the step (linear in the
  step's end values here, or exactly where the caller knows the current).

Blocked runs (x = v = 0) have no events. Units: SI.
"""
from __future__ import annotations

import math

# plain arithmetic on floats and numpy arrays alike; register_jitable lets the compiled core
# (harness.sim.core) call the same functions
from numba.extending import register_jitable

__all__ = ["hermite_crossing", "sign_change_fraction"]


@register_jitable
def hermite_crossing(x0, v0, x1, v1, h, r0, iterations: int = 40):
    """Fraction s in (0, 1] of a step where its cubic Hermite interpolant first reaches r0.

    Parameters
    ----------
    x0, v0 : float or array
        Displacement [m] and velocity [m/s] at the step start (x0 < r0).
    x1, v1 : float or array
        The same at the step end (x1 >= r0).
    h : float or array
        Step size [s].
    r0 : float or array
        Gap [m] (position of the coil face).
    iterations : int
        Bisection steps (40: s to 1e-12).

    Returns
    -------
    float or array
        s, the smallest bisection bracket end with the interpolant >= r0.
    """
    lo = x0 * 0.0
    hi = lo + 1.0
    for _ in range(iterations):
        s = 0.5 * (lo + hi)
        s2, s3 = s * s, s * s * s
        p = ((2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * x1
             + (s3 - s2) * h * v1)
        above = p >= r0
        # the bracket end where the interpolant is above r0 (a select written as arithmetic: exact)
        hi = s * above + hi * (1.0 - above)
        lo = lo * above + s * (1.0 - above)
    return hi


@register_jitable
def sign_change_fraction(g0: float, g1: float) -> float:
    """Fraction s in [0, 1] of a step where g, linear between g0 >= 0 and g1 < 0, turns negative.

    Parameters
    ----------
    g0, g1 : float
        Net contact force [N] at the step start and end.

    Returns
    -------
    float
        g0/(g0 - g1) clipped to [0, 1] (0 where g0 < 0 already, or where it is not a number).
    """
    if not g0 > 0.0:
        return 0.0
    s = g0 / (g0 - g1) if g0 != g1 else math.inf
    if s != s:
        return 0.0
    return min(max(s, 0.0), 1.0)
