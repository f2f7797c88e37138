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
output, compiled with numba (``fmu_src.integrator``; the formulas it calls are the
functions of ``fmu_src.diaphragm``, ``fmu_src.effects`` and ``fmu_src.field``), so a
communication step costs about a microsecond. With the input held constant it
integrates past a communication point and interpolates; when the input changes it
restarts from the interpolated state at that point. Contact and release instants
are located on the dense output. The classes here are the Python API: they keep
parameters and state in preallocated float64 arrays and make one compiled call per
``advance`` and one per ``outputs``.
"""
from __future__ import annotations

import math

import numpy as np

from .params import Params
from .field import make_kernel
from .diaphragm import tangent_stiffness

FREE, CONTACT, BLOCKED = 0, 1, 2

_JIT = None


def _jit():
    """fmu_src.integrator (imported on first use: it imports fmu_src.effects, which imports this module)."""
    global _JIT
    if _JIT is None:
        from . import integrator
        assert (integrator.FREE, integrator.CONTACT, integrator.BLOCKED) == (FREE, CONTACT, BLOCKED)
        _JIT = integrator
    return _JIT


class Dynamics:
    """Right-hand sides and outputs of the paper's model for one parameter set.

    The numbers live in ``P`` (the parameter block of ``fmu_src.integrator``) and ``coef`` (the force
    kernel's table); the methods call the compiled functions of ``fmu_src.integrator``.
    """

    n_states = 3
    handles_effects = False   # True in fmu_src.effects.EffectDynamics
    # effect switches and state indices (EffectDynamics sets them)
    heat = sat = creep = edge = emf = lag = False
    iT = ixc = ixs = iFs = None

    def __init__(self, p: Params):
        self.p = p.validated()
        if not self.handles_effects:
            from .effects import active_effects  # lazy: fmu_src.effects imports this module
            if active_effects(p):
                raise ValueError(f"Dynamics is the paper's plain model; effects {list(active_effects(p))} are on: "
                                 "use fmu_src.effects.EffectDynamics (ActuatorModel picks it by default)")
        self.kernel = make_kernel(p.a, p.D, p.kB, p.r0)
        self.G = self.kernel  # callable: G(r) [T^2/(A^2.m)]
        self.coef = self.kernel.coef
        self.P = self._param_block()

    def _param_block(self) -> np.ndarray:
        J = _jit()
        p, k = self.p, self.kernel
        P = np.zeros(J.NP)
        for i, name in zip(range(J.P_R, J.P_KB + 1), ("R", "L", "Em", "r0", "K1", "K2", "C", "m", "a", "kB")):
            P[i] = getattr(p, name)
        for i, name in zip(range(J.P_RTH, J.P_TAUS + 1), ("Rth", "tau_th", "ksat", "Kc", "tau_c", "K5", "lam", "tau_s")):
            P[i] = getattr(p, name)
        for i, on in zip(range(J.F_HEAT, J.F_LAG + 1), (self.heat, self.sat, self.creep, self.edge, self.emf, self.lag)):
            P[i] = 1.0 if on else 0.0
        for i, idx in zip(range(J.I_T, J.I_FS + 1), (self.iT, self.ixc, self.ixs, self.iFs)):
            P[i] = -1.0 if idx is None else float(idx)
        P[J.K_SMAX], P[J.K_DR], P[J.K_INVDR], P[J.K_G0], P[J.K_DG0] = k._smax, k._dr, k._inv_dr, k.G0, k.dG0
        P[J.P_N] = self.n_states
        return P

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
        return [0.0] * self.n_states

    def scales(self) -> list:
        """Absolute-tolerance scales per state (A, m, m/s)."""
        p = self.p
        return [1e-3, 1e-3 * max(p.r0, 1e-3), 1e-2 * max(p.r0, 1e-3)]

    def _y(self, y) -> np.ndarray:
        y = np.asarray(y, dtype=np.float64)
        if y.shape != (self.n_states,):
            raise ValueError(f"state must have {self.n_states} entries {getattr(self, 'state_names', '')}, "
                             f"got shape {y.shape}")
        return np.ascontiguousarray(y)

    def magnetic_force(self, y, r: float) -> float:
        """Magnetic force [N] at the distance r [m] from the coil face for the current y[0]."""
        return _jit().force_at(self.P, self.coef, float(y[0]), float(r))

    def rhs(self, y, V: float, mode: int) -> list:
        """dy/dt for the state y [I, x, v, ...] under voltage V [V] in the given mode."""
        out = np.empty(self.n_states)
        _jit().rhs(self.P, self.coef, self._y(y), float(V), int(mode), out)
        return out.tolist()

    def net_contact_force(self, y) -> float:
        """Magnetic minus restoring force [N] with the diaphragm on the coil face (x = r0)."""
        return _jit().net_contact_force(self.P, self.coef, self._y(y))

    def outputs(self, y, mode: int) -> dict:
        """Outputs (see ``ActuatorModel.outputs``) of the state y in the given mode."""
        out = np.empty(8)
        _jit().outputs(self.P, self.coef, self._y(y), int(mode), out)
        return _output_dict(out)

    def force(self, y, mode: int) -> float:
        """Magnetic force on the diaphragm [N], attraction positive."""
        return self.magnetic_force(y, max(self.p.r0 - y[1], 0.0))


def _output_dict(out) -> dict:
    I, x, v, F, B, contact, xs, Fs = out.tolist()
    return {"I": I, "x": x, "v": v, "F": F, "B": B, "contact": contact != 0.0, "x_sensor": xs, "F_sensor": Fs}


class Integrator:
    """Adaptive DP5(4) integrator with contact/release events and input-hold semantics.

    ``advance(t_end, V)`` moves the view time to t_end with the voltage V held
    since the previous call; ``y`` and ``mode`` give the state at the view time.
    The work is ``fmu_src.integrator.advance`` (compiled) on the arrays ``S`` (parameters and
    integrator scalars) and ``W`` (state rows: front, stages, dense record, view).
    """

    def __init__(self, dyn: Dynamics, rtol: float = 1e-7, max_step: float = 0.05, t0: float = 0.0):
        if not (rtol > 0 and math.isfinite(rtol)):
            raise ValueError(f"parameter rtol must be > 0 and finite, got {rtol!r}")
        J = _jit()
        self.dyn = dyn
        self.rtol = float(rtol)
        self.atol = [self.rtol * s for s in dyn.scales()]
        self.max_step = min(float(max_step), dyn.stability_step())
        n = dyn.n_states
        self.S = np.zeros(J.NS)
        self.S[:J.NP] = dyn.P
        self.S[J.P_RTOL] = self.rtol
        self.S[J.P_MAXSTEP] = self.max_step
        self.S[J.P_ATOL:J.P_ATOL + n] = self.atol
        self.W = np.zeros((J.NW, n))
        self.coef = dyn.coef
        self._out = np.empty(8)
        self._advance = J.advance
        self._view_outputs = J.view_outputs
        self.reset(t0)

    # -- state ---------------------------------------------------------------
    def reset(self, t0: float = 0.0, y0=None):
        J, dyn, S, W = _jit(), self.dyn, self.S, self.W
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
        S[J.NP:] = 0.0
        S[J.S_T] = S[J.S_TF] = self.t
        S[J.S_MODE] = S[J.S_VMODE] = mode
        S[J.S_V] = math.nan           # no input held yet: the first advance starts the integration
        S[J.S_CHANGED] = 1.0
        S[J.S_H] = 1e-4
        W[:] = 0.0
        W[J.W_Y] = y
        W[J.W_VIEW] = y

    # -- public --------------------------------------------------------------
    def advance(self, t_end: float, V: float):
        """Integrate to t_end [s] with the input voltage V [V] held constant since ``self.t``."""
        if t_end < self.t - 1e-15:
            raise ValueError(f"cannot integrate backwards from t={self.t} to t={t_end}")
        if self._advance(self.S, self.W, self.coef, float(t_end), float(V)):
            raise ArithmeticError(f"step size underflow at t={self.S[_jit().S_TF]}: "
                                  "the model is not integrable here")
        self.t = t_end

    @property
    def y(self) -> list:
        """State [I, x, v, ...] at the view time ``t``."""
        return self.W[_jit().W_VIEW].tolist()

    @property
    def mode(self) -> int:
        """FREE, CONTACT or BLOCKED at the view time ``t``."""
        return int(self.S[_jit().S_VMODE])

    @property
    def n_steps(self) -> int:
        return int(self.S[_jit().S_NSTEPS])

    @property
    def n_rhs(self) -> int:
        return int(self.S[_jit().S_NRHS])

    def outputs(self) -> dict:
        """Outputs at the view time (see ``ActuatorModel.outputs``): one compiled call."""
        self._view_outputs(self.S, self.W, self.coef, self._out)
        return _output_dict(self._out)


class ActuatorModel:
    """The paper's model with outputs; the FMU slave and the harness both use this class."""

    def __init__(self, params: Params, rtol: float = 1e-7, dynamics_cls=None):
        self.params = params.validated()
        if dynamics_cls is None:  # the plain Dynamics unless an effect is on
            from .effects import dynamics_class
            dynamics_cls = dynamics_class(params)
        self.dyn = dynamics_cls(params)
        self.integ = Integrator(self.dyn, rtol=rtol)
        # advance(t_end, V): integrate to t_end [s] with the voltage V [V] held since t (Integrator.advance,
        # bound here: one Python call less per communication step)
        self.advance = self.integ.advance

    def reset(self, t0: float = 0.0):
        self.integ.reset(t0)

    @property
    def t(self) -> float:
        return self.integ.t

    def outputs(self) -> dict:
        """Outputs at the view time: I [A], x [m], v [m/s], F [N], B [T], contact (bool),
        x_sensor [m], F_sensor [N] (the sensor readings: x and F unless sensor_lag is on)."""
        return self.integ.outputs()

    # -- state save/restore (the FMU's fmi2GetFMUstate / fmi2SetFMUstate) ------------------------------------
    def get_state(self) -> dict:
        """A copy of everything that determines this model's future: the parameters, rtol, the dynamics class,
        the view time and the integrator's arrays S (parameter block, integrator scalars: front time, mode,
        held input, step size, dense-output record) and W (state rows: front, stages, dense record, view; the
        effect and sensor states are columns of these rows). ``set_state`` / ``from_state`` restore it."""
        return {"params": self.params.as_dict(), "rtol": self.integ.rtol, "dynamics": type(self.dyn).__name__,
                "t": self.integ.t, "S": self.integ.S.copy(), "W": self.integ.W.copy()}

    def set_state(self, state: dict) -> None:
        """Restore a ``get_state`` of a model with the same parameters, rtol and dynamics class (in place: no
        re-initialization); raises ValueError (naming what differs) otherwise, leaving this model unchanged."""
        if state.get("params") != self.params.as_dict():
            raise ValueError("the state has other parameters than this model")
        if state.get("rtol") != self.integ.rtol or state.get("dynamics") != type(self.dyn).__name__:
            raise ValueError("the state has another rtol or dynamics class than this model")
        S = np.asarray(state.get("S"), dtype=np.float64)
        W = np.asarray(state.get("W"), dtype=np.float64)
        if S.shape != self.integ.S.shape or W.shape != self.integ.W.shape:
            raise ValueError(f"the state's arrays have shapes {S.shape}, {W.shape}; this model's are "
                             f"{self.integ.S.shape}, {self.integ.W.shape}")
        if not np.array_equal(S[:_jit().NP], self.integ.S[:_jit().NP]):
            raise ValueError("the state's parameter block differs from this model's")
        t = float(state.get("t"))
        self.integ.S[:] = S   # in place: the compiled advance holds no other reference
        self.integ.W[:] = W
        self.integ.t = t

    @classmethod
    def from_state(cls, state: dict) -> "ActuatorModel":
        """A new model in the state ``state`` (a ``get_state``); raises ValueError for an unusable state."""
        try:
            params = Params(**state["params"])
            rtol = float(state["rtol"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"the state does not describe a model: {exc}") from None
        model = cls(params, rtol=rtol)
        model.set_state(state)
        return model


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


def compile_all() -> None:
    """Compile (or load from numba's cache) every compiled entry point the classes here call.

    ``build_fmu.py`` runs this on the FMU's staged copy of ``fmu_src`` so that the FMU ships the
    cache (resources/fmu_src/__pycache__/*.nbi, *.nbc) and a freshly extracted FMU starts without
    compiling. One set of compiled functions serves every parameter set and effect combination.
    """
    from .effects import EffectDynamics
    p = Params()
    on = dict(Rth=8.0, tau_th=0.5, ksat=3.0, Kc=8.0, tau_c=0.3, K5=1e9, lam=0.3, tau_s=0.005)
    for q, cls in ((p, Dynamics), (p.with_(r0=0.002, **on), EffectDynamics)):
        model = ActuatorModel(q, dynamics_cls=cls)
        model.reset(0.0)
        model.advance(1e-3, 11.9)
        model.outputs()
        dyn, y = model.dyn, model.integ.y
        dyn.rhs(y, 11.9, FREE)
        dyn.net_contact_force(y)
        dyn.outputs(y, FREE)
        dyn.force(y, FREE)
