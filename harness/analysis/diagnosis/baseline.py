"""The paper's analytic identification steps on prepared tests (R, L, Em, K1, K2), as the diagnosis uses them.

R = V/I over the steady part of T5, L from the T5 current rise, Em from the steady blocked force of T8,
K1 and K2 from the static balance at the steady displacements of T3 and T5 (paper section 3).
"""
from __future__ import annotations

import math

import numpy as np

from fmu_src.diaphragm import damping_coefficient
from fmu_src.field import make_kernel
from fmu_src.params import Params
from harness.sim.batch import zoh_current

from .prepare import SampleData, Series


class BaselineError(ValueError):
    """A sample lacks the identification tests."""


def steady_window(test: Series, frac: float = 0.5) -> slice:
    """The steady part of a step test: the last ``frac`` of the record after the onset (at least 10 samples)."""
    n_post = test.t.size - test.k_on
    k = test.t.size - max(10, int(frac * n_post))
    return slice(k, None)


def steady_resistance(test: Series) -> float:
    """R = mean V / mean I [Ohm] over the steady window of a step test."""
    w = steady_window(test)
    return float(np.mean(test.V[w]) / np.mean(test.I[w]))


def fit_tau(test: Series, R: float, I0: float = 0.0) -> float:
    """Electrical time constant L/R [s] by least squares of the exact RL response to the measured voltage
    (from the onset), for the resistance R [Ohm] and initial current I0 [A]."""
    from scipy.optimize import least_squares
    k = test.k_on
    tt, VV, II = test.t[k:], test.V[k:], test.I[k:]

    def res(q):
        return zoh_current(tt, VV, R, R * math.exp(q[0]), I0) - II

    best = min((float(np.sum(res([math.log(t0)]) ** 2)), t0) for t0 in (0.002, 0.005, 0.01, 0.02, 0.05))
    sol = least_squares(res, [math.log(best[1])], method="lm")
    return math.exp(float(sol.x[0]))


def analytic_baseline(sd: SampleData) -> tuple:
    """The paper's analytic identification steps (as ``harness.analysis.identify``) for R, L, Em, K1, K2.

    C and m are placeholders here (fitted afterwards: damping ratio 0.5, natural frequency 15 Hz).
    Returns (Params, notes: list of str).
    """
    notes = []
    T3, T5, T8 = (sd.tests.get(n) for n in ("T3", "T5", "T8"))
    if not all(isinstance(t, Series) for t in (T3, T5, T8)):
        raise BaselineError(f"sample {sd.sid}: the diagnosis needs the identification tests T3, T5 and T8")
    w5, w3, w8 = steady_window(T5), steady_window(T3), steady_window(T8)
    R = float(np.mean(T5.V[w5]) / np.mean(T5.I[w5]))
    L = R * fit_tau(T5, R)
    I3, I5, I8 = (float(np.mean(t.I[w])) for t, w in ((T3, w3), (T5, w5), (T8, w8)))
    x3, x5 = float(np.mean(T3.y[w3])), float(np.mean(T5.y[w5]))
    F8 = float(np.mean(T8.y[w8]))
    G8 = float(make_kernel(sd.a, sd.D, sd.kB, T8.r0)(T8.r0))
    Em = F8 / (I8 ** 2 * G8)
    k3 = make_kernel(sd.a, sd.D, sd.kB, T3.r0)
    k5 = make_kernel(sd.a, sd.D, sd.kB, T5.r0)
    F3 = Em * I3 ** 2 * float(k3(T3.r0 - x3))
    F5 = Em * I5 ** 2 * float(k5(T5.r0 - x5))
    try:
        K1, K2 = np.linalg.solve(np.array([[x3 ** 3, x3], [x5 ** 3, x5]]), [F3, F5])
    except np.linalg.LinAlgError:
        K1, K2 = 0.0, F5 / x5
    if not (K2 > 0):
        notes.append(f"K2 from T3/T5 not positive ({K2:.4g} N/m): linear spring from T5 alone")
        K1, K2 = 0.0, F5 / x5
    if not (K1 >= 0):
        notes.append(f"K1 from T3/T5 negative ({K1:.4g} N/m3): set to 0, K2 from T5")
        K1, K2 = 0.0, F5 / x5
    K1 = max(float(K1), 1.0)
    m = K2 / (2 * math.pi * 15.0) ** 2
    C = float(damping_coefficient(0.5, K2, m))
    return Params(a=sd.a, D=sd.D, kB=sd.kB, R=R, L=L, Em=Em, K1=K1, K2=float(K2), C=C, m=m), notes
