"""The diaphragm as a mass-spring-damper with a Duffing hardening spring (paper Eqs. 4-5).

    m*x'' + C*x' + (K1*x^2 + K2)*x = F

x is the centre displacement toward the coil [m]; contact with the coil face at
x = r0 is handled by the integrator (``fmu_src.integrator``).
"""
from __future__ import annotations

# register_jitable: these stay plain Python functions (floats and numpy arrays) and numba-compiled code
# (the FMU's integrator, fmu_src.integrator) can call the very same functions
import numpy as np
from numba.extending import register_jitable


@register_jitable
def spring_force(x, K1: float, K2: float):
    """Restoring force (K1*x^2 + K2)*x [N] at displacement x [m]."""
    return (K1 * x * x + K2) * x


@register_jitable
def acceleration(x, v, F, K1: float, K2: float, C: float, m: float):
    """x'' [m/s^2] from Eq. 4: (F - C*v - (K1*x^2 + K2)*x) / m. Works on floats and numpy arrays."""
    return (F - C * v - (K1 * x * x + K2) * x) / m


@register_jitable
def tangent_stiffness(x, K1: float, K2: float):
    """d/dx of the spring force, 3*K1*x^2 + K2 [N/m]."""
    return 3.0 * K1 * x * x + K2


def damping_ratio(C, K2, m):
    """Small-signal damping ratio zeta = C / (2 sqrt(K2 m)) [-] of damping C [N.s/m], linear stiffness K2 [N/m]
    and mass m [kg]. Floats or numpy arrays."""
    return C / (2.0 * np.sqrt(K2 * m))


def damping_coefficient(zeta, K2, m):
    """Damping C = 2 zeta sqrt(K2 m) [N.s/m] for damping ratio zeta [-], K2 [N/m], m [kg]; the inverse of
    :func:`damping_ratio`. Floats or numpy arrays."""
    return 2.0 * zeta * np.sqrt(K2 * m)
