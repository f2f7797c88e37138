"""The paper's analytic identification on the diagnosis's prepared tests (``harness.analysis.identification.analytic``).

R = V/I over the steady part of T5, L from the T5 current rise, Em from the steady blocked force of T8,
K1 and K2 from the static balance at the steady displacements of T3 and T5 (paper section 3), with the
choices of :meth:`harness.analysis.identification.analytic.AnalyticOptions.diagnosis_baseline` (initial current 0, time
constant started from a grid, one force kernel per test gap, non-physical stiffness -> linear spring
from T5, noted). :func:`analytic_baseline` only adapts :class:`~harness.analysis.diagnosis.prepare.Series` to
:class:`~harness.analysis.identification.analytic.StepTest`; :func:`paper_baseline` adds C and m by least squares on
T3/T5 (the diagnosis's evaluator, ``fitting.Evaluator``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmu_src.diaphragm import damping_coefficient
from fmu_src.specs import Params
from harness.analysis.core import cpu_clock
from harness.analysis.core.lsq import BoxProblem
from harness.analysis.identification import analytic

from .candidates import base_bounds, base_vector
from .fitting import Evaluator, FitProblem
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


def paper_baseline(samples, settings, deadline_s: float | None = None) -> tuple:
    """Per sample: analytic R, L, Em, K1, K2 (paper section 3) and C, m by least squares on T3/T5 (no iteration
    starts after the CPU-clock instant ``deadline_s``, :mod:`harness.analysis.core.cpu_clock`; default:
    ``settings.fit_budget_s`` from now).

    Where the diaphragm rests on the coil face in T5, the static balance there bounds K1 only
    (:class:`~harness.analysis.diagnosis.baseline.T3Line`): K1 is then fitted with C and m (up to that bound, from a
    grid of fractions of it), K2 following T3's balance, and the notes say so.

    Returns ({sample index: Params}, {sample index: [notes]}).
    """
    ev = Evaluator(samples, ["T3", "T5"], settings)
    start, notes, lines = {}, {}, {}
    for i, sd in enumerate(samples):
        start[i], notes[i], lines[i] = analytic_baseline(sd)

    def with_x(i, p, x):
        """Params of sample i from its analytic p and x = (log zeta, log m[, log K1 on T3's line])."""
        if x.size > 2:
            K1 = math.exp(x[2])
            p = p.with_(K1=K1, K2=lines[i].K2(K1))
        m = math.exp(x[1])
        return p.with_(C=float(damping_coefficient(math.exp(x[0]), p.K2, m)), m=m)

    # coarse grid of (natural frequency, damping ratio[, K1 / its bound]), then Levenberg-Marquardt on
    # (log zeta, log m[, log K1])
    grid = [(f, z) for f in (4.0, 8.0, 16.0, 32.0, 64.0) for z in (0.25, 0.6, 1.5)]   # f_n [Hz], zeta
    pts = []
    for i, p in start.items():
        k1s = [None] if lines[i] is None else [lines[i].K1_max_N_per_m3 * r for r in CONTACT_K1_GRID]
        for k1 in k1s:
            q = p if k1 is None else p.with_(K1=k1, K2=lines[i].K2(k1))
            for f, z in grid:
                m = q.K2 / (2 * math.pi * f) ** 2
                pts.append((i, q.with_(m=m, C=float(damping_coefficient(z, q.K2, m)))))
    vecs = ev.vectors([[q] for q in pts])
    best = {}
    for (i, p), v in zip(pts, vecs):
        c = float(v @ v)
        if i not in best or c < best[i][0]:
            best[i] = (c, p)

    probs = []
    for i, (c, p) in best.items():
        b = base_vector(p)
        lo, hi = base_bounds(b)
        x0, lo, hi = b[5:], lo[5:], hi[5:]
        what = "C, m"
        if lines[i] is not None:
            k1_hi = math.log(lines[i].K1_max_N_per_m3)
            x0, lo, hi = (np.append(x0, b[3]), np.append(lo, k1_hi - math.log(CONTACT_K1_RANGE)),
                          np.append(hi, k1_hi))
            what = "C, m, K1 (T5 in contact)"
        probs.append(FitProblem(BoxProblem(x0, lo, hi, np.full(x0.size, 1e-5),
                                            label=f"paper baseline {what} of sample {samples[i].sid}"),
                                 lambda x, p=p, i=i: [(i, with_x(i, p, x))]))
    res = ev.solve(probs, settings.max_iter,
                   cpu_clock.now() + settings.fit_budget_s if deadline_s is None else deadline_s)
    out = {}
    for i, prob, r in zip(best, probs, res):
        out[i] = with_x(i, start[i], r.x)
        if lines[i] is not None:
            notes[i] = list(notes[i]) + [f"K1 fitted on the T3/T5 trajectories with C and m: {out[i].K1:.4g} N/m3 "
                                         f"(K2 {out[i].K2:.4g} N/m from T3's balance)"]
        if r.cut_short:
            notes[i] = list(notes[i]) + [f"{prob.box.label}: the least-squares fit stopped on its "
                                         f"{'time budget' if r.stop == 'time_budget' else 'iteration limit'} "
                                         f"after {r.iterations} iterations (not at a minimum)"]
    return out, notes


#: K1 start grid of a sample whose T5 rests on the coil face, as fractions of the bound the contact gives
CONTACT_K1_GRID = (1.0, 0.5, 0.25, 0.1, 0.01)
#: ... and the range below that bound the fit may go (a factor)
CONTACT_K1_RANGE = 1e4
