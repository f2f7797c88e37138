"""Time integration of the actuator: RL coil + loop field + force kernel + Duffing diaphragm.

State y = [I (A), x (m), v (m/s), *effect states]; the effect states and terms
(``EffectDynamics``, equations in ``fmu_src.effects``) are there only when an effect is switched on,
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

from . import effects, integrator as J
from .field import force_kernel, make_kernel
from .specs import BASE_STATES, BLOCK, EFFECTS, MU0, Params, active_effects
from .terms import LAG_STATES, LAGS, active_terms, lags_in_use

FREE, CONTACT, BLOCKED = J.FREE, J.CONTACT, J.BLOCKED
MAX_STEPS_PER_ADVANCE = 500_000   # internal steps one advance (one FMU doStep) may take before StepLimitError
MIN_TIME_SCALE_S = 1e-9           # shortest time scale [s] of the model that check_integrable accepts
MAX_TIME_SCALE_S = 1e5            # longest (about a day) of the coil's, the diaphragm's and the effects'
MAX_FACE_TRACTION = 1.0           # largest force at the coil face per B^2/(2*mu0)*pi*D^2/4 (see check_integrable)
R0_MAX_PER_A = 60.0               # largest gap r0 per coil radius a that the force-kernel table resolves


class StepLimitError(RuntimeError):
    """One advance needed more than its cap of internal steps (``MAX_STEPS_PER_ADVANCE``)."""


def state_names(on) -> tuple:
    """Names of the state vector y with the effects ``on`` (names) switched on: I, x, v, then the states of
    those effects in catalogue order (``fmu_src.specs.EFFECTS``), then, if "terms" is in ``on`` (any term of
    ``fmu_src.terms`` on), every lag state of the term set (``fmu_src.terms.LAG_STATES``)."""
    return (BASE_STATES + tuple(s for e in EFFECTS if e in on for s in EFFECTS[e].states)
            + (LAG_STATES if "terms" in on else ()))


def switched_on(p) -> tuple:
    """The effects on in the Params p (``active_effects``), plus "terms" if any term of the term set is on."""
    return active_effects(p) + (("terms",) if active_terms(p) else ())


def block_head(params) -> list:
    """The head of the parameter block (``fmu_src.specs.BLOCK``) that the whole-model functions of
    ``fmu_src.effects`` (``rates``, ``force``, ``contact_force``, ``sensor_readings``, ``stability_step``)
    take, for a sequence of Params with the same effects on.

    For one Params: a list of floats. For several: each parameter a float64 array (one value per run),
    each effect switch (1.0/0.0) and effect state index (position in y, -1.0 when off) a float, for the
    array form of those functions (states y of shape (n_states, runs)). The term set's switch (1.0 while a
    term is on), its lag switches (1.0 where a term with a nonzero coefficient uses the lag; an array for
    several runs) and lag-state indices likewise. ``ValueError`` if the runs do not all have the same effects
    (and the term set) on.
    """
    params = list(params)
    on = {switched_on(p) for p in params}
    if len(on) != 1:
        raise ValueError(f"block_head: the runs must have the same effects on, got {sorted(on)}")
    on = on.pop()
    index = {n: i for i, n in enumerate(state_names(on))}
    head = [0.0] * BLOCK.size
    for name, i in BLOCK.param.items():
        head[i] = float(getattr(params[0], name)) if len(params) == 1 else \
            np.array([getattr(p, name) for p in params], dtype=float)
    for name, i in BLOCK.switch.items():
        head[i] = 1.0 if name in on else 0.0
    for name, i in BLOCK.state.items():
        head[i] = float(index.get(name, -1))
    head[BLOCK.terms] = 1.0 if "terms" in on else 0.0
    for name, i in BLOCK.lag_on.items():
        used = [1.0 if name in lags_in_use(p) else 0.0 for p in params]
        head[i] = used[0] if len(params) == 1 else np.array(used)
    for name, i in BLOCK.lag_state.items():
        head[i] = float(index.get(name, -1))
    return head


def check_integrable(p: Params) -> None:
    """Refuse parameters that are valid one by one but physically absurd together: ``ValueError`` naming them.

    The one check that every way in goes through: the FMU's fmi2ExitInitializationMode, ``mpc-actuator build``
    (its parameters and --gap-mm) and every parameter file the harness reads (``harness.jobs.load_params_file``).

    * r0 > ``R0_MAX_PER_A``*a - 0.01 m: the force-kernel table (1201 points on [0, 2*r0 + 20 mm]) would not
      resolve the field, which varies on the scale of the coil radius a;
    * a time scale of the model shorter than ``MIN_TIME_SCALE_S`` (far below anything an actuator does, and
      too close to the integrator's floor ``fmu_src.integrator.H_MIN``): the coil's L/R, the diaphragm's
      sqrt(m/K2), sqrt(m/(3*K1*r0^2 + K2)) and m/C (unless blocked), and the time constants [s] of the
      effects that are on;
    * a time scale longer than ``MAX_TIME_SCALE_S`` = 1e5 s (about a day): the coil's L/R, the diaphragm's
      sqrt(m/K2) (unless blocked) and the effects' time constants. The rig's tests last seconds (coil L/R
      ~ 8 ms, diaphragm periods ~ 10 ms, effect time constants 5 ms to 4 s; a large coil's thermal time
      constant is minutes to an hour): a dynamics slower than a day is a unit slip (ms given as s, H as uH),
      not an actuator. m/C is not bounded above: a lightly damped diaphragm (C -> 0) is physical;
    * a magnetic force at the coil face beyond what any magnetic field can pull: the traction of a field B on
      a body of area A is at most B^2/(2*mu0)*A (Maxwell stress on an ideal, infinitely permeable pole face;
      e.g. 633 N for B = 1 T on the 45 mm diaphragm). The model's force at the coil face at the current that
      gives the field B there is Em*(B/kB)^2*G(0), also proportional to B^2, so the ratio
      Em*G(0)/kB^2 / (pi*D^2/(8*mu0)) does not depend on the current and depends on Em, a and D only (G scales
      with kB^2). It must not exceed ``MAX_FACE_TRACTION`` = 1: the diaphragm sees at most the coil-face field,
      over at most its own area. The virtual rig's samples (5-35 wt%, 20-70 mm; ``harness.data.rig``) and the
      paper's defaults lie below 0.02, so identified parameters of real diaphragms are far from the bound;
      Em = 1e30 N.m/T^2 is 1.6e29 times beyond it.

    Parameters
    ----------
    p : Params
        The parameters to check.

    Examples
    --------
    >>> check_integrable(Params())
    >>> check_integrable(Params(L=1e-9))     # L/R = 67 ps: a unit slip
    Traceback (most recent call last):
    ...
    ValueError: time scale(s) L/R (parameters L, R) = 6.67e-11 s below ...
    """
    r0_max = R0_MAX_PER_A * p.a - 0.01
    if p.r0 > r0_max:
        raise ValueError(f"parameter r0 [m] = {p.r0!r} is too large for the coil radius a = {p.a!r} m: the "
                         f"force-kernel table resolves gaps up to {R0_MAX_PER_A:g}*a - 0.01 m = {r0_max:.6g} m")
    scales = {"L/R (parameters L, R)": p.L / p.R}
    if not p.blocked:
        scales["sqrt(m/K2) (parameters m, K2)"] = math.sqrt(p.m / p.K2)
        scales["sqrt(m/(3*K1*r0^2 + K2)) (parameters m, K1, r0, K2)"] = math.sqrt(p.m / (3 * p.K1 * p.r0 ** 2 + p.K2))
        if p.C > 0.0:
            scales["m/C (parameters m, C)"] = p.m / p.C
    for e in active_effects(p):
        scales.update({f"{s.name} (parameter {s.name})": getattr(p, s.name) for s in EFFECTS[e].param_specs
                       if s.unit == "s"})
    for g in lags_in_use(p):
        if LAGS[g].first_order:
            scales[f"tau_{g} (parameter tau_{g})"] = getattr(p, f"tau_{g}")
        elif not p.blocked:   # a lag with its own rate (Dahl): the presliding spring's period
            k = float(effects.presliding_stiffness(block_head([p])))
            if k > 0.0:
                scales[f"sqrt(m/k_presliding) (parameters m, tau_{g})"] = math.sqrt(p.m / k)
    short = [f"{name} = {value:.3g} s" for name, value in scales.items() if not value >= MIN_TIME_SCALE_S]
    if short:
        raise ValueError(f"time scale(s) {', '.join(short)} below {MIN_TIME_SCALE_S:g} s: physically absurd "
                         f"parameters (the integrator's smallest step is {J.H_MIN:g} s)")
    long = [f"{name} = {value:.3g} s" for name, value in scales.items()
            if not name.startswith(("m/C", "sqrt(m/(3")) and not value <= MAX_TIME_SCALE_S]
    if long:
        raise ValueError(f"time scale(s) {', '.join(long)} above {MAX_TIME_SCALE_S:g} s (about a day): physically "
                         f"absurd parameters (a unit slip?)")
    g0 = float(force_kernel(0.0, p.a, p.D, 1.0)[0])          # G(0)/kB^2 [1/m]
    area = math.pi * p.D ** 2 / 4.0
    ratio = p.Em * g0 / (area / (2.0 * MU0))
    if not ratio <= MAX_FACE_TRACTION:
        raise ValueError(
            f"parameters Em = {p.Em:.6g} N.m/T2, a = {p.a:.6g} m, D = {p.D:.6g} m: the magnetic force at the coil "
            f"face, {p.Em * g0:.3g} N at a coil-face field of 1 T, is {ratio:.3g} times the most a 1 T field can "
            f"pull on the diaphragm's area (B^2/(2*mu0)*pi*D^2/4 = {area / (2.0 * MU0):.3g} N; the ratio does not "
            f"depend on the current): physically absurd parameters")


class Dynamics:
    """Right-hand sides and outputs of the paper's model for one parameter set.

    The numbers live in ``P`` (the parameter block of ``fmu_src.integrator``) and ``coef`` (the force
    kernel's table); the methods call the compiled functions of ``fmu_src.integrator``.
    """

    handles_effects = False   # True in EffectDynamics

    def __init__(self, p: Params):
        self.p = p.validated()
        on = active_effects(p)
        self.terms = bool(active_terms(p))
        if (on or self.terms) and not self.handles_effects:
            raise ValueError(f"Dynamics is the paper's plain model; effects {list(on) + list(active_terms(p))} are "
                             "on: use fmu_src.model.EffectDynamics (ActuatorModel picks it by default)")
        self.on = on
        self.state_names = state_names(on + (("terms",) if self.terms else ()))
        self.n_states = len(self.state_names)
        self.index = {n: i for i, n in enumerate(self.state_names)}   # state name -> position in y
        self.kernel = make_kernel(p.a, p.D, p.kB, p.r0)
        self.coef = self.kernel.coef
        if not (np.all(np.isfinite(self.coef)) and math.isfinite(self.kernel.G0) and math.isfinite(self.kernel.dG0)):
            raise ValueError(f"parameters a = {p.a!r} m, D = {p.D!r} m, kB = {p.kB!r} T/A, r0 = {p.r0!r} m give a "
                             "non-finite force kernel")
        self.P = self._param_block()

    def _param_block(self) -> np.ndarray:
        k = self.kernel
        P = np.zeros(J.NP)
        P[:BLOCK.size] = block_head([self.p])
        P[J.K_SMAX], P[J.K_DR], P[J.K_INVDR], P[J.K_G0], P[J.K_DG0] = k.smax, k.dr, k.inv_dr, k.G0, k.dG0
        P[J.P_N] = self.n_states
        return P

    def stability_step(self) -> float:
        """Largest step [s] inside DP5's real-axis stability region for every mode
        (``fmu_src.effects.stability_step``)."""
        return effects.stability_step(self.P, self.p.blocked)

    def initial_state(self) -> list:
        return [0.0] * self.n_states

    def scales(self) -> list:
        """Absolute-tolerance scales per state (A, m, m/s, then each effect state's: ``StateSpec.atol_scale``,
        or the displacement's)."""
        p = self.p
        sc = [1e-3, 1e-3 * max(p.r0, 1e-3), 1e-2 * max(p.r0, 1e-3)]
        for e in self.on:
            sc += [sc[1] if s.atol_scale is None else s.atol_scale for s in EFFECTS[e].state_specs]
        if getattr(self, "terms", False):
            sc += [g.atol_scale for g in LAGS.values()]
        return sc

    def _y(self, y) -> np.ndarray:
        y = np.asarray(y, dtype=np.float64)
        if y.shape != (self.n_states,):
            raise ValueError(f"state must have {self.n_states} entries {self.state_names}, got shape {y.shape}")
        return np.ascontiguousarray(y)

    def magnetic_force(self, y, r: float) -> float:
        """Magnetic force [N] at the distance r [m] from the coil face for the current y[0]."""
        return J.force_at(self.P, self.coef, float(y[0]), float(r))

    def rhs(self, y, V: float, mode: int) -> list:
        """dy/dt for the state y [I, x, v, ...] under voltage V [V] in the given mode."""
        out = np.empty(self.n_states)
        J.rhs(self.P, self.coef, self._y(y), float(V), int(mode), out)
        return out.tolist()

    def net_contact_force(self, y) -> float:
        """Magnetic minus restoring force [N] with the diaphragm on the coil face (x = r0)."""
        return J.net_contact_force(self.P, self.coef, self._y(y))

    def outputs(self, y, mode: int) -> dict:
        """Outputs (see ``ActuatorModel.outputs``) of the state y in the given mode."""
        out = np.empty(8)
        J.outputs(self.P, self.coef, self._y(y), int(mode), out)
        return _output_dict(out)

    def force(self, y, mode: int) -> float:
        """Magnetic force on the diaphragm [N], attraction positive."""
        return self.magnetic_force(y, max(self.p.r0 - y[1], 0.0))

    # transition aliases (generic: ``on``, ``index``) for the callers of the former per-effect attributes;
    # kept until the parallel branches of the restructuring are merged
    heat = property(lambda self: "coil_heating" in self.on)
    creep = property(lambda self: "viscoelastic_creep" in self.on)
    lag = property(lambda self: "sensor_lag" in self.on)
    iT = property(lambda self: self.index.get("dT"))
    ixc = property(lambda self: self.index.get("xc"))


class EffectDynamics(Dynamics):
    """The paper's model plus the effects switched on in the parameters (``fmu_src.effects``; the
    compiled integrator selects the terms from the switches in the parameter block).

    State y = [I, x, v] followed by the states of the effects that are on, in catalogue order
    (``fmu_src.specs.EFFECTS``): dT [K] (coil_heating), xc [m] (viscoelastic_creep), x_sensor [m] and
    F_sensor [N] (sensor_lag); ``state_names``, ``index``.
    """

    handles_effects = True


def dynamics_class(p: Params):
    """The plain ``Dynamics`` when every effect and term is off, else ``EffectDynamics``."""
    return EffectDynamics if switched_on(p) else Dynamics


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

    def __init__(self, dyn: Dynamics, rtol: float = 1e-7, max_step: float = 0.05, t0: float = 0.0,
                 max_steps: int = MAX_STEPS_PER_ADVANCE):
        if not (rtol > 0 and math.isfinite(rtol)):
            raise ValueError(f"parameter rtol must be > 0 and finite, got {rtol!r}")
        self.dyn = dyn
        self.max_steps = int(max_steps)
        self.rtol = float(rtol)
        self.atol = [self.rtol * s for s in dyn.scales()]
        self.max_step = float(min(float(max_step), dyn.stability_step()))
        n = dyn.n_states
        self.S = np.zeros(J.NS)
        self.S[:J.NP] = dyn.P
        self.S[J.P_RTOL] = self.rtol
        self.S[J.P_MAXSTEP] = self.max_step
        self.S[J.P_MAXSTEPS] = self.max_steps
        self.S[J.P_ATOL:J.P_ATOL + n] = self.atol
        self.W = np.zeros((J.NW, n))
        self.coef = dyn.coef
        self._out = np.empty(8)
        self._advance = J.advance
        self._view_outputs = J.view_outputs
        self.reset(t0)

    # -- state ---------------------------------------------------------------
    def reset(self, t0: float = 0.0, y0=None):
        dyn, S, W = self.dyn, self.S, self.W
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
        status = self._advance(self.S, self.W, self.coef, float(t_end), float(V))
        if status == J.TOO_MANY_STEPS:
            raise StepLimitError(f"more than {self.max_steps} internal steps from t={self.t!r} s toward "
                                 f"t={t_end!r} s (reached t={float(self.S[J.S_TF])!r} s; step bound {self.max_step!r} s): "
                                 "the step is too long for the model's time scales")
        if status:
            raise ArithmeticError(f"step size underflow at t={self.S[J.S_TF]}: "
                                  "the model is not integrable here")
        self.t = t_end

    @property
    def y(self) -> list:
        """State [I, x, v, ...] at the view time ``t``."""
        return self.W[J.W_VIEW].tolist()

    @property
    def mode(self) -> int:
        """FREE, CONTACT or BLOCKED at the view time ``t``."""
        return int(self.S[J.S_VMODE])

    def outputs(self) -> dict:
        """Outputs at the view time (see ``ActuatorModel.outputs``): one compiled call."""
        self._view_outputs(self.S, self.W, self.coef, self._out)
        return _output_dict(self._out)


class ActuatorModel:
    """The paper's model with outputs; the FMU slave and the harness both use this class.

    Parameters
    ----------
    params : Params
        The model's parameters (SI units), validated here.
    rtol : float
        Relative tolerance of the integrator (the FMU's ``rtol``).
    dynamics_cls : type or None
        The right-hand side (None: the plain dynamics, or the effects' when an effect is on).

    Examples
    --------
    Stepped like a co-simulation master steps the FMU: ``advance(t_end, V)`` holds V [V] up to t_end [s].

    >>> from fmu_src.specs import Params
    >>> model = ActuatorModel(Params(blocked=True))
    >>> model.reset(0.0)
    >>> for k in range(1, 101):
    ...     model.advance(k * 1e-3, 15.0)
    >>> print(f"t = {model.t:.3f} s, I = {model.outputs()['I']:.4f} A")   # 12.5 L/R: the steady V/R = 1 A
    t = 0.100 s, I = 1.0000 A
    """

    def __init__(self, params: Params, rtol: float = 1e-7, dynamics_cls=None):
        self.params = params.validated()
        if dynamics_cls is None:  # the plain Dynamics unless an effect is on
            dynamics_cls = dynamics_class(params)
        self.dyn = dynamics_cls(params)
        self.integ = Integrator(self.dyn, rtol=rtol)
        # advance(t_end, V): integrate to t_end [s] with the voltage V [V] held since t (Integrator.advance,
        # bound here: one Python call less per communication step)
        self.advance = self.integ.advance

    def reset(self, t0: float = 0.0):
        """Start again at rest (I = x = v = 0, effect states at their rest values) at the time t0.

        Parameters
        ----------
        t0 : float
            Start time [s].
        """
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
        re-initialization); raises ValueError (naming what differs) otherwise, leaving this model unchanged.

        Parameters
        ----------
        state : dict
            What :meth:`get_state` returned.
        """
        if state.get("params") != self.params.as_dict():
            raise ValueError("the state has other parameters than this model")
        if state.get("rtol") != self.integ.rtol or state.get("dynamics") != type(self.dyn).__name__:
            raise ValueError("the state has another rtol or dynamics class than this model")
        S = np.asarray(state.get("S"), dtype=np.float64)
        W = np.asarray(state.get("W"), dtype=np.float64)
        if S.shape != self.integ.S.shape or W.shape != self.integ.W.shape:
            raise ValueError(f"the state's arrays have shapes {S.shape}, {W.shape}; this model's are "
                             f"{self.integ.S.shape}, {self.integ.W.shape}")
        if not np.array_equal(S[:J.NP], self.integ.S[:J.NP]):
            raise ValueError("the state's parameter block differs from this model's")
        t = float(state.get("t"))
        check_restored_state(S, W, t, self.params.r0)
        self.integ.S[:] = S   # in place: the compiled advance holds no other reference
        self.integ.W[:] = W
        self.integ.t = t

    @classmethod
    def from_state(cls, state: dict) -> "ActuatorModel":
        """A new model in the state ``state`` (a ``get_state``); raises ValueError for an unusable state.

        Parameters
        ----------
        state : dict
            What :meth:`get_state` returned.
        """
        try:
            params = Params(**state["params"])
            rtol = float(state["rtol"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"the state does not describe a model: {exc}") from None
        model = cls(params, rtol=rtol)
        model.set_state(state)
        return model


_SCALARS = {J.S_T: "view time", J.S_TF: "front time", J.S_MODE: "mode", J.S_V: "held input V",
            J.S_CHANGED: "input-changed flag", J.S_K0: "FSAL flag", J.S_H: "step size", J.S_DENSE: "dense flag",
            J.S_DT0: "dense start time", J.S_DH: "dense step", J.S_DMODE: "dense mode", J.S_VMODE: "view mode"}


def check_restored_state(S: np.ndarray, W: np.ndarray, t: float, r0: float) -> None:
    """Refuse integrator arrays that no run of the model can produce (a forged or damaged state whose checksum
    is valid): ``ValueError`` naming the field. The time t and every integrator scalar finite (the held input
    may be NaN: none yet), t equal to the view time, the front not behind the view, the modes FREE, CONTACT or
    BLOCKED, the step size >= 0, every state row finite, and the displacement x <= r0 at the front and at the
    view (the diaphragm never passes the coil face)."""
    if not math.isfinite(t):
        raise ValueError(f"the state's time t = {t!r} is not finite")
    for i, name in _SCALARS.items():
        v = float(S[i])
        if not (math.isfinite(v) or (i == J.S_V and math.isnan(v))):
            raise ValueError(f"the state's {name} = {v!r} is not finite")
    if S[J.S_T] != t:
        raise ValueError(f"the state's time t = {t!r} differs from its view time {float(S[J.S_T])!r}")
    if not S[J.S_TF] >= S[J.S_T]:
        raise ValueError(f"the state's front time {float(S[J.S_TF])!r} is behind its view time {t!r}")
    for i in (J.S_MODE, J.S_VMODE, J.S_DMODE):
        if S[i] not in (FREE, CONTACT, BLOCKED):
            raise ValueError(f"the state's {_SCALARS[i]} = {float(S[i])!r} is not a mode (0 free, 1 contact, "
                             f"2 blocked)")
    if not S[J.S_H] >= 0.0:
        raise ValueError(f"the state's step size = {float(S[J.S_H])!r} is negative")
    bad = np.argwhere(~np.isfinite(W))
    if bad.size:
        row, col = (int(v) for v in bad[0])
        raise ValueError(f"the state's row {row}, state {col} = {float(W[row, col])!r} is not finite")
    for row, where in ((J.W_Y, "front"), (J.W_VIEW, "view")):
        x = float(W[row, 1])
        if not x <= r0:
            raise ValueError(f"the state's displacement x = {x!r} m at the {where} is beyond the coil face r0 = "
                             f"{r0!r} m")


def simulate(params: Params, t, V, rtol: float = 1e-7, dynamics_cls=None) -> dict:
    """Simulate on the time grid t [s] with the voltage V [V] held constant over each interval.

    V[k] is applied on [t[k], t[k+1]) (zero-order hold, as a co-simulation master does).

    Parameters
    ----------
    params : Params
        The model's parameters (SI units; effects off when their parameters are 0).
    t : array_like
        Increasing time grid [s]; the state starts at rest (I = x = v = 0) at t[0].
    V : float or array_like
        Coil voltage [V]: one value, or one per time of ``t`` (V[k] held on [t[k], t[k+1])).
    rtol : float
        Relative tolerance of the integrator (the FMU's ``rtol``).
    dynamics_cls : type or None
        The right-hand side (None: :func:`dynamics_class` of ``params``).

    Returns
    -------
    dict
        Arrays on ``t`` keyed by output name: "I" [A], "x" [m], "v" [m/s], "F" [N], "B" [T], "contact",
        "x_sensor" [m], "F_sensor" [N], plus "t".

    Examples
    --------
    Blocked (the force-transducer mode: the diaphragm held at the gap r0), a 15 V step drives the current as
    I(t) = V/R (1 - exp(-t R/L)), time constant L/R = 0.12 H / 15 Ohm = 8 ms, and the on-axis field of the
    single-loop coil of radius a at the gap r0 is B = kB I a^3 / (a^2 + r0^2)^(3/2):

    >>> import numpy as np
    >>> from fmu_src.specs import Params
    >>> p = Params(blocked=True)
    >>> out = simulate(p, [0.0, 0.008, 0.1], V=15.0)
    >>> print(f"{out['I'][1]:.4f} {1.0 * (1 - np.exp(-1)):.4f}")      # one time constant: 1 - 1/e of V/R [A]
    0.6321 0.6321
    >>> print(f"{out['I'][2]:.4f}")                                   # 12.5 time constants: V/R [A]
    1.0000
    >>> print(f"{out['B'][2]:.4f} {p.kB * 1.0 * p.a**3 / (p.a**2 + p.r0**2) ** 1.5:.4f}")   # [T]
    0.1828 0.1828
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
