"""Time integration of the actuator: RL coil + loop field + force kernel + Duffing diaphragm.

State y = [I (A), x (m), v (m/s), *effect states]; the effect states and terms
(``fmu_src.effects.EffectDynamics``) are there only when an effect is switched on,
otherwise the plain 3-state ``Dynamics`` runs. Three modes:

* free: the full ODE;
* contact: the diaphragm rests on the coil face, x = r0 and v = 0; it got there
  by a perfectly inelastic impact (no bounce) and stays while the net force
  F - K(r0)*r0 pulls toward the coil; it is released when the net force changes sign;
* blocked: x = v = 0 always (force-transducer tests T7/T8); F is the blocked force.

The integrator is an adaptive Dormand-Prince 5(4) pair with its 4th-order dense
output, written for Python floats so a communication step costs a few microseconds.
With the input held constant it integrates past a communication point and
interpolates; when the input changes it restarts from the interpolated state at
that point. Contact and release instants are located on the dense output.
"""
from __future__ import annotations

import math

import numpy as np

from .params import Params
from .field import make_kernel
from .diaphragm import acceleration, spring_force, tangent_stiffness

# Dormand-Prince 5(4) tableau (Hairer & Wanner), as in scipy's RK45.
_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0)
_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
)
_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)
_E = (-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40)
# Dense output: y(t + s*h) = y + h * sum_j Q_j s^(j+1), Q = K^T P.
_P = (
    (1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432),
    (0.0, 0.0, 0.0, 0.0),
    (0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799),
    (0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072),
    (0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632),
    (0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844),
    (0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423),
)

FREE, CONTACT, BLOCKED = 0, 1, 2


class Dynamics:
    """Right-hand sides and outputs of the paper's model for one parameter set."""

    n_states = 3
    handles_effects = False   # True in fmu_src.effects.EffectDynamics

    def __init__(self, p: Params):
        self.p = p.validated()
        if not self.handles_effects:
            from .effects import active_effects  # lazy: fmu_src.effects imports this module
            if active_effects(p):
                raise ValueError(f"Dynamics is the paper's plain model; effects {list(active_effects(p))} are on: "
                                 "use fmu_src.effects.EffectDynamics (ActuatorModel picks it by default)")
        self.kernel = make_kernel(p.a, p.D, p.kB, p.r0)
        self.G = self.kernel  # callable: G(r) [T^2/(A^2.m)]
        self._rhs = self._make_rhs()

    def stability_step(self) -> float:
        """Largest step [s] inside DP5's real-axis stability region (about -3.3) for every mode.

        Near a steady state the error estimate vanishes, so without this bound the
        step grows until the method becomes unstable and oscillates at the tolerance.
        """
        p = self.p
        rates = [p.R / p.L]
        if not p.blocked:
            k_t = tangent_stiffness(p.r0, p.K1, p.K2)
            rates += [math.sqrt(k_t / p.m), p.C / p.m]
        return 2.5 / max(rates)

    def initial_state(self) -> list:
        return [0.0, 0.0, 0.0]

    def scales(self) -> list:
        """Absolute-tolerance scales per state (A, m, m/s)."""
        p = self.p
        return [1e-3, 1e-3 * max(p.r0, 1e-3), 1e-2 * max(p.r0, 1e-3)]

    def magnetic_force(self, y, r: float) -> float:
        I = y[0]
        return self.p.Em * I * I * self.G(r)

    def rhs(self, y, V: float, mode: int) -> list:
        """dy/dt for the state y [I, x, v] under voltage V [V] in the given mode."""
        return self._rhs(y, V, mode)

    def _make_rhs(self):
        p, G = self.p, self.G
        R, invL, Em, r0, K1, K2, C, m = p.R, 1.0 / p.L, p.Em, p.r0, p.K1, p.K2, p.C, p.m

        def rhs(y, V, mode):
            I = y[0]
            dI = (V - R * I) * invL
            if mode != FREE:
                return [dI, 0.0, 0.0]
            x, v = y[1], y[2]
            return [dI, v, acceleration(x, v, Em * I * I * G(r0 - x), K1, K2, C, m)]
        return rhs

    def net_contact_force(self, y) -> float:
        """Magnetic minus spring force [N] with the diaphragm on the coil face (x = r0)."""
        p = self.p
        return self.magnetic_force(y, 0.0) - spring_force(p.r0, p.K1, p.K2)

    def field_centre(self, y, mode: int) -> float:
        """Field at the diaphragm centre [T]: on-axis loop field kB*I*a^3/(a^2+r^2)^(3/2) at r = r0 - x."""
        p = self.p
        r = max(p.r0 - y[1], 0.0)
        return p.kB * y[0] * p.a ** 3 / (p.a * p.a + r * r) ** 1.5

    def force(self, y, mode: int) -> float:
        """Magnetic force on the diaphragm [N], attraction positive."""
        return self.magnetic_force(y, max(self.p.r0 - y[1], 0.0))

    def sensors(self, y, mode: int, F: float):
        """Displacement [m] and force [N] as the sensors read them: x and F (no sensor lag here)."""
        return y[1], F


class Integrator:
    """Adaptive DP5(4) integrator with contact/release events and input-hold semantics.

    ``advance(t_end, V)`` moves the view time to t_end with the voltage V held
    since the previous call; ``y`` and ``mode`` give the state at the view time.
    """

    def __init__(self, dyn: Dynamics, rtol: float = 1e-7, max_step: float = 0.05, t0: float = 0.0):
        if not (rtol > 0 and math.isfinite(rtol)):
            raise ValueError(f"parameter rtol must be > 0 and finite, got {rtol!r}")
        self.dyn = dyn
        self.rtol = float(rtol)
        self.atol = [self.rtol * s for s in dyn.scales()]
        self.max_step = min(float(max_step), dyn.stability_step())
        self.reset(t0)

    # -- state ---------------------------------------------------------------
    def reset(self, t0: float = 0.0, y0=None):
        dyn = self.dyn
        y = list(dyn.initial_state() if y0 is None else y0)
        if dyn.p.blocked:
            mode = BLOCKED
            y[1] = y[2] = 0.0
        elif y[1] >= dyn.p.r0:
            mode = CONTACT
            y[1], y[2] = dyn.p.r0, 0.0
        else:
            mode = FREE
        self.t = float(t0)
        self._view = (y, mode)
        # integration front (may run ahead of the view time while the input is unchanged)
        self._t = self.t
        self._y = list(y)
        self._mode = mode
        self._V = None
        self._hold_changed = True
        self._k0 = None          # FSAL derivative at the front
        self._h = 1e-4
        self._dense = None       # (t0, h, y0, Q) of the last accepted step
        self.n_steps = 0
        self.n_rhs = 0

    # -- public --------------------------------------------------------------
    def advance(self, t_end: float, V: float):
        """Integrate to t_end [s] with the input voltage V [V] held constant since ``self.t``."""
        if t_end < self.t - 1e-15:
            raise ValueError(f"cannot integrate backwards from t={self.t} to t={t_end}")
        self._hold_changed = V != self._V
        if self._hold_changed:
            # restart from the current view state with the new input
            self._t, self._y, self._mode = self.t, list(self.y), self.mode
            self._k0 = None
            self._dense = None
            self._V = V
        while self._t < t_end:
            self._step(t_end)
        self.t = t_end
        self._view = None   # computed when asked for (see ``y`` and ``mode``)

    @property
    def y(self) -> list:
        """State [I, x, v, ...] at the view time ``t``."""
        if self._view is None:
            self._view = self._view_state()
        return self._view[0]

    @property
    def mode(self) -> int:
        """FREE, CONTACT or BLOCKED at the view time ``t``."""
        if self._view is None:
            self._view = self._view_state()
        return self._view[1]

    def _view_state(self):
        d, t = self._dense, self.t
        if d is not None and d[0] <= t < self._t:
            y = self._interp(d, t)
            if d[4] != FREE:
                y[1], y[2] = d[2][1], 0.0
            return y, d[4]
        return list(self._y), self._mode

    # -- internals -----------------------------------------------------------
    @staticmethod
    def _coeffs(d):
        """Dense-output coefficients Q of a step record, computed on first use."""
        if d[5] is None:
            K = d[3]
            d[5] = [[sum(K[j][i] * _P[j][c] for j in (0, 2, 3, 4, 5, 6)) for c in range(4)]
                    for i in range(len(d[2]))]
        return d[5]

    def _interp(self, d, t):
        t0, h, y0 = d[0], d[1], d[2]
        Q = self._coeffs(d)
        s = (t - t0) / h
        s2 = s * s
        s3 = s2 * s
        s4 = s3 * s
        return [y0[i] + h * (Q[i][0] * s + Q[i][1] * s2 + Q[i][2] * s3 + Q[i][3] * s4) for i in range(len(y0))]

    def _step(self, t_end: float):
        dyn, V, mode = self.dyn, self._V, self._mode
        y = self._y
        f = dyn._rhs
        if self._k0 is None:
            self._k0 = f(y, V, mode)
            self.n_rhs += 1
        k1 = self._k0
        h = min(self._h, self.max_step)
        clipped = False
        if self._hold_changed and self._t + h > t_end:
            # the input has been changing: stop at the communication point instead of
            # integrating ahead a step that the next input change would throw away
            h, clipped = t_end - self._t, True
        rtol, atol = self.rtol, self.atol
        (a21,), (a31, a32), (a41, a42, a43), (a51, a52, a53, a54), (a61, a62, a63, a64, a65) = _A[1:]
        b1, _, b3, b4, b5, b6 = _B
        e1, _, e3, e4, e5, e6, e7 = _E
        while True:
            k2 = f([yy + h * a21 * q1 for yy, q1 in zip(y, k1)], V, mode)
            k3 = f([yy + h * (a31 * q1 + a32 * q2) for yy, q1, q2 in zip(y, k1, k2)], V, mode)
            k4 = f([yy + h * (a41 * q1 + a42 * q2 + a43 * q3) for yy, q1, q2, q3 in zip(y, k1, k2, k3)], V, mode)
            k5 = f([yy + h * (a51 * q1 + a52 * q2 + a53 * q3 + a54 * q4)
                    for yy, q1, q2, q3, q4 in zip(y, k1, k2, k3, k4)], V, mode)
            k6 = f([yy + h * (a61 * q1 + a62 * q2 + a63 * q3 + a64 * q4 + a65 * q5)
                    for yy, q1, q2, q3, q4, q5 in zip(y, k1, k2, k3, k4, k5)], V, mode)
            ynew = [yy + h * (b1 * q1 + b3 * q3 + b4 * q4 + b5 * q5 + b6 * q6)
                    for yy, q1, q3, q4, q5, q6 in zip(y, k1, k3, k4, k5, k6)]
            k7 = f(ynew, V, mode)
            self.n_rhs += 6
            err = 0.0
            for yy, yn, sc_a, q1, q3, q4, q5, q6, q7 in zip(y, ynew, atol, k1, k3, k4, k5, k6, k7):
                e = h * (e1 * q1 + e3 * q3 + e4 * q4 + e5 * q5 + e6 * q6 + e7 * q7)
                sc = sc_a + rtol * max(abs(yy), abs(yn))
                err += (e / sc) ** 2
            err = math.sqrt(err / len(y))
            if err <= 1.0:
                fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2))
                if not (clipped and fac * h < self._h):
                    self._h = h * fac
                break
            if not math.isfinite(err):
                h *= 0.1
            else:
                h *= max(0.1, 0.9 * err ** -0.2)
            clipped = False
            if h < 1e-14:
                raise ArithmeticError(f"step size underflow at t={self._t}: the model is not integrable here")
        t0 = self._t
        dense = [t0, h, y, (k1, k2, k3, k4, k5, k6, k7), mode, None]
        self.n_steps += 1
        # events
        p = dyn.p
        if mode == FREE and ynew[1] > p.r0:
            s = self._root(lambda s_: self._interp(dense, t0 + s_ * h)[1] - p.r0)
            tc = t0 + s * h
            yc = self._interp(dense, tc)
            yc[1], yc[2] = p.r0, 0.0
            self._dense = self._truncate(dense, s) if s > 0 else None
            self._t, self._y = tc, yc
            self._mode = CONTACT if dyn.net_contact_force(yc) >= 0.0 else FREE
            if self._mode == FREE:
                yc[1] = p.r0 * (1.0 - 1e-12)
            self._k0 = None
            return
        if mode == CONTACT and dyn.net_contact_force(ynew) < 0.0:
            s = self._root(lambda s_: -dyn.net_contact_force(self._interp(dense, t0 + s_ * h)))
            tc = t0 + s * h
            yc = self._interp(dense, tc)
            yc[1], yc[2] = p.r0, 0.0
            self._dense = self._truncate(dense, s) if s > 0 else None
            self._t, self._y, self._mode = tc, yc, FREE
            self._k0 = None
            return
        self._dense = dense
        self._t = t0 + h
        self._y = ynew
        self._k0 = k7

    @classmethod
    def _truncate(cls, dense, s):
        """Dense record restricted to the first fraction s of its step."""
        Q = cls._coeffs(dense)
        # y(t0 + u*(s h)) = y0 + h*sum Q_k (u s)^(k+1) = y0 + (s h) * sum (Q_k s^k) u^(k+1)
        Qs = [[row[0], row[1] * s, row[2] * s * s, row[3] * s ** 3] for row in Q]
        return [dense[0], s * dense[1], dense[2], None, dense[4], Qs]

    @staticmethod
    def _root(g, tol=1e-13):
        """Smallest s in (0, 1] with g(s) = 0 where g(0) < 0 <= g(1); bisection + secant."""
        lo, hi = 0.0, 1.0
        glo, ghi = g(lo), g(hi)
        if glo >= 0.0:
            return 0.0
        for _ in range(80):
            s = hi - ghi * (hi - lo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
            if not (lo < s < hi) or (hi - lo) > 0.5:
                s = 0.5 * (lo + hi) if not (lo < s < hi) else s
            gs = g(s)
            if gs >= 0.0:
                hi, ghi = s, gs
            else:
                lo, glo = s, gs
            if hi - lo < tol:
                break
        return hi


class ActuatorModel:
    """The paper's model with outputs; the FMU slave and the harness both use this class."""

    def __init__(self, params: Params, rtol: float = 1e-7, dynamics_cls=None):
        self.params = params.validated()
        if dynamics_cls is None:  # the plain Dynamics unless an effect is on
            from .effects import dynamics_class
            dynamics_cls = dynamics_class(params)
        self.dyn = dynamics_cls(params)
        self.integ = Integrator(self.dyn, rtol=rtol)

    def reset(self, t0: float = 0.0):
        self.integ.reset(t0)

    def advance(self, t_end: float, V: float):
        self.integ.advance(t_end, V)

    @property
    def t(self) -> float:
        return self.integ.t

    def outputs(self) -> dict:
        """Outputs at the view time: I [A], x [m], v [m/s], F [N], B [T], contact (bool),
        x_sensor [m], F_sensor [N] (the sensor readings: x and F unless sensor_lag is on)."""
        y, mode = self.integ.y, self.integ.mode
        dyn = self.dyn
        F = dyn.force(y, mode)
        xs, Fs = dyn.sensors(y, mode, F)
        return {
            "I": y[0], "x": y[1], "v": y[2],
            "F": F,
            "B": dyn.field_centre(y, mode),
            "contact": mode == CONTACT,
            "x_sensor": xs, "F_sensor": Fs,
        }


def simulate(params: Params, t, V, rtol: float = 1e-7, dynamics_cls=None) -> dict:
    """Simulate on the time grid t [s] with the voltage V [V] held constant over each interval.

    V[k] is applied on [t[k], t[k+1]) (zero-order hold, as a co-simulation master does).
    Returns arrays keyed by output name (see ``ActuatorModel.outputs``) plus "t".
    """
    t = np.asarray(t, dtype=float)
    V = np.broadcast_to(np.asarray(V, dtype=float), t.shape)
    model = ActuatorModel(params, rtol=rtol, dynamics_cls=dynamics_cls)
    model.reset(float(t[0]))
    keys = ("I", "x", "v", "F", "B", "contact", "x_sensor", "F_sensor")
    out = {k: np.empty(t.shape, dtype=bool if k == "contact" else float) for k in keys}
    o = model.outputs()
    for k in keys:
        out[k][0] = o[k]
    for i in range(1, len(t)):
        model.advance(float(t[i]), float(V[i - 1]))
        o = model.outputs()
        for k in keys:
            out[k][i] = o[k]
    out["t"] = t
    return out
