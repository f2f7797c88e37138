"""FMI 2.0 co-simulation slave of the displacement controller (built with pythonfmu: ``build_fmu.py --controller``).

Inputs x_ref [m] (displacement setpoint) and x_meas [m] (measured displacement); output V [V] (the coil
voltage, to connect to the actuator FMU's input V). A PID with static-inverse feed-forward, voltage limits
and back-calculation anti-windup, in discrete time with the communication step h:

    e      = x_ref - x_meas
    V_ff   = static inverse of the model at min(x_ref, x_holdable) (``fmu_src.statics``; 0 when feedforward = false;
             x_holdable: the largest displacement a voltage up to V_max holds, so that a saturating or heating
             model limits the range instead of failing)
    D      = -Kd*(x_meas - x_f)/Tf           (derivative on the measurement through a first-order filter Tf)
    u      = V_ff + Kp*e + q + D,   V = min(max(u, V_min), V_max)
    doStep: q += h*(Ki*e + (V - u)/Tt),  x_f += (1 - exp(-h/Tf))*(x_meas - x_f)

V is a direct function of the inputs at the communication point (direct feedthrough: set x_ref and x_meas,
read V, then doStep integrates the controller's states q [V] and x_f [m] over the step). Tt = 0 turns the
back-calculation off (plain integration, the integrator winds up). The feed-forward uses the model's
parameters, which the controller FMU has under the actuator's names (a, r0, ..., effect parameters); the
gains come from ``harness.control.tuning`` (linearization of the same model). Voltages are >= 0 by
default (V_min = 0): the force goes with I^2, so a negative voltage would attract again.

Errors follow the actuator's convention (``fmu_src.mpc_actuator``): a recoverable error (invalid parameter)
is logged at error status; through the status shim the call then returns fmi2Error.
"""
import json
import math
import os

import numpy as np
from pythonfmu import Boolean, DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real

import fmu_src

# Several pythonfmu FMUs in one process share one interpreter and so one ``fmu_src`` package: the first FMU
# instantiated provides it (e.g. the actuator FMU, which does not ship ``statics``): look in this FMU's copy too.
_OWN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fmu_src")
if os.path.isdir(_OWN) and _OWN not in list(fmu_src.__path__):
    fmu_src.__path__.append(_OWN)

from fmu_src.slave_status import StatusShimErrors  # noqa: E402
from fmu_src.specs import EFFECT_SPECS, SPECS, Params, validate  # noqa: E402
from fmu_src.statics import feedforward_table  # noqa: E402

# (name, unit, default, description) of the controller's own parameters, in value-reference order
GAINS = (
    ("Kp", "V/m", 6000.0, "Proportional gain on e = x_ref - x_meas"),
    ("Ki", "V/m.s", 3.0e5, "Integral gain on e"),
    ("Kd", "V.s/m", 0.0, "Derivative gain on the filtered measurement (derivative on measurement)"),
    ("Tf", "s", 0.002, "Time constant of the derivative's first-order filter (> 0)"),
    ("Tt", "s", 0.01, "Tracking time constant of the back-calculation anti-windup (0 = no anti-windup)"),
    ("V_min", "V", 0.0, "Lower voltage limit"),
    ("V_max", "V", 30.0, "Upper voltage limit (>= V_min)"),
)


class MpcController(StatusShimErrors, Fmi2Slave):
    """Displacement controller of the MPC diaphragm actuator: PID + static-inverse feed-forward."""

    author = "mpc-actuator"
    description = ("Displacement controller for the MPC diaphragm actuator: PID with static-inverse "
                   "feed-forward, voltage limits and anti-windup (SI units)")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "mpc_controller"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=0.001)
        self.x_ref = 0.0
        self.x_meas = 0.0
        for name, desc in (("x_ref", "Displacement setpoint (toward the coil)"),
                           ("x_meas", "Measured displacement (toward the coil)")):
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous, description=desc))
        self.register_variable(Real(
            "V", causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
            initial=Fmi2Initial.calculated, description="Coil voltage command (connect to the actuator's V)",
            getter=self.command))
        for name, _unit, default, desc in GAINS:
            setattr(self, name, float(default))
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed, initial=Fmi2Initial.exact,
                                        description=desc))
        self.feedforward = True
        self.register_variable(Boolean(
            "feedforward", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
            initial=Fmi2Initial.exact, description="Add the static-inverse feed-forward of the model parameters"))
        for spec in SPECS + EFFECT_SPECS:
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Real(
                spec.name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                initial=Fmi2Initial.exact, description=f"Feed-forward model: {spec.description}"))
        self._table = None   # (x [m], V [V]) of the static inverse, after initialization
        self._q = 0.0        # integrator state [V]
        self._xf = 0.0       # filtered measurement [m]
        self._ok = False

    # -- errors (as fmu_src.mpc_actuator) ------------------------------------------------------
    # -- life cycle -------------------------------------------------------------------------
    def exit_initialization_mode(self):
        self._initialized = True   # from now on the fixed parameters cannot be set (StatusShimErrors)
        try:
            self._check()
            if self.feedforward:
                values = {s.name: float(getattr(self, s.name)) for s in SPECS + EFFECT_SPECS}
                validate(values)
                self._table = feedforward_table(Params(**values), V_max=float(self.V_max))
            else:
                self._table = None
        except ValueError as exc:
            self._ok = False
            if self._report_error(f"invalid parameter: {exc}"):
                raise
            return
        self._q = 0.0
        self._xf = float(self.x_meas)
        self._ok = True

    def _check(self):
        for name, unit, _d, _desc in GAINS:
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise ValueError(f"parameter {name} [{unit}] must be finite, got {v!r}")
            if name in ("Kp", "Ki", "Kd", "Tt") and v < 0.0:
                raise ValueError(f"parameter {name} [{unit}] must be >= 0, got {v!r}")
        if not float(self.Tf) > 0.0:
            raise ValueError(f"parameter Tf [s] must be > 0, got {self.Tf!r}")
        if not float(self.V_max) >= float(self.V_min):
            raise ValueError(f"parameter V_max [V] = {self.V_max!r} must be >= V_min = {self.V_min!r}")

    def _unsaturated(self) -> float:
        """u [V]: feed-forward + P + I + D before the limits."""
        x_ref, x_meas = float(self.x_ref), float(self.x_meas)
        ff = 0.0
        if self._table is not None:
            xs, vs = self._table
            ff = float(np.interp(min(max(x_ref, 0.0), xs[-1]), xs, vs))
        d = -float(self.Kd) * (x_meas - self._xf) / float(self.Tf)
        return ff + float(self.Kp) * (x_ref - x_meas) + self._q + d

    def command(self) -> float:
        """The output V [V] for the current inputs (0 before a successful initialization)."""
        if not self._ok:
            return 0.0
        u = self._unsaturated()
        if not math.isfinite(u):
            return float(self.V_min) if float(self.V_min) > 0.0 else 0.0
        return min(max(u, float(self.V_min)), float(self.V_max))

    def do_step(self, current_time, step_size):
        if not self._ok:
            if self._report_error("doStep before a successful initialization (see the earlier error)"):
                raise RuntimeError("doStep before a successful initialization")
            return False
        h = float(step_size)
        if not (h >= 0.0 and math.isfinite(float(self.x_ref)) and math.isfinite(float(self.x_meas))):
            if self._report_error(f"doStep at t={current_time!r}: step {h!r} < 0 or non-finite input "
                                  f"(x_ref={self.x_ref!r}, x_meas={self.x_meas!r})"):
                raise ValueError("bad step or input")
            return False
        u = self._unsaturated()
        V = min(max(u, float(self.V_min)), float(self.V_max))
        e = float(self.x_ref) - float(self.x_meas)
        aw = (V - u) / float(self.Tt) if float(self.Tt) > 0.0 else 0.0
        self._q += h * (float(self.Ki) * e + aw)
        self._xf += (1.0 - math.exp(-h / float(self.Tf))) * (float(self.x_meas) - self._xf)
        return True

    # -- FMU state (fmi2GetFMUstate ...): the controller's states and every variable, as JSON bytes ----------
    STATE_FORMAT = "mpc_controller-slave-state/1"

    def _state_names(self) -> list:
        return ["x_ref", "x_meas", "feedforward"] + [g[0] for g in GAINS] + [s.name for s in SPECS + EFFECT_SPECS]

    def _get_fmu_state(self):
        table = None if self._table is None else [self._table[0].tolist(), self._table[1].tolist()]
        return self._own_state(json.dumps({"format": self.STATE_FORMAT, "q": self._q, "xf": self._xf, "ok": self._ok,
                                           "table": table, "vars": {k: getattr(self, k) for k in self._state_names()}
                                           }).encode())

    def _set_fmu_state(self, state):
        if self._foreign_state(state):     # another instance's state object (pythonfmu's stock binary)
            return
        try:
            doc = json.loads(bytes(state).decode("utf-8"))
            if doc.get("format") != self.STATE_FORMAT or set(doc["vars"]) != set(self._state_names()):
                raise ValueError("not a state of this controller")
            table = doc["table"]
            self._table = None if table is None else (np.array(table[0]), np.array(table[1]))
            self._q, self._xf, self._ok = float(doc["q"]), float(doc["xf"]), bool(doc["ok"])
            for k, v in doc["vars"].items():
                setattr(self, k, v)
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
            if self._report_error(f"fmi2SetFMUstate: {exc}"):
                raise
