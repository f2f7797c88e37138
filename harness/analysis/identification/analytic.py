"""The paper's analytic identification (section 3), written once for identification and diagnosis.

From three measured step tests of one sample, in SI units:

* T5 (0.23 T displacement step): coil resistance R = V_ss / I_ss [Ohm] over the steady part of the
  record; inductance L [H] and the step instant (anywhere within the sample interval before the first
  sample of the step) by a joint least-squares fit (``scipy.optimize.least_squares``, over log(L/R)
  and the fraction of the interval) of the exact RL response to the step at that instant, then to
  the measured voltage held over each sample interval (:func:`harness.sim.population.zoh_current`),
  to the measured current from the step on (:func:`fit_rl`; any step test: :func:`step_instant`); the field per
  ampere kB [T/A] = field_T / I_ss when the manifest does not give it.
* T8 (0.23 T blocked-force step): Em [N.m/T^2] = F_ss / (I_ss^2 G(r0_T8)) (diaphragm held at x = 0).
* T3 and T5 (0.11 T and 0.23 T displacement steps): the static balance
  K1 x^3 + K2 x = Em I^2 G(r0 - x) written for both tests is a 2x2 linear system for
  K1 [N/m^3] and K2 [N/m].

Steady values are means over the last ``steady_fraction`` of the samples from the step on (at least
10 samples), or from a test's ``steady_start`` on where that is given; their standard uncertainties are
std / sqrt(n) of the window (white noise). The standard uncertainty of L comes from the fit (residual
variance and Jacobian), those of Em, K1 and K2 from the steady means by linear propagation (central
differences), that of R from the steady V and I.

Inputs are plain arrays (:class:`StepTest`, :class:`AnalyticInput`), the result a frozen
:class:`AnalyticResult`. :class:`AnalyticOptions` holds the choices in which the two former copies
(``harness.analysis.identification.identify`` and ``harness.analysis.diagnose``) differed; the default is
identify's, :meth:`AnalyticOptions.diagnosis_baseline` reproduces diagnose's former numbers:

============================  ===============================  =================================
option                        default (identify)               diagnosis_baseline()
============================  ===============================  =================================
``initial_current``           "pre_step_mean": mean current    "zero": 0 A
                              of the 20 samples before the
                              step (start of the RL response)
``tau_start``                 "crossing": 63 % crossing of     "grid": best of 2, 5, 10, 20,
                              the current                      50 ms by squared error
``tau_scaling``               "unit": x_scale = 1              "jacobian": scipy's default
                                                               (x_scale = 'jac' since 1.16)
``kernel_range``              "shared": one G table up to the  "per_test": one table per test
                              largest gap of T3, T5, T8        gap (``make_kernel(.., r0)``)
``nonphysical``               "raise": AnalyticError           "fallback": K2 <= 0 or K1 < 0 ->
                                                               K1 = 0, K2 = F5/x5 (noted)
============================  ===============================  =================================

The start value and scaling of the L fit change L only within the fit's tolerance (about 1e-7
relative); the initial current by the pre-step current offset; the kernel range by the spline's
interpolation error (< 1e-8). "fallback" also skips the plausibility checks (positive blocked
force, displacement distinguishable from noise and not in contact, monotonic T3 -> T5).
The diagnosis's former copy also raised K1 to at least 1 N/m^3 afterwards (its fits work on log K1):
that floor is the caller's, not part of the identification.

Use (what ``harness.analysis.diagnose`` did, same numbers to 2e-15 on the default dataset)::

    tests = {n: StepTest(n, t, V, I, y_SI, r0_m, field_T, step=k_on) for n, ... in (T3, T5, T8)}
    res = analytic_identification(AnalyticInput(tests["T3"], tests["T5"], tests["T8"], a_m, D_m, kB),
                                  AnalyticOptions.diagnosis_baseline())
    params = res.params(C=..., m=...)          # fmu_src.specs.Params; res.notes: fallbacks taken
    tau_s = fit_rl(test, R_Ohm, steady_state(test), AnalyticOptions.diagnosis_baseline()).tau_s
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares

from fmu_src.field import make_kernel
from harness.data.protocol import NoStepError, step_onset
from harness.sim.population import zoh_current

from .analytic_types import (AnalyticError, AnalyticInput, AnalyticOptions, AnalyticResult, RLFit,  # noqa: F401
                             SteadyState, StepTest)
from .coil_lag import refine_step_instant

__all__ = [
    "AnalyticError", "StepTest", "AnalyticInput", "AnalyticOptions", "SteadyState", "RLFit", "AnalyticResult",
    "steady_window", "steady_state", "fit_rl", "step_instant", "rl_current", "static_stiffness", "analytic_identification",
    "MIN_SAMPLES", "MIN_STEADY_SAMPLES", "CONTACT_GAP_FRACTION", "k2_on_t3_line",
]

MIN_SAMPLES = 20           # samples a record needs in all, and after the step
MIN_STEADY_SAMPLES = 10    # samples of the steady window at least
_PRE_STEP_SAMPLES = 20     # samples before the step averaged for the initial current
_TAU_GRID_S = (0.002, 0.005, 0.01, 0.02, 0.05)


# ============================================================================ steps
def steady_window(n_samples: int, step: int, fraction: float = 0.5) -> slice:
    """Steady window: the last ``fraction`` of the n_samples - step samples from the step on (>= 10)."""
    return slice(n_samples - max(MIN_STEADY_SAMPLES, int(fraction * (n_samples - step))), None)


def _mean_sd(y: np.ndarray) -> tuple[float, float]:
    return float(np.mean(y)), float(np.std(y)) / math.sqrt(y.size)


def steady_state(test: StepTest, fraction: float = 0.5) -> SteadyState:
    """Steady values of a step test (checked: finite arrays, increasing time, a step from rest).

    Raises :class:`AnalyticError` naming the test for records that are too short, non-finite,
    not increasing in time, without a step, whose current never rises or is not at rest before.
    """
    name = test.name
    t, V, I, y = (np.asarray(v, dtype=float) for v in (test.time_s, test.voltage_V, test.current_A, test.response))
    for arr, what in ((t, "time_s"), (V, "voltage_V"), (I, "current_A"), (y, test.response_name)):
        if arr.size < MIN_SAMPLES or not np.all(np.isfinite(arr)):
            raise AnalyticError(name, f"{what} must hold at least {MIN_SAMPLES} finite samples")
    if np.any(np.diff(t) <= 0):
        raise AnalyticError(name, "time_s must be strictly increasing")
    try:
        k = step_onset(t, V).index if test.step is None else int(test.step)
    except NoStepError as e:
        raise AnalyticError(name, str(e)) from None
    if k < 1 or t.size - k < MIN_SAMPLES:
        raise AnalyticError(name, f"the record needs samples before and at least {MIN_SAMPLES} after the step")
    win = steady_window(t.size, k, fraction)
    if test.steady_start is not None:
        if not (k < int(test.steady_start) <= t.size - MIN_STEADY_SAMPLES):
            raise AnalyticError(name, f"the steady window's start (sample {test.steady_start}) must lie after the "
                                      f"step (sample {k}) and leave at least {MIN_STEADY_SAMPLES} samples")
        win = slice(int(test.steady_start), None)
    Iss, sd_I = _mean_sd(I[win])
    if not (Iss > max(10.0 * sd_I, 1e-6)):
        raise AnalyticError(name, f"the current never rises (steady current {Iss:.4g} A)")
    I_pre = float(np.mean(np.abs(I[:k])))
    if I_pre > 0.2 * Iss:
        raise AnalyticError(name, f"the current is already {I_pre:.4g} A before the step "
                                  f"(steady {Iss:.4g} A): not a step from rest")
    Vss, sd_V = _mean_sd(V[win])
    yss, sd_y = _mean_sd(y[win])
    return SteadyState(step=k, start=win.start, t_step_s=float(t[k]), voltage_V=Vss, current_A=Iss, response=yss,
                       sd_voltage_V=sd_V, sd_current_A=sd_I, sd_response=sd_y)


# ============================================================================ coil
def _tau_start_crossing(tt, II, I0: float, I_ss: float, dt0: float) -> float:
    frac = (II - I0) / (I_ss - I0)
    above = np.flatnonzero(frac >= 1.0 - math.exp(-1.0))
    return max(float(tt[above[0]] - tt[0]) if above.size else (tt[-1] - tt[0]) / 5, 2 * dt0)


def _first_interval_current(s: float, dt: float, V_k: float, R: float, tau: float, I0: float) -> float:
    """Current [A] at the first sample of the step, ``s * dt`` [s] after the step instant (V_k from it on)."""
    return V_k / R + (I0 - V_k / R) * math.exp(-s * dt / tau)


def _initial_current(I: np.ndarray, k: int, options: AnalyticOptions) -> float:
    """[A] the current the step starts from (``options.initial_current``): the mean of the samples before the
    step's first sample k, or 0."""
    if k > 0 and options.initial_current == "pre_step_mean":
        return float(np.mean(I[max(0, k - _PRE_STEP_SAMPLES):k]))
    return 0.0


def _resistance_rel_sd(steady: SteadyState) -> float:
    """Relative standard uncertainty [-] of R = V_ss / I_ss from the steady means' own."""
    return math.hypot(steady.sd_current_A / steady.current_A, steady.sd_voltage_V / max(abs(steady.voltage_V), 1e-300))


def _rl_nuisances(I: np.ndarray, k: int, steady: SteadyState, R_Ohm: float, I0: float, options) -> list:
    """[(keyword of the fit's residual, value, d log L / d value held directly, standard uncertainty)] of what the
    RL fit holds: R [Ohm] (V_ss / I_ss of the steady window: L = R tau, so 1 / R directly) and the initial current
    I0 [A] (the mean of the pre-step samples; its noise is the steady window's per-sample sigma over the square
    root of their count: at 100 Hz, with L/R about one sample period, the first samples of the rise carry the fit
    and an I0 off by its noise moves L by a fraction of its sd)."""
    out = []
    if steady.current_A > 0 and math.isfinite(steady.sd_current_A):
        out.append(("R", R_Ohm, 1.0 / R_Ohm, R_Ohm * _resistance_rel_sd(steady)))
    n_pre = min(k, _PRE_STEP_SAMPLES)
    n_win = max(1, I.size - int(steady.start))
    if options.initial_current == "pre_step_mean" and n_pre > 0 and math.isfinite(steady.sd_current_A):
        out.append(("I_0", I0, 0.0, steady.sd_current_A * math.sqrt(n_win) / math.sqrt(n_pre)))
    return out


#: step of the one-sided difference [fraction of a sample period] that gives the step phase's Jacobian column at a bound
_PHASE_STEP = 1e-6


def _step_phase_jacobian(resid, sol, J: np.ndarray) -> np.ndarray:
    """The RL fit's Jacobian (columns log tau, s) with the step phase's column computed even when s sits on a
    bound (0 or 1: the step at a sample instant, as when a DAQ drives and samples on one clock): there the fit
    held s (its column zero), and a covariance from that Jacobian is L's given s, too narrow, since the data
    cannot tell s = 0 from s slightly above it (at 100 Hz, L/R ~ 1 sample period: rms z 1.14 of L, 131 of 240
    fits on a bound). A one-sided difference into the interval gives the column; the covariance is then that of
    the unconstrained linearization, the marginal uncertainty of L and of the instant."""
    x = np.asarray(sol.x, dtype=float)
    s = float(x[1])
    if 0.0 < s < 1.0 and np.any(J[:, 1] != 0.0):
        return J
    h = _PHASE_STEP if s <= 0.5 else -_PHASE_STEP
    col = (np.asarray(resid([x[0], s + h])) - np.asarray(sol.fun)) / h
    return np.column_stack([J[:, 0], col])


def fit_rl(test: StepTest, R_Ohm: float, steady: SteadyState, options: AnalyticOptions = AnalyticOptions()
           ) -> RLFit:
    """Time constant L/R [s], L [H] and the step instant [s] of a step's current by least squares.

    Model (the README's data format, "between samples"): the coil sees 0 V (the pre-step voltage)
    until the step instant ``t_step = t[k] - s dt`` (k = ``steady.step``, the first sample of the
    step, dt its sample period, 0 <= s <= 1), the voltage of sample k from then to t[k], and each
    later sample's voltage held over its interval (zero-order hold); the current starts at the
    initial current (``options.initial_current``). Fitted to the measured current from sample k on:
    log(L/R) and, with ``options.step_instant == "fit"``, s jointly (trust-region reflective within
    the bounds); with "sample" s = 0 (the step at sample k, Levenberg-Marquardt on log(L/R) alone).
    R_Ohm [Ohm] is held. Raises :class:`AnalyticError` when the fit fails or
    (``nonphysical="raise"``) the time constant exceeds half the record.
    """
    t = np.asarray(test.time_s, dtype=float)
    V = np.asarray(test.voltage_V, dtype=float)
    I = np.asarray(test.current_A, dtype=float)
    k = steady.step
    tt, VV, II = t[k:], V[k:], I[k:]
    dt = float(t[k] - t[k - 1]) if k > 0 else float(t[1] - t[0])
    I0 = _initial_current(I, k, options)
    fit_s = options.step_instant == "fit"

    def model(p, R=R_Ohm, I_0=I0):
        tau = math.exp(p[0])
        s = float(p[1]) if fit_s else 0.0
        Ik = _first_interval_current(s, dt, float(VV[0]), R, tau, I_0)
        return zoh_current(tt, VV, R, R * tau, Ik)

    def resid(p, R=R_Ohm, I_0=I0):
        return model(p, R, I_0) - II

    if options.tau_start == "crossing":
        tau0 = _tau_start_crossing(tt, II, I0, steady.current_A, float(t[1] - t[0]))
    else:
        tau0 = min((float(np.sum(resid([math.log(t0), 0.5]) ** 2)), t0) for t0 in _TAU_GRID_S)[1]
    if fit_s:
        # start s from the first sample's rise (first order in s dt / tau), within the bounds
        frac = (II[0] - I0) / max(abs(float(VV[0]) / R_Ohm - I0), 1e-300)
        s0 = min(max(-tau0 * math.log(max(1.0 - frac, 1e-12)) / dt, 0.0), 1.0)
        sols = [least_squares(resid, [math.log(tau0), st], bounds=([-np.inf, 0.0], [np.inf, 1.0]),
                              method="trf", x_scale=[1.0, 1.0], xtol=1e-12, ftol=1e-12)
                for st in sorted({s0, 0.5})]
        # the bounds themselves (a step at a sample instant, s = 0 or 1), where trf converges slowly
        for edge in (0.0, 1.0):
            e = least_squares(lambda p, e_=edge: resid([p[0], e_]), [math.log(tau0)], method="lm")
            e.x = np.array([e.x[0], edge])
            e.jac = np.column_stack([e.jac, np.zeros(e.jac.shape[0])])
            sols.append(e)
        sol = min(sols, key=lambda r: float(np.sum(r.fun ** 2)))
    else:
        kw = {"x_scale": [1.0]} if options.tau_scaling == "unit" else {}
        sol = least_squares(lambda p: resid([p[0], 0.0]), [math.log(tau0)], method="lm", **kw)
    tau = math.exp(float(sol.x[0]))
    s = float(sol.x[1]) if fit_s else 0.0
    L = R_Ohm * tau
    if not (math.isfinite(L) and L > 0):
        raise AnalyticError(test.name, f"the RL fit of the current failed (L = {L!r})")
    J = sol.jac
    if fit_s:
        J = _step_phase_jacobian(resid, sol, J)
    s2 = float(np.sum(sol.fun ** 2)) / max(1, tt.size - J.shape[1])
    try:
        A = np.linalg.pinv(J.T @ J)
        var = s2 * np.diag(A)                 # (log tau[, s])
        var_logL = float(var[0])
        var_s = float(var[1]) if fit_s else 0.0
        # the held nuisances (R, the initial current I0) are estimates too: their uncertainty moves the fitted
        # (log tau, s) by -A J^T dr/dq (the implicit-function derivative at the optimum), and L = R tau
        for name, q, dlogL_direct, sd_q in _rl_nuisances(I, k, steady, R_Ohm, I0, options):
            h = 1e-6 * max(abs(q), 1e-3 if name == "I_0" else 1e-9)
            dr = (resid(sol.x, **{name: q + h}) - sol.fun) / h
            dp = -A @ (J.T @ dr)
            var_logL += (float(dp[0]) + dlogL_direct) ** 2 * sd_q ** 2
            if fit_s:
                var_s += float(dp[1]) ** 2 * sd_q ** 2
        sd_L = float(L * math.sqrt(max(var_logL, 0.0)))
        sd_s = float(math.sqrt(max(var_s, 0.0))) if fit_s else 0.0
    except np.linalg.LinAlgError:
        sd_L, sd_s = float("nan"), float("nan")
    if options.nonphysical == "raise" and tau > 0.5 * (tt[-1] - tt[0]):
        raise AnalyticError(test.name, f"the current does not reach steady state (time constant "
                                       f"{tau:.3g} s is longer than half the record)")
    return RLFit(tau_s=tau, L_H=L, sd_L_H=sd_L, I0_A=I0, t_step_s=float(t[k]) - s * dt,
                 sd_t_step_s=sd_s * dt, step_delay_s=s * dt, sample_period_s=dt)


#: sub-intervals per sample interval on which a "cubic" drive's spline is sampled (then read linear between
#: them): the linear reading's error there is (w dt / 8)^2 / 8 of the drive's amplitude, 2.5e-5 for 55
#: samples per drive period (a 1.9 Hz sine at 105 Hz)
CUBIC_SUBDIVISION = 8


def cubic_drive(V, M: int = CUBIC_SUBDIVISION) -> np.ndarray:
    """The sampled voltage V [V] (n,) read as a smooth drive: scipy's not-a-knot cubic spline through the
    samples, sampled M times per sample interval ((n - 1) M + 1 values; every M-th is V itself). Its error
    for a drive of angular frequency w is of order (w dt)^4, where the linear reading's is (w dt)^2 / 8."""
    from scipy.interpolate import CubicSpline
    V = np.asarray(V, dtype=float)
    if V.size < 4:
        return np.interp(np.arange((V.size - 1) * M + 1) / M, np.arange(V.size), V)
    return CubicSpline(np.arange(V.size), V)(np.arange((V.size - 1) * M + 1) / M)


def rl_current(t, V, R_Ohm: float, L_H: float, I0_A: float = 0.0, hold: str = "zoh") -> np.ndarray:
    """Exact coil current [A] on the uniform grid t [s] for the sampled voltage V [V] from I0_A [A].

    hold "zoh": V[k] held over [t[k], t[k+1]) (:func:`harness.sim.population.zoh_current`);
    "linear": V linear between the samples, I[k+1] = a I[k] + ((1 - a) - c) V[k]/R + c V[k+1]/R with
    a = exp(-dt R/L), c = 1 - (L/R)(1 - a)/dt (the exact solution for a ramp over each interval);
    "cubic": V a cubic spline through the samples (:func:`cubic_drive`: an analog drive sampled slowly),
    the linear solution on its :data:`CUBIC_SUBDIVISION` sub-intervals, read at the samples.
    """
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    if hold == "zoh":
        return zoh_current(t, V, R_Ohm, L_H, I0_A)
    if hold == "cubic":
        M = CUBIC_SUBDIVISION
        fine = t[0] + (t[-1] - t[0]) * np.arange((t.size - 1) * M + 1) / ((t.size - 1) * M)
        return rl_current(fine, cubic_drive(V, M), R_Ohm, L_H, I0_A, "linear")[::M]
    if hold != "linear":
        raise ValueError(f"hold must be 'zoh', 'linear' or 'cubic', got {hold!r}")
    from scipy.signal import lfilter
    dt = float((t[-1] - t[0]) / (t.size - 1))
    tau = L_H / R_Ohm
    a = math.exp(-dt / tau)
    c = 1.0 - tau * (1.0 - a) / dt
    b = [c / R_Ohm, ((1.0 - a) - c) / R_Ohm]
    y, _ = lfilter(b, [1.0, -a], V, zi=[I0_A - b[0] * V[0]])
    return y


def step_instant(test: StepTest, options: AnalyticOptions = AnalyticOptions()) -> RLFit:
    """The RL fit (:func:`fit_rl`) of any step test with R = V_ss / I_ss of its own steady window:
    its step instant ``t_step_s`` [s] (within the sample interval before the first sample of the
    step) and the delay ``step_delay_s`` [s] of that first sample after it. A current that rises as a coil with
    a lag (eddy currents in the core) rather than as one RL circuit gets that coil's instant
    (:func:`harness.analysis.identification.coil_lag.refine_step_instant`; L and L/R stay the RL fit's)."""
    st = steady_state(test, options.steady_fraction)
    R = st.voltage_V / st.current_A
    rl = fit_rl(test, R, st, options)
    k = st.step
    if options.step_instant != "fit" or k < 1:
        return rl
    t = np.asarray(test.time_s, dtype=float)
    I = np.asarray(test.current_A, dtype=float)
    I0 = _initial_current(I, k, options)
    return refine_step_instant(t[k:], np.asarray(test.voltage_V, dtype=float)[k:], I[k:], R, I0,
                               float(t[k] - t[k - 1]), rl)


# ============================================================================ static balance
def static_stiffness(F3_N: float, x3_m: float, F5_N: float, x5_m: float) -> tuple[float, float]:
    """(K1 [N/m^3], K2 [N/m]) with K1 x^3 + K2 x = F at two steady points (x [m], F [N]).

    Raises ``numpy.linalg.LinAlgError`` when the two points do not determine them (x3 = x5, or 0).
    """
    A = np.array([[x3_m ** 3, x3_m], [x5_m ** 3, x5_m]])
    K1, K2 = np.linalg.solve(A, [F3_N, F5_N])
    return float(K1), float(K2)


class _Kernels:
    """G(r) per test: one table up to the largest gap ("shared") or one per test gap ("per_test")."""

    def __init__(self, inp: AnalyticInput, kB: float, mode: str):
        gaps = {n: float(getattr(inp, n).gap_m) for n in ("T3", "T5", "T8")}
        if mode == "shared":
            G = make_kernel(inp.a_m, inp.D_m, kB, max(gaps.values()))
            self.by_test = {n: G for n in gaps}
        else:
            self.by_test = {n: make_kernel(inp.a_m, inp.D_m, kB, r0) for n, r0 in gaps.items()}
        self.gaps = gaps

    def at(self, test: str, x_m: float = 0.0) -> float:
        """G(r0 - x) [T^2/(A^2.m)] of a test at displacement x [m]."""
        return float(self.by_test[test].eval(self.gaps[test] - x_m))


def _em_k(values, G: _Kernels, I5_ref: float | None = None) -> np.ndarray:
    """(Em, K1, K2) from (F8 [N], I8 [A], x3 [m], I3 [A], x5 [m], I5 [A]).

    ``I5_ref`` [A]: kB was derived from T5 as field_T / I5_ref (None: kB known), so at another I5 the kernel
    G, which scales as kB^2, is G (I5_ref / I5)^2: Em moves as I5^2, the forces Em kB^2 I^2 (so K1, K2) do not."""
    F8, I8, x3, I3, x5, I5 = values
    s = 1.0 if I5_ref is None else (I5_ref / I5) ** 2
    Em = F8 / (I8 ** 2 * G.at("T8") * s)
    K1, K2 = static_stiffness(Em * s * I3 * I3 * G.at("T3", x3), x3, Em * s * I5 * I5 * G.at("T5", x5), x5)
    return np.array([Em, K1, K2])


def _propagate(v0: np.ndarray, sd: np.ndarray, G: _Kernels, I5_ref: float | None = None) -> np.ndarray:
    """Standard uncertainties of (Em, K1, K2) from those of the steady means (central differences; ``I5_ref``
    as :func:`_em_k`: a kB derived from T5 carries T5's current uncertainty into Em)."""
    Jm = np.empty((3, v0.size))
    for i in range(v0.size):
        dv = np.zeros(v0.size)
        dv[i] = 1e-6 * max(abs(v0[i]), 1e-12)
        Jm[:, i] = (_em_k(v0 + dv, G, I5_ref) - _em_k(v0 - dv, G, I5_ref)) / (2 * dv[i])
    return np.sqrt((Jm ** 2) @ (sd ** 2))


def _radius_sensitivity(inp: AnalyticInput, kB: float, options, v0: np.ndarray) -> np.ndarray:
    """d(Em, K1, K2)/da [per m] at the steady means v0 (central differences of +-1e-4 a)."""
    h = 1e-4 * inp.a_m
    up, dn = (_em_k(v0, _Kernels(replace(inp, a_m=inp.a_m + s * h), kB, options.kernel_range)) for s in (1, -1))
    return (up - dn) / (2 * h)


def _check_plausible(inp: AnalyticInput, s3: SteadyState, s5: SteadyState, s8: SteadyState) -> bool:
    """Raises :class:`AnalyticError` for implausible steady values; returns whether T3's step is resolved by the
    noise (a T3 within ``MIN_STEP_SD`` standard deviations of 0 beside a resolved T5 is not an error: K1 is then
    left undetermined and K2 taken from T5)."""
    if not (s8.response > 0):
        raise AnalyticError("T8", f"the steady blocked force is {s8.response:.4g} N: it must be positive "
                                  f"(attraction toward the coil); check the sign of force_N")
    if s8.response < 5.0 * max(s8.sd_response, 1e-12):
        raise AnalyticError("T8", f"the steady blocked force {s8.response:.4g} N is not distinguishable "
                                  f"from noise")
    resolved = {}
    for s, name in ((s5, "T5"), (s3, "T3")):
        x, r0 = s.response, float(getattr(inp, name).gap_m)
        resolved[name] = bool(x > MIN_STEP_SD * max(s.sd_response, 1e-15) and x > 0)
        if not resolved[name] and (name == "T5" or x <= -MIN_STEP_SD * s.sd_response):
            raise AnalyticError(name, f"the steady displacement {x * 1e3:.4g} mm is not a positive "
                                      f"step toward the coil")
        if x >= CONTACT_GAP_FRACTION * r0:
            raise AnalyticError(name, f"the diaphragm rests on the coil face (steady displacement "
                                      f"{x * 1e3:.4g} mm, gap {r0 * 1e3:.4g} mm): the static balance "
                                      f"does not hold in contact")
    if not (s5.current_A > s3.current_A):
        raise AnalyticError("T5", f"non-monotonic data: the T5 current ({s5.current_A:.4g} A) must exceed the "
                                  f"T3 current ({s3.current_A:.4g} A) (higher field)")
    return resolved["T3"]


def _stiffness_checked(F3, x3, F5, x5, nonphysical: str, notes: list) -> tuple[float, float]:
    if nonphysical == "raise":
        if not (F5 > F3):
            raise AnalyticError("T5", "non-monotonic data: the magnetic force of T5 does not exceed that of T3")
        if not (x5 > x3):
            raise AnalyticError("T5", f"non-monotonic data: the T5 displacement ({x5 * 1e3:.4g} mm) must "
                                      f"exceed the T3 displacement ({x3 * 1e3:.4g} mm) at the higher force")
        K1, K2 = static_stiffness(F3, x3, F5, x5)
        if not (K2 > 0):
            raise AnalyticError("T3", f"non-physical linear stiffness K2 = {K2:.4g} N/m from T3 and T5")
        return K1, K2               # K1 < 0: judged against its uncertainty (_k1_within_noise)
    try:
        K1, K2 = static_stiffness(F3, x3, F5, x5)
    except np.linalg.LinAlgError:
        notes.append("T3/T5 do not determine K1 and K2: linear spring from T5 alone")
        return 0.0, F5 / x5
    if not (K2 > 0):
        notes.append(f"K2 from T3/T5 not positive ({K2:.4g} N/m): linear spring from T5 alone")
        return 0.0, F5 / x5
    if not (K1 >= 0):
        notes.append(f"K1 from T3/T5 negative ({K1:.4g} N/m3): set to 0, K2 from T5")
        return 0.0, F5 / x5
    return K1, K2


#: a T3 or T5 steady displacement is a step the noise resolves beyond this many standard deviations of its window
#: mean (an unresolved T5, or a T3 as far below 0, is refused; an unresolved T3 leaves K1 undetermined)
MIN_STEP_SD = 5.0
#: a steady displacement at or beyond this fraction of the test's gap r0 is the diaphragm resting on the coil face
CONTACT_GAP_FRACTION = 0.98


def k2_on_t3_line(K1_N_per_m3: float, x3_m: float, F3_N: float) -> float:
    """K2 [N/m] that keeps T3's static balance K1 x3^3 + K2 x3 = F3 for a given K1 [N/m^3] (x3 [m], F3 [N])."""
    return (F3_N - K1_N_per_m3 * x3_m ** 3) / x3_m


def _contact_tests(inp: AnalyticInput, x3: float, x5: float) -> tuple:
    """The identification tests whose steady displacement is at the coil face (CONTACT_GAP_FRACTION)."""
    return tuple(n for n, x in (("T3", x3), ("T5", x5)) if x >= CONTACT_GAP_FRACTION * float(getattr(inp, n).gap_m))


#: a negative K1 within this many standard uncertainties of 0 is noise (set to 0), beyond it an error
K1_NOISE_SD = 3.0


def _k1_within_noise(K1, sd_K1, F3, x3, F5, x5, notes: list) -> tuple[float, float]:
    """("raise" policy) K1 < 0 [N/m^3]: (0, F5/x5) with a note when within K1_NOISE_SD standard uncertainties
    sd_K1 of 0 (noisy steady displacements of a stiff, weakly deflected sample do not resolve the Duffing
    term), else :class:`AnalyticError`."""
    if math.isfinite(sd_K1) and K1 >= -K1_NOISE_SD * sd_K1:
        notes.append(f"K1 from T3/T5 negative ({K1:.4g} +- {sd_K1:.3g} N/m3) but within {K1_NOISE_SD:g} standard "
                     f"uncertainties of 0 (not resolved by the noise): set to 0, K2 from T5")
        return 0.0, F5 / x5
    raise AnalyticError("T5", f"non-physical Duffing coefficient K1 = {K1:.4g} N/m^3 < 0 (standard uncertainty "
                              f"{sd_K1:.3g} N/m^3): the secant stiffness F/x falls from T3 ({F3 / x3:.4g} N/m) "
                              f"to T5 ({F5 / x5:.4g} N/m)")


# ============================================================================ all together
def _coil_field(inp: AnalyticInput, s5: SteadyState, options: AnalyticOptions):
    R = s5.voltage_V / s5.current_A
    rl = fit_rl(inp.T5, R, s5, options)
    sd_R = R * _resistance_rel_sd(s5)
    kB, source = inp.kB_T_per_A, "manifest"
    if kB is None:
        kB, source = float(inp.T5.field_T) / s5.current_A, "T5 field_T / steady current"
    if not (kB > 0 and math.isfinite(kB)):
        raise AnalyticError("T5", f"field per ampere must be > 0, got {kB!r}")
    return R, sd_R, rl, float(kB), source


def analytic_identification(inp: AnalyticInput, options: AnalyticOptions = AnalyticOptions()) -> AnalyticResult:
    """R, L, kB, Em, K1, K2 of one sample with standard uncertainties (paper section 3; module docstring).

    Raises :class:`AnalyticError` (naming the test) for unusable data; with
    ``options.nonphysical == "raise"`` also for implausible steady values and non-physical stiffness.
    """
    if not (inp.a_m > 0 and math.isfinite(inp.a_m)):
        raise AnalyticError(None, f"the loop radius a must be > 0 m, got {inp.a_m!r}")
    if not (inp.D_m > 0):
        raise AnalyticError(None, f"the diameter D must be > 0 m, got {inp.D_m!r}")
    s3, s5, s8 = (steady_state(t, options.steady_fraction) for t in (inp.T3, inp.T5, inp.T8))
    R, sd_R, rl, kB, kB_source = _coil_field(inp, s5, options)
    for name in ("T3", "T5", "T8"):
        r0 = float(getattr(inp, name).gap_m)
        if not (r0 > 0 and math.isfinite(r0)):
            raise AnalyticError(name, f"gap_mm must be > 0, got {r0 * 1e3:.6g}")
    G = _Kernels(inp, kB, options.kernel_range)
    t3_resolved = _check_plausible(inp, s3, s5, s8) if options.nonphysical == "raise" else True
    Em = s8.response / (s8.current_A ** 2 * G.at("T8"))
    x3, x5 = s3.response, s5.response
    I3, I5 = s3.current_A, s5.current_A
    F3 = Em * I3 * I3 * G.at("T3", x3)
    F5 = Em * I5 * I5 * G.at("T5", x5)
    notes: list = []
    contact = _contact_tests(inp, x3, x5) if options.nonphysical == "fallback" else ()
    if t3_resolved:
        K1, K2 = _stiffness_checked(F3, x3, F5, x5, options.nonphysical, notes)
    else:
        K1, K2 = 0.0, F5 / x5
        notes.append(f"T3's steady displacement ({x3 * 1e3:.4g} +- {s3.sd_response * 1e3:.3g} mm) is not resolved "
                     f"by the noise (under {MIN_STEP_SD:g} standard deviations): K1 not determined (set to 0), "
                     f"K2 from T5")
    if contact == ("T5",):
        notes.append(f"T5: the diaphragm rests on the coil face (steady displacement {x5 * 1e3:.4g} mm, gap "
                     f"{float(inp.T5.gap_m) * 1e3:.4g} mm): the static balance does not hold there, so T3/T5 give "
                     f"only an upper bound on K1 ({K1:.4g} N/m3, on T3's balance line)")
    elif contact:
        notes.append("T3 and T5: the diaphragm rests on the coil face: the static balance does not determine K1 "
                     "and K2 (kept from the T3/T5 formulas)")
    v0 = np.array([s8.response, s8.current_A, x3, s3.current_A, x5, s5.current_A])
    sd = np.array([s8.sd_response, s8.sd_current_A, s3.sd_response, s3.sd_current_A, s5.sd_response,
                   s5.sd_current_A])
    try:
        sd_ek = _propagate(v0, sd, G, None if kB_source == "manifest" else float(s5.current_A))
        if inp.sd_a_m > 0:        # a derived from the data: its uncertainty reaches Em, K1, K2 through G
            sd_ek = np.hypot(sd_ek, _radius_sensitivity(inp, kB, options, v0) * inp.sd_a_m)
    except np.linalg.LinAlgError:
        sd_ek = np.full(3, np.nan)
    if t3_resolved and K1 < 0:
        K1, K2 = _k1_within_noise(K1, float(sd_ek[1]), F3, x3, F5, x5, notes)
    return AnalyticResult(
        a_m=float(inp.a_m), D_m=float(inp.D_m), kB_T_per_A=kB, kB_source=kB_source, R_Ohm=R, L_H=rl.L_H,
        Em_N_m_per_T2=Em, K1_N_per_m3=float(K1), K2_N_per_m=float(K2), sd_R_Ohm=sd_R, sd_L_H=rl.sd_L_H,
        sd_Em_N_m_per_T2=float(sd_ek[0]), sd_K1_N_per_m3=float(sd_ek[1]), sd_K2_N_per_m=float(sd_ek[2]),
        steady={"T3": s3, "T5": s5, "T8": s8}, notes=tuple(notes), rl_T5=rl, sd_a_m=float(inp.sd_a_m),
        contact=contact, static_points={"T3": (float(x3), float(F3)), "T5": (float(x5), float(F5))})
