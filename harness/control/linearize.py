"""Linearization of the actuator at an operating point, as a python-control ``StateSpace``.

The operating point is the steady state holding the displacement x0 (``fmu_src.statics``); A and B are
central finite differences of the compiled right-hand side the FMU integrates (``fmu_src.model.Dynamics.rhs``,
free flight), so the linear model is the FMU's model's, with its effects. Input: the voltage deviation
dV [V]; output: the displacement deviation dx [m]; states: deviations of y = [I, x, v, effect states].

    lin = linearize(Params(), x0_m=1e-3)
    lin.sys            # control.StateSpace, dx/dV
    lin.V0_V, lin.y0   # operating point
"""
from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from fmu_src.model import FREE
from fmu_src.specs import Params
from fmu_src.statics import Statics


@dataclass(frozen=True)
class Linearization:
    """Linear model dx/dV at an operating point: ``sys`` (StateSpace), y0 (states), V0_V, x0_m, names."""
    sys: object
    y0: np.ndarray
    V0_V: float
    x0_m: float
    state_names: tuple

    def dc_gain_m_per_V(self) -> float:
        """Static gain d x / d V [m/V] of the linear model."""
        return float(np.real(control.dcgain(self.sys)))


def linearize(p: Params, x0_m: float, rel_step: float = 1e-6) -> Linearization:
    """Linearize the model of p at the steady state holding x0_m [m] (0 <= x0_m < r0).

    Parameters
    ----------
    p : Params
        Model parameters (effects included).
    x0_m : float
        Operating displacement [m].
    rel_step : float
        Relative finite-difference step (per state: of its scale; for V: of max(V0, 1 V)).
    """
    s = Statics(p)
    I0 = s.current_for(float(x0_m))
    y0 = s.state(I0, float(x0_m))
    V0 = s.voltage(I0, float(x0_m))
    dyn = s.dyn
    n = s.n
    scales = np.array(dyn.scales()) * 1e3   # the integrator's atol scales: 1 A, r0 m, 10 r0 m/s, ...

    def f(y, V):
        return np.array(dyn.rhs(y, V, FREE))
    A = np.zeros((n, n))
    for j in range(n):
        h = rel_step * scales[j]
        e = np.zeros(n)
        e[j] = h
        A[:, j] = (f(y0 + e, V0) - f(y0 - e, V0)) / (2 * h)
    hV = rel_step * max(abs(V0), 1.0)
    B = ((f(y0, V0 + hV) - f(y0, V0 - hV)) / (2 * hV)).reshape(n, 1)
    C = np.zeros((1, n))
    C[0, 1] = 1.0
    sys = control.ss(A, B, C, np.zeros((1, 1)), inputs=["dV_V"], outputs=["dx_m"],
                     states=[f"d{k}" for k in s.names])
    return Linearization(sys, y0, float(V0), float(x0_m), tuple(s.names))
