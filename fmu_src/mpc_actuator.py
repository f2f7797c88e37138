"""FMI 2.0 co-simulation slave of the MPC diaphragm actuator (built with pythonfmu).

Input V [V]; outputs x [m], v [m/s], F [N], I [A], B [T], contact, x_sensor [m],
F_sensor [N]; parameters are the paper's (``fmu_src.specs.SPECS``), blocked, the
integrator tolerance rtol and the candidate effects' (``fmu_src.specs.EFFECT_SPECS``,
all 0 = off). The value references of the paper's model come first, so they are
the same as before the effects were added.
The physics lives in ``fmu_src.model``; the builder (``build_fmu.py``) ships the
``fmu_src`` package inside the FMU's resources/ folder, next to this file.

Error handling (convention shared with the C status shim, fmu_shim/fmi2_status_shim.c):
a recoverable error is reported by ``_report_error`` (``fmu_src.slave_status``), which logs the message at
``Fmi2Status.error``. Invalid parameters (m, L, R, D <= 0, negative r0, non-finite
values, rtol <= 0; ``fmu_src.specs.validate``) are rejected this way in
fmi2ExitInitializationMode, with a message naming the parameter; a doStep whose
integration fails likewise. Where this platform's binary is the status shim
(``resources/status_shim.json``, written by build_fmu.py: linux64) the slave then
returns normally (doStep returns False) and the shim, which saw the error message
during the call, returns fmi2Error; the pythonfmu instance stays intact, so
fmi2Reset (pythonfmu re-creates the slave: start values) and fmi2FreeInstance work.
Elsewhere (``build_fmu.py --no-status-shim``, the stock win64 binary) the slave
raises after the message, and pythonfmu reports fmi2Fatal (the message reaches the
master only with loggingOn = true). An exception without such a message (a bug)
is fmi2Fatal everywhere.
"""
import json
import math
import os

from pythonfmu import Boolean, DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real

import fmu_src

# Several pythonfmu FMUs in one process share one interpreter and so one ``fmu_src`` package: the first FMU
# instantiated provides it (e.g. the controller FMU, which ships other modules): look in this FMU's copy too.
_OWN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fmu_src")
if os.path.isdir(_OWN) and _OWN not in list(fmu_src.__path__):
    fmu_src.__path__.append(_OWN)

from fmu_src.coil import voltage_for_field  # noqa: E402
from fmu_src.model import ActuatorModel, check_integrable  # noqa: E402
from fmu_src.slave_status import StatusShimErrors  # noqa: E402
from fmu_src.specs import EFFECT_SPECS, SPECS, TERM_SPECS, Params, validate  # noqa: E402

B_FACE_START = 0.23  # [T] field at the coil face that the start voltage produces
RTOL_DEFAULT = 1e-7  # relative error of the outputs stays below 1e-7 (see tests/fmu/test_fmu.py)
RTOL_MIN, RTOL_MAX = 1e-10, 1e-3   # the range of rtol the FMU accepts (outside: fmi2Error naming rtol)
TIME_REL_TOL = 1e-9  # communication points match to TIME_REL_TOL*(|t| + step): masters' time arithmetic

# (name, description) of the outputs, in value-reference order after the input.
OUTPUTS = (
    ("x", "Centre displacement of the diaphragm toward the coil (contact at x = r0)"),
    ("v", "Centre velocity of the diaphragm, toward the coil positive"),
    ("F", "Magnetic attraction force on the diaphragm, F = Em*I^2*G(r0 - x) "
          "(divided by 1 + ksat*(kB*I)^2 with filler_saturation)"),
    ("I", "Coil current"),
    ("B", "Magnetic flux density on the coil axis at the diaphragm centre"),
)
# registered after the effect parameters
SENSOR_OUTPUTS = (
    ("x_sensor", "Displacement as the displacement sensor reads it: x through a first-order lag tau_s "
                 "(sensor_lag; equal to x when tau_s = 0)"),
    ("F_sensor", "Force as the force transducer reads it: F through a first-order lag tau_s "
                 "(sensor_lag; equal to F when tau_s = 0)"),
)


class MpcActuator(StatusShimErrors, Fmi2Slave):
    """Grey-box model of a magnetic polymer composite diaphragm actuator."""

    author = "mpc-actuator"
    description = ("Magnetic polymer composite diaphragm actuator: RL coil, current-loop field, "
                   "Duffing diaphragm with contact on the coil face (SI units)")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "mpc_actuator"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=0.001)
        d = Params()

        # input
        self.V = voltage_for_field(B_FACE_START, d.kB, d.R)
        self.register_variable(Real(
            "V", causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
            description=f"Coil voltage (start: the voltage whose steady current gives {B_FACE_START} T at the coil face "
                        "with the default kB and R)"))

        # outputs: computed from the model state when the master reads them (fmi2GetReal),
        # once per communication point, so a doStep costs only the integration
        self._outputs = None
        for name, desc in OUTPUTS:
            self.register_variable(Real(
                name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                initial=Fmi2Initial.calculated, description=desc, getter=self._getter(name)))
        self.register_variable(Boolean(
            "contact", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
            initial=Fmi2Initial.calculated, description="True while the diaphragm rests on the coil face (x = r0)",
            getter=self._getter("contact")))

        # parameters
        for spec in SPECS:
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Real(
                spec.name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                initial=Fmi2Initial.exact, description=spec.description))
        self.blocked = bool(d.blocked)
        self.register_variable(Boolean(
            "blocked", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
            initial=Fmi2Initial.exact,
            description="Blocked-diaphragm mode: x = v = 0 and F is the blocked force (force-transducer tests)"))
        self.rtol = RTOL_DEFAULT
        self.register_variable(Real(
            "rtol", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
            initial=Fmi2Initial.exact,
            description="Relative tolerance of the internal adaptive Dormand-Prince 5(4) integrator"))
        # candidate effects (fmu_src.specs.EFFECTS): parameters 0 = off, then the sensor outputs
        for spec in EFFECT_SPECS:
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Real(
                spec.name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                initial=Fmi2Initial.exact, description=spec.description))
        for name, desc in SENSOR_OUTPUTS:
            self.register_variable(Real(
                name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                initial=Fmi2Initial.calculated, description=desc, getter=self._getter(name)))
        # the generic term set (fmu_src.terms): coefficients c_<term> (0 = off) and lag time constants tau_<lag>,
        # after the outputs so that the value references of the variables above stay as they were
        for spec in TERM_SPECS:
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Real(
                spec.name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                initial=Fmi2Initial.exact, description=spec.description))

        self._apply_baked_start_values()
        self.model = None
        self._t0 = 0.0

    def _apply_baked_start_values(self):
        """Start values baked in by ``build_fmu.py --params`` (resources/start_values.json, SI names).

        Also moves the input's start to the voltage giving B_FACE_START with the baked kB and R.
        """
        path = os.path.join(self.resources or "", "start_values.json") if self.resources else None
        if not path or not os.path.isfile(path):
            return
        with open(path) as f:
            values = json.load(f)
        known = {s.name for s in SPECS + EFFECT_SPECS + TERM_SPECS} | {"blocked", "rtol"}
        for name, value in values.items():
            if name not in known:
                raise ValueError(f"{path}: unknown parameter {name!r}")
            setattr(self, name, bool(value) if name == "blocked" else float(value))
        self.V = voltage_for_field(B_FACE_START, self.kB, self.R)

    # -- FMI life cycle ----------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        for name, value in (("startTime", start_time), ("stopTime", stop_time)):
            if value is not None and not math.isfinite(float(value)):
                if self._report_error(f"fmi2SetupExperiment: {name} {value!r} is not a finite number"):
                    raise ValueError(f"{name} {value!r} is not a finite number")
                return
        self._t0 = float(start_time)
        self._stop_time = None if stop_time is None else float(stop_time)
        if stop_time is not None and not self._stop_time >= self._t0:   # FMI 2.0: stopTime >= startTime
            self._stop_time = None
            if self._report_error(f"fmi2SetupExperiment: stopTime {stop_time!r} is before startTime {start_time!r}"):
                raise ValueError(f"stopTime {stop_time!r} < startTime {start_time!r}")

    def exit_initialization_mode(self):
        self._initialized = True   # from now on the fixed parameters cannot be set (StatusShimErrors)
        values = {spec.name: getattr(self, spec.name) for spec in SPECS + EFFECT_SPECS + TERM_SPECS}
        try:
            validate(values)
            rtol = float(self.rtol)
            if not (math.isfinite(rtol) and rtol > 0.0):
                raise ValueError(f"parameter rtol must be > 0 and finite, got {rtol!r}")
            if not RTOL_MIN <= rtol <= RTOL_MAX:
                raise ValueError(f"parameter rtol must be in [{RTOL_MIN:g}, {RTOL_MAX:g}], got {rtol!r}")
            params = Params(**{k: float(v) for k, v in values.items()}, blocked=bool(self.blocked))
            check_integrable(params)
            self.model = ActuatorModel(params, rtol=rtol)
        except ValueError as exc:
            # recoverable (fmi2Error through the status shim): the message names the parameter
            self.model = None
            if self._report_error(f"invalid parameter: {exc}"):
                raise
            return
        self.model.reset(self._t0)
        self._outputs = None
        stop = getattr(self, "_stop_time", None)   # fmi2SetupExperiment's stopTime (None: not defined)
        self._t_limit = math.inf if stop is None else stop + TIME_REL_TOL * (abs(stop) + abs(stop - self._t0))

    def do_step(self, current_time, step_size):
        model = self.model
        if model is None:
            if self._report_error("doStep before a successful initialization (see the earlier error)"):
                raise RuntimeError("doStep before a successful initialization")
            return False
        t_end = current_time + step_size
        t = model.integ.t   # where the previous step ended (FMI 2.0: the next one starts there)
        if not (abs(current_time - t) <= TIME_REL_TOL * (abs(t) + abs(step_size)) and t_end <= self._t_limit
                and step_size >= 0.0):   # (False for NaN)
            on_time = abs(current_time - t) <= TIME_REL_TOL * (abs(t) + abs(step_size))
            if not step_size >= 0.0:
                why = f"communicationStepSize {step_size!r} must be >= 0"
            elif not on_time:
                why = (f"currentCommunicationPoint {current_time!r} is not where the previous step ended ({t!r}): "
                       "a skipped or repeated communication point")
            else:
                why = f"the step ends at {t_end!r}, after stopTime {self._stop_time!r}"
            if self._report_error(f"doStep at t={current_time!r} (h={step_size!r}): {why}"):
                raise ValueError(why)
            return False
        try:
            model.advance(t_end, self.V)
        except Exception as exc:  # pythonfmu reports only "unknown error": log the reason (fmi2Error via the shim)
            if self._report_error(f"doStep at t={current_time!r} (h={step_size!r}, V={self.V!r}) failed: "
                                  f"{type(exc).__name__}: {exc}"):
                raise
            return False
        self._outputs = None
        return True

    def _getter(self, name):
        def get():
            if self._outputs is None:
                if self.model is None:   # before initialization: the initial state (rest, no current)
                    return False if name == "contact" else 0.0
                self._outputs = self.model.outputs()
            return self._outputs[name]
        return get

    # -- FMU state save/restore (fmi2GetFMUstate ... fmi2DeSerializeFMUstate) -----------------------------------
    # pythonfmu 0.7's own implementation (Fmi2Slave._get_fmu_state) only records the registered variables through
    # their getters and sets them back through setters: it would lose the integrator (the outputs have no
    # setters and the model's state is not a variable). Here the state is one bytes object (the whole state,
    # JSON; the integrator's float64 arrays in base64, bit-exact), so pythonfmu's to/from-bytes hooks are the
    # identity. The status shim (fmu_shim/fmi2_status_shim.c) keeps these bytes in its own FMU-state objects and
    # wraps them, when serialized, in a header naming the model (modelIdentifier, GUID, format version).
    STATE_FORMAT = "mpc_actuator-slave-state/1"

    def _state_fields(self) -> list:
        return ["V", "blocked", "rtol", "_t0"] + [spec.name for spec in SPECS + EFFECT_SPECS]

    def _get_fmu_state(self):
        try:
            return self._own_state(encode_state(self.STATE_FORMAT, {k: getattr(self, k) for k in self._state_fields()},
                                                None if self.model is None else self.model.get_state()))
        except Exception as exc:  # never through pythonfmu (fmi2Fatal, broken instance): fmi2Error via the shim
            if self._report_error(f"fmi2GetFMUstate failed: {type(exc).__name__}: {exc}"):
                raise
            return b""

    def _set_fmu_state(self, state):
        if self._foreign_state(state):     # another instance's state object (pythonfmu's stock binary)
            return
        try:
            fields, model_state = decode_state(self.STATE_FORMAT, state, self._state_fields())
            check_state_fields(fields, model_state)
            if model_state is None:
                model = None
            elif self.model is not None and model_state["params"] == self.model.params.as_dict() \
                    and model_state["rtol"] == self.model.integ.rtol:
                model = self.model
                model.set_state(model_state)   # the usual case (rollback): in place
            else:
                model = ActuatorModel.from_state(model_state)
        except Exception as exc:
            if self._report_error(f"fmi2SetFMUstate: not a usable state of this model: {type(exc).__name__}: {exc}"):
                raise
            return
        for k, v in fields.items():
            setattr(self, k, v)
        self.model = model
        self._outputs = None


def check_state_fields(fields: dict, model_state) -> None:
    """Refuse a restored state whose slave fields are not a state this slave can be in: ``ValueError`` naming the
    field (the integrator's part is checked by ``ActuatorModel.set_state``). V, _t0 finite; rtol in its range;
    the parameters valid one by one and together (``validate``, ``check_integrable``); the model's time not
    before the start time."""
    for name in ("V", "_t0"):
        if not math.isfinite(fields[name]):
            raise ValueError(f"field {name} = {fields[name]!r} is not finite")
    if not RTOL_MIN <= fields["rtol"] <= RTOL_MAX:
        raise ValueError(f"field rtol = {fields['rtol']!r} is outside [{RTOL_MIN:g}, {RTOL_MAX:g}]")
    values = {spec.name: fields[spec.name] for spec in SPECS + EFFECT_SPECS}
    validate(values)
    check_integrable(Params(**values, blocked=fields["blocked"]))
    if model_state is not None:
        t = model_state["t"]
        if not (isinstance(t, (int, float)) and math.isfinite(t)):
            raise ValueError(f"the model's time t = {t!r} is not finite")
        if not t >= fields["_t0"]:
            raise ValueError(f"the model's time t = {t!r} is before the start time _t0 = {fields['_t0']!r}")
        if model_state["params"] != Params(**values, blocked=fields["blocked"]).as_dict():
            raise ValueError("the model's parameters differ from the slave's parameter fields")


def encode_state(fmt: str, fields: dict, model_state) -> bytes:
    """The slave's state as bytes: JSON (floats by repr: exact), numpy arrays as base64 of their float64 bytes."""
    import base64
    import numpy as np

    def arr(a):
        a = np.ascontiguousarray(a, dtype="<f8")
        return {"shape": list(a.shape), "f8": base64.b64encode(a.tobytes()).decode("ascii")}
    model = None
    if model_state is not None:
        model = {k: (arr(v) if k in ("S", "W") else v) for k, v in model_state.items()}
    return json.dumps({"format": fmt, "fields": fields, "model": model}, allow_nan=True).encode("utf-8")


def decode_state(fmt: str, data, field_names) -> tuple:
    """(fields, model state or None) from ``encode_state`` bytes; ValueError for anything else."""
    import base64
    import numpy as np
    try:
        doc = json.loads(bytes(data).decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"not a state of this model (not its JSON: {exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        raise ValueError(f"format {doc.get('format') if isinstance(doc, dict) else None!r}, expected {fmt!r}")
    fields = doc.get("fields")
    if not isinstance(fields, dict) or set(fields) != set(field_names):
        raise ValueError("the state's slave fields differ from this slave's")
    for k, v in fields.items():
        if k == "blocked" and not isinstance(v, bool) or k != "blocked" and not isinstance(v, (int, float)):
            raise ValueError(f"field {k!r} has a wrong type")
    fields = {k: (v if k == "blocked" else float(v)) for k, v in fields.items()}
    model = doc.get("model")
    if model is None:
        return fields, None
    if not isinstance(model, dict) or not {"params", "rtol", "dynamics", "t", "S", "W"} <= set(model):
        raise ValueError("the model part of the state is incomplete")

    def arr(d):
        raw = base64.b64decode(d["f8"], validate=True)
        a = np.frombuffer(raw, dtype="<f8").astype(np.float64)
        return a.reshape([int(n) for n in d["shape"]])
    try:
        model = {**model, "S": arr(model["S"]), "W": arr(model["W"])}
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"the state's arrays are damaged: {exc}") from None
    return fields, model
