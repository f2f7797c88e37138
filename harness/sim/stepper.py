"""One RK4 step of the vectorized simulator (:mod:`harness.sim.simulator`) for a batch of runs: the stages
(right-hand side from :mod:`harness.sim.physics`), the contact events with the FMU's semantics
(:mod:`harness.sim.contact`) and the exact update of the sensor lag.

Contact, as ``fmu_src.integrator``: a free diaphragm whose step ends beyond the coil face hits it at the
instant located on the step's cubic Hermite interpolant (perfectly inelastic: x = r0, v = 0); it rests
there if the net contact force at that instant pulls toward the coil, else it is free at once. A resting
diaphragm is released at the instant the net contact force changes sign (located linearly inside the
step); the rest of the step is then integrated free from (r0, 0). Blocked runs: x = v = 0 always.

Sensor lag: y_s' = (u - y_s)/tau_s (``fmu_src.effects.sensor_rate``) solved exactly over a step for u
(x or F) quadratic in time through its values at the step's start, middle and end (two linear pieces
for x in a step with an impact or release). Units: SI.
"""
from __future__ import annotations

import numpy as np

from . import physics
from .contact import hermite_crossing, sign_change_fraction

__all__ = ["STATE_NAMES", "new_state", "make_stepper"]

STATE_NAMES = ("I", "x", "v", "dT", "xc", "xs", "Fs", "F")


def new_state(c: dict) -> dict:
    """The batch at rest: every state 0, free runs movable (fm = 1), no contact."""
    n = len(c["R"])
    S = {k: np.zeros(n) for k in STATE_NAMES}
    S["fm"] = (~c["blocked"]).astype(float)
    S["contact"] = np.zeros(n, dtype=bool)
    return S


def _rk4(f, y, h, V, F0=None):
    """Classic RK4 of the 5 states y = (I, x, v, dT, xc) (then fm) over h [s] (float or per-run array).

    V = (start, middle, end) voltages [V]; F0: the magnetic force [N] at y if known. dT and xc are left
    alone where their rates are the scalar 0.0 (coil heating / creep off in the whole batch). Returns
    (y_new, the stage derivatives k1..k4; k1[5] is the force at the start).
    """
    I, x, v, dT, xc, fm = y
    Va, Vm, Vb = V
    h2, h6 = 0.5 * h, h / 6.0

    def stage(k, hs):
        return (I + hs * k[0], x + hs * k[1], v + hs * k[2],
                dT if type(k[3]) is float else dT + hs * k[3], xc if type(k[4]) is float else xc + hs * k[4])
    k1 = f(I, x, v, dT, xc, Va, fm, F0)
    k2 = f(*stage(k1, h2), Vm, fm)
    k3 = f(*stage(k2, h2), Vm, fm)
    k4 = f(*stage(k3, h), Vb, fm)
    out = tuple(y[i] if type(k1[i]) is float else y[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]) for i in range(5))
    return out, (k1, k2, k3, k4)


def _midpoint(y, ks, h, i):
    """State i at the middle of an RK4 step: its third-order continuous extension at theta = 1/2,
    y + h*(5/24 k1 + 1/6 (k2 + k3) - 1/24 k4)."""
    k1, k2, k3, k4 = ks
    return y[i] + h * ((5.0 / 24.0) * k1[i] + (k2[i] + k3[i]) / 6.0 - k4[i] / 24.0)


def _lerp(a, b, s):
    return a + s * (b - a)


def _lag(ys, u0, u1, h, tau):
    """Exact first-order lag (``fmu_src.effects.sensor_rate``: ys' = (u - ys)/tau) over h [s] (array) for
    an input u linear from u0 to u1; tau [s] per run (0: no lag, ys = u)."""
    on = tau > 0
    hp = np.where(h > 0, h, 1.0)
    E = np.where(on, np.exp(-h / np.where(on, tau, 1.0)), 0.0)
    cE = np.where(on & (h > 0), tau * (1.0 - E) / hp, np.where(on, 1.0, 0.0))
    return u1 + (ys - u0) * E - (u1 - u0) * cE


def _lag_quadratic(ys, u, h: float, lag):
    """Exact first-order lag over h [s] for an input u quadratic through u = (u0, u_mid, u1) at 0, h/2, h:
    ys(h) = u(h) - tau u'(h) + tau^2 u'' + (ys0 - u0 + tau u'(0) - tau^2 u'') exp(-h/tau); lag = (tau [s],
    exp(-h/tau)) per run (tau 0: no lag, ys = u1, with exp(-h/tau) = 0)."""
    u0, um, u1 = u
    tau, E = lag
    b2 = 4.0 * (u1 - 2.0 * um + u0) / (h * h)           # u'' = 2 b
    a = (4.0 * um - 3.0 * u0 - u1) / h                   # u'(0)
    tt = tau * tau * b2
    return u1 - tau * (a + b2 * h) + tt + (ys - u0 + tau * a - tt) * E


class _Stepper:
    """The step of one batch (constants c) with step size hh [s]."""

    def __init__(self, c: dict, hh: float):
        self.c, self.hh = c, hh
        self.flags = c["flags"]
        self.rhs = physics.rhs(c)
        self.force, self.net_contact = physics.forces(c)
        if self.flags[5]:
            tau = c["tau_s"]
            self.lag_E = np.where(tau > 0, np.exp(-hh / np.where(tau > 0, tau, 1.0)), 0.0)

    def __call__(self, S: dict, Va, Vb) -> None:
        heat, creep = self.flags[0], self.flags[2]
        r0 = self.c["r0"]
        Vm = Va if Va is Vb else 0.5 * (Va + Vb)
        old = (S["I"], S["x"], S["v"], S["dT"], S["xc"])
        fm = S["fm"]
        # the force at the start is the one of the previous step's end (same state)
        (I, x, v, dT, xc), ks = _rk4(self.rhs, old + (fm,), self.hh, (Va, Vm, Vb), S["F"])
        F_old = ks[0][5]
        if self.flags[5]:
            # the state at the middle of the step (the lag of the curved force, below)
            mid_state = (_midpoint(old, ks, self.hh, 0), np.minimum(_midpoint(old, ks, self.hh, 1), r0))
        if not heat:
            dT = old[3]
        if not creep:
            xc = old[4]
        contact = S["contact"]
        g_start = None
        s_evt = None          # fraction of the step at an impact or release (-1: none)
        hit = (fm > 0) & (x >= r0)
        if hit.any():
            # impact located on the step's Hermite interpolant; the state there: x = r0, v = 0
            s_imp = np.zeros(x.size)
            s_imp[hit] = hermite_crossing(old[1][hit], old[2][hit], x[hit], v[hit], self.hh, r0[hit])
            x = np.where(hit, r0, x)
            v = np.where(hit, 0.0, v)
            s_evt = np.where(hit, s_imp, -1.0)
            net_imp = self.net_contact(_lerp(old[0], I, s_imp), _lerp(old[4], xc, s_imp))
            stick = hit & (net_imp >= 0.0)
            if stick.any():
                contact = contact | stick
                fm = np.where(stick, 0.0, fm)
                g_start = (stick, net_imp, s_imp)
        if contact.any():
            net_end = self.net_contact(I, xc)
            rel = contact & (net_end < 0.0)
            if rel.any():
                g0 = self.net_contact(old[0], old[4])
                s0 = np.zeros(x.size)
                if g_start is not None:
                    stick, net_imp, s_imp = g_start
                    g0 = np.where(stick, net_imp, g0)
                    s0 = np.where(stick, s_imp, 0.0)
                s = np.maximum(sign_change_fraction(g0, net_end), s0)
                s_evt = np.where(rel, s, -1.0 if s_evt is None else s_evt)
                I, x, v, dT, xc, contact, fm = self._release(rel, s, (old, (I, x, v, dT, xc)), (Va, Vb),
                                                             (contact, fm))
        F = self.force(I, x)
        if self.flags[5]:
            x_old = old[1]
            xs = _lag_quadratic(S["xs"], (x_old, mid_state[1], x), self.hh, (self.c["tau_s"], self.lag_E))
            if s_evt is not None:
                # x is r0 from the event on: the exact lag of the two linear pieces
                ev = np.flatnonzero(s_evt >= 0.0)
                se, tau, r0e = s_evt[ev], self.c["tau_s"][ev], r0[ev]
                mid = _lag(S["xs"][ev], x_old[ev], r0e, se * self.hh, tau)
                xs[ev] = _lag(mid, r0e, x[ev], (1.0 - se) * self.hh, tau)
            S["xs"] = xs
            # x and F are curved within a step (F ~ I^2): the exact lag of their quadratics through the
            # start, the middle (third-order continuous extension of the step) and the end
            F_mid = self.force(mid_state[0], mid_state[1])
            S["Fs"] = _lag_quadratic(S["Fs"], (F_old, F_mid, F), self.hh, (self.c["tau_s"], self.lag_E))
        S.update(I=I, x=x, v=v, dT=dT, xc=xc, fm=fm, contact=contact, F=F)

    def _release(self, rel, s, states, V, modes):
        """Release the runs rel at the fractions s of the step: integrate the rest of the step free from
        (r0, 0) with the other states interpolated at s; returns the updated (I, x, v, dT, xc, contact, fm)."""
        old, new = states
        contact, fm = modes
        idx = np.flatnonzero(rel)
        sub = physics.subset(self.c, idx)
        sr = s[idx]
        Va, Vb = (np.broadcast_to(u, rel.shape)[idx] for u in V)
        Vs = _lerp(Va, Vb, sr)
        y0 = (_lerp(old[0][idx], new[0][idx], sr), sub["r0"].copy(), np.zeros(idx.size),
              _lerp(old[3][idx], new[3][idx], sr), _lerp(old[4][idx], new[4][idx], sr), np.ones(idx.size))
        y1, _ = _rk4(physics.rhs(sub), y0, (1.0 - sr) * self.hh, (Vs, 0.5 * (Vs + Vb), Vb))
        # only the mechanics are taken from the partial step: the current, temperature and dashpot of
        # the whole step (in contact until s) differ from it by the interpolation error only
        I, x, v, dT, xc = new
        x, v = np.array(x, dtype=float, copy=True), np.array(v, dtype=float, copy=True)
        x[idx], v[idx] = y1[1], y1[2]
        contact = contact & ~rel
        fm = np.where(rel, 1.0, fm)
        # pulled back onto the face within the same step: rests again if the net force pulls
        back = rel & (x >= self.c["r0"])
        if back.any():
            x = np.where(back, self.c["r0"], x)
            v = np.where(back, 0.0, v)
            again = back & (self.net_contact(I, xc) >= 0.0)
            contact = contact | again
            fm = np.where(again, 0.0, fm)
        return I, x, v, dT, xc, contact, fm


def make_stepper(c: dict, hh: float):
    """step(S, Va, Vb): one RK4 step of size hh [s] of the runs in c, the state dict S updated in place;
    Va, Vb the voltages [V] at the step's start and end (equal for a held input)."""
    return _Stepper(c, hh)
