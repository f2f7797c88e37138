"""The paper's analytic identification on the diagnosis's prepared tests (``harness.analysis.identification.analytic``).

R = V/I over the steady part of T5, L from the T5 current rise, Em from the steady blocked force of T8,
K1 and K2 from the static balance at the steady displacements of T3 and T5 (paper section 3), with the
choices of :meth:`harness.analysis.identification.analytic.AnalyticOptions.diagnosis_baseline` (initial current 0, time
constant started from a grid, one force kernel per test gap, non-physical stiffness -> linear spring
from T5, noted). This module only adapts :class:`~harness.analysis.diagnosis.prepare.Series` to
:class:`~harness.analysis.identification.analytic.StepTest`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmu_src.diaphragm import damping_coefficient
from fmu_src.specs import Params
from harness.analysis.identification import analytic

from .prepare import SampleData, Series

OPTIONS = analytic.AnalyticOptions.diagnosis_baseline()


class BaselineError(ValueError):
    """A sample lacks the identification tests."""


def step_test(test: Series) -> analytic.StepTest:
    """The analytic identification's view of a prepared step test (SI; step at ``test.k_on``)."""
    return analytic.StepTest(test.name, test.t, test.V, test.I, test.y, test.r0, test.field_T,
                             response_name="force_N" if test.blocked else "displacement", step=test.k_on)


def steady_window(test: Series, frac: float = 0.5) -> slice:
    """The steady part of a step test: the last ``frac`` of the record after the onset (at least 10 samples)."""
    return analytic.steady_window(test.t.size, test.k_on, frac)


def steady_resistance(test: Series) -> float:
    """R = mean V / mean I [Ohm] over the steady window of a step test."""
    w = steady_window(test)
    return float(np.mean(test.V[w]) / np.mean(test.I[w]))


def fit_tau(test: Series, R: float) -> float:
    """Electrical time constant L/R [s] of a step test by least squares of the exact RL response to the
    measured voltage (from the onset, initial current 0) for the resistance R [Ohm]."""
    st = step_test(test)
    return analytic.fit_rl(st, R, analytic.steady_state(st, OPTIONS.steady_fraction), OPTIONS).tau_s


@dataclass(frozen=True)
class T3Line:
    """T5 rests on the coil face: K1 is free up to ``K1_max_N_per_m3`` and K2 follows from T3's static balance
    through (``x3_m`` [m], ``F3_N`` [N]) (:func:`harness.analysis.identification.analytic.k2_on_t3_line`)."""
    x3_m: float
    F3_N: float
    K1_max_N_per_m3: float

    def K2(self, K1_N_per_m3: float) -> float:
        """K2 [N/m] on T3's balance line at K1 [N/m^3]."""
        return analytic.k2_on_t3_line(K1_N_per_m3, self.x3_m, self.F3_N)


def analytic_baseline(sd: SampleData) -> tuple:
    """R, L, Em, K1 (at least 1 N/m^3: the fits work on log K1), K2 of a sample by the paper's analytic steps.

    C and m are placeholders here (fitted afterwards: damping ratio 0.5, natural frequency 15 Hz).
    Returns (Params, notes: list of str, T3Line or None): a :class:`T3Line` when the diaphragm rests on the coil
    face in T5 (the static balance there bounds K1 only; the caller fits K1 on the trajectories).
    """
    T3, T5, T8 = (sd.tests.get(n) for n in ("T3", "T5", "T8"))
    if not all(isinstance(t, Series) for t in (T3, T5, T8)):
        raise BaselineError(f"sample {sd.sid}: the diagnosis needs the identification tests T3, T5 and T8")
    res = analytic.analytic_identification(
        analytic.AnalyticInput(step_test(T3), step_test(T5), step_test(T8), sd.a, sd.D, sd.kB), OPTIONS)
    K2 = res.K2_N_per_m
    m = K2 / (2 * math.pi * 15.0) ** 2
    C = float(damping_coefficient(0.5, K2, m))
    line = None
    if res.contact == ("T5",) and res.K1_N_per_m3 > 1.0:
        x3, F3 = res.static_points["T3"]
        line = T3Line(x3, F3, res.K1_N_per_m3)
    return Params(a=sd.a, D=sd.D, kB=sd.kB, R=res.R_Ohm, L=res.L_H, Em=res.Em_N_m_per_T2,
                  K1=max(res.K1_N_per_m3, 1.0), K2=K2, C=C, m=m), list(res.notes), line
