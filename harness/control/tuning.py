"""PI(D) gains from the linearization (``harness.control.linearize``), for the controller FMU.

The feed-forward (static inverse) supplies the steady voltage; the PI corrects around it. The gains are
chosen on the loop C(s)*G(s)*exp(-s*T_d) with G the linearization at each operating point of interest,
C = Kp*(1 + 1/(Ti*s)) with Ti = ``ti_factor``/wc (anti-windup tracking time Tt = 0.3*Ti), and T_d = 1.5
communication steps (zero-order hold and the one-step delay of a co-simulation loop, as a first-order Pade term): the largest crossover wc [rad/s]
on a grid for which every operating point keeps a phase margin >= ``pm_deg`` and a gain margin >= ``gm``.
Kp is set so that |C*G| = 1 at wc at the operating point with the largest gain (the plant's gain grows
toward pull-in: elsewhere the crossover is lower, the loop slower but stable).
"""
from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from fmu_src.specs import Params

from .linearize import linearize


@dataclass(frozen=True)
class PidGains:
    """Gains of the controller FMU (its parameters of the same names): Kp [V/m], Ki [V/(m.s)], Kd [V.s/m],
    Tf [s], Tt [s]; the design's crossover wc [rad/s] and its worst margins (phase [deg], gain [-])."""
    Kp: float
    Ki: float
    Kd: float
    Tf: float
    Tt: float
    wc_rad_s: float
    phase_margin_deg: float
    gain_margin: float

    def fmu_parameters(self) -> dict:
        """{FMU parameter name: value} of the controller FMU."""
        return {"Kp": self.Kp, "Ki": self.Ki, "Kd": self.Kd, "Tf": self.Tf, "Tt": self.Tt}


def _margins(loop) -> tuple[float, float]:
    gm, pm, _wg, _wp = control.margin(loop)
    gm = np.inf if gm is None or not np.isfinite(gm) else float(gm)
    return gm, float(pm)


def tune_pi(p: Params, x_ops_m, step_s: float = 1e-3, pm_deg: float = 55.0, gm: float = 2.5,
            ti_factor: float = 3.0, best_effort: bool = False) -> PidGains:
    """PI gains (Kd = 0) for the operating points x_ops_m [m] (see the module docstring).

    Parameters
    ----------
    p : Params
        The model (paper's, or extended by the diagnosis).
    x_ops_m : sequence of float
        Operating displacements [m] the loop must be stable and well damped at.
    step_s : float
        Control period [s] (communication step of the loop).
    pm_deg, gm : float
        Smallest phase margin [deg] and gain margin [-] accepted at every operating point.
    ti_factor : float
        Integral time Ti = ti_factor/wc.
    best_effort : bool
        When no crossover meets both margins: the crossover whose worse margin comes closest to its requirement
        (min(PM/pm_deg, GM/gm) largest), if the loop is still stable (PM > 0, GM > 1) at every operating point;
        the returned margins say how far it falls short. Without it (default) that is a ValueError.
    """
    lins = [linearize(p, x) for x in x_ops_m]
    if not lins:
        raise ValueError("tune_pi: no operating point given")
    num, den = control.pade(1.5 * step_s, 1)
    delay = control.tf(num, den)
    plants = [control.ss2tf(lin.sys) * delay for lin in lins]
    s = control.tf("s")
    best, closest = None, None
    for wc in np.geomspace(2.0, 2000.0, 60):
        Ti = ti_factor / wc
        C0 = 1 + 1 / (Ti * s)
        kp = min(1.0 / abs(control.evalfr(C0 * G, 1j * wc)) for G in plants)   # largest-gain point crosses at wc
        worst_pm, worst_gm = np.inf, np.inf
        for G in plants:
            g_m, p_m = _margins(kp * C0 * G)
            worst_pm, worst_gm = min(worst_pm, p_m), min(worst_gm, g_m)
        if worst_pm >= pm_deg and worst_gm >= gm:
            best = (wc, kp, Ti, worst_pm, worst_gm)
        score = min(worst_pm / pm_deg, worst_gm / gm)
        if worst_pm > 0.0 and worst_gm > 1.0 and (closest is None or score > closest[0]):
            closest = (score, (wc, kp, Ti, worst_pm, worst_gm))
    if best is None and best_effort and closest is not None:
        best = closest[1]
    if best is None:
        raise ValueError(f"tune_pi: no crossover meets phase margin {pm_deg} deg and gain margin {gm}")
    wc, kp, Ti, pm, g = best
    return PidGains(Kp=float(kp), Ki=float(kp / Ti), Kd=0.0, Tf=0.002, Tt=float(0.3 * Ti),
                    wc_rad_s=float(wc), phase_margin_deg=pm, gain_margin=g)
