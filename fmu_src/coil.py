"""The electromagnet as a series RL circuit (paper Eq. 1): V - I*R - L*dI/dt = 0.

The current's rate is ``fmu_src.effects.current_rate`` (with the effects on the coil); here the static
relation the rig and the FMU's start value use.
"""
from __future__ import annotations


def voltage_for_field(B_face: float, kB: float, R: float) -> float:
    """Voltage [V] whose steady current gives the field B_face [T] at the coil face (kB in T/A)."""
    return B_face / kB * R
