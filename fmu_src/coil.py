"""The electromagnet as a series RL circuit (paper Eq. 1): V - I*R - L*dI/dt = 0."""
from __future__ import annotations

import math


def steady_current(V: float, R: float) -> float:
    """Steady-state current V/R [A] for a constant voltage V [V] and resistance R [Ohm]."""
    return V / R


def time_constant(R: float, L: float) -> float:
    """Electrical time constant L/R [s]."""
    return L / R


def current_step(I0: float, V: float, R: float, L: float, h: float) -> float:
    """Exact current [A] after holding voltage V [V] for h [s], starting from I0 [A]."""
    Iinf = V / R
    return Iinf + (I0 - Iinf) * math.exp(-h * R / L)


def voltage_for_field(B_face: float, kB: float, R: float) -> float:
    """Voltage [V] whose steady current gives the field B_face [T] at the coil face (kB in T/A)."""
    return B_face / kB * R
