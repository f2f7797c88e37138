"""The step instant of a coil whose current does not rise as one RL circuit (:func:`refine_step_instant`).

:func:`harness.analysis.identification.analytic.step_instant` locates a step between two samples from the
shape of the current's rise, fitted as a plain RL circuit. A coil with a lag in its voltage balance (eddy currents
in the core: a shorted secondary, the term set's ``eddy_current``, L_f I' = V - R I + c (z - I),
z' = (I - z)/tau_e) rises at first with its fast inductance L_f = (1 - k^2) L and then with the slow one L: fitted
as one RL circuit, the fast start reads as a step up to a whole sample period early, and every model simulated from
that instant misses the first samples of the step by the fast rise (hundreds of noise floors), whatever its coil.

Here the same record is fitted a second time with that coil: parameters the slow inductance L, the share
k^2 = c tau_e / L in [0, ``SHARE_MAX``] the lag carries, tau_e and the instant; R held (steady state). Its instant
replaces the RL fit's when the lag lowers the residual sum of squares by more than the BIC penalty of its two extra
parameters (2 ln n, in units of the lagged fit's residual variance): a plain RL coil keeps the RL fit's instant.
The response is exact for the sampled (zero-order-hold) voltage: two real modes, each a first-order recursion.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

#: largest share k^2 of the slow inductance the lag may carry (as the discovery's ``SHARE_BOUND``)
SHARE_MAX = 0.95
#: [s] starts of the lag's time constant (a fast and a slow eddy-current lag)
TAU_STARTS_S = (0.002, 0.02, 0.1)


def lagged_coil_current(t, V, R_Ohm: float, L_H: float, k2: float, tau_e_s: float, delay_s: float,
                        I0_A: float = 0.0) -> np.ndarray:
    """Current [A] at the uniform instants t [s] (t[0]: the first sample of the step) of the coil
    (1 - k2) L I' = V - R I + c (z - I), z' = (I - z)/tau_e, c = k2 L/tau_e, at rest at I0 (z = I0) until
    ``delay_s`` before t[0], then V[0] up to t[0] and each V[n] held over [t[n], t[n+1]) (zero-order hold)."""
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    dt = float(t[1] - t[0])
    Lf = (1.0 - k2) * L_H
    c = k2 * L_H / tau_e_s
    A = np.array([[-(R_Ohm + c) / Lf, c / Lf], [1.0 / tau_e_s, -1.0 / tau_e_s]])
    lam, P = np.linalg.eig(A)
    lam, P = lam.real, P.real
    Pinv = np.linalg.inv(P)
    g = Pinv @ np.array([1.0 / Lf, 0.0])               # modal input gains
    w = Pinv @ np.array([I0_A, I0_A])                  # at rest before the step
    w_ss = -g * V[0] / lam                             # the modes' steady values under V[0]
    w0 = w_ss + (w - w_ss) * np.exp(lam * delay_s)     # at t[0]
    I = np.zeros(t.size)
    for j in range(2):
        mu = math.exp(lam[j] * dt)
        y, _ = lfilter([0.0, (mu - 1.0) / lam[j] * g[j]], [1.0, -mu], V, zi=[w0[j]])
        y[0] = w0[j]
        I += P[0, j] * y
    return I


def refine_step_instant(tt, VV, II, R_Ohm: float, I0_A: float, dt: float, rl):
    """``rl`` (the RL fit, :class:`~harness.analysis.identification.analytic.RLFit`, of the current II [A] at the
    instants tt [s] from the first sample of the step on, voltage VV [V]) with the step instant of the lagged coil
    when that coil explains the rise better by more than the BIC penalty (module docstring); else ``rl``
    itself. Its L and time constant stay the RL fit's (the paper's identification)."""
    tt, VV, II = (np.asarray(a, dtype=float) for a in (tt, VV, II))
    n = II.size
    if n < 8 or not (R_Ohm > 0 and rl.L_H > 0 and dt > 0):
        return rl
    s_rl = rl.step_delay_s / dt
    r_rl = II - lagged_coil_current(tt, VV, R_Ohm, rl.L_H, 0.0, 1.0, s_rl * dt, I0_A)
    rss_rl = float(r_rl @ r_rl)

    def resid(p):
        return lagged_coil_current(tt, VV, R_Ohm, math.exp(p[0]), p[1], math.exp(p[2]), p[3] * dt, I0_A) - II

    lo = [math.log(rl.L_H) - 3.0, 0.0, math.log(max(dt / 4.0, 1e-6)), 0.0]
    hi = [math.log(rl.L_H) + 3.0, SHARE_MAX, math.log(max(tt[-1] - tt[0], 10 * dt)), 1.0]
    best = None
    for tau0 in TAU_STARTS_S:
        x0 = np.clip([math.log(rl.L_H), 0.5, math.log(tau0), 0.5], lo, hi)
        try:
            sol = least_squares(resid, x0, bounds=(lo, hi), method="trf", xtol=1e-10, ftol=1e-10)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if np.all(np.isfinite(sol.fun)) and (best is None or sol.cost < best.cost):
            best = sol
    if best is None:
        return rl
    rss = 2.0 * float(best.cost)
    s2 = rss / max(n - 4, 1)
    if not (s2 > 0 and (rss_rl - rss) / s2 > 2.0 * math.log(n)):
        return rl
    s = float(best.x[3])
    try:
        cov = s2 * np.linalg.pinv(best.jac.T @ best.jac)
        sd_s = math.sqrt(max(float(cov[3, 3]), 0.0))
    except np.linalg.LinAlgError:
        sd_s = float("nan")
    return replace(rl, t_step_s=float(tt[0]) - s * dt, sd_t_step_s=sd_s * dt, step_delay_s=s * dt)
