"""FMI 3.0 co-simulation slave of the MPC diaphragm actuator (built with pythonfmu3: ``build_fmu.py --fmi 3``).

A thin class over the FMI 2.0 slave (``mpc_actuator.py``, i.e. ``fmu_src.mpc_actuator``): the same variables
(names, descriptions, start values, value-reference order after FMI 3.0's independent variable ``time``), and
the same methods for start values, initialization (parameter validation), doStep and the outputs, which call
the one physics implementation (``fmu_src.model``). Only the variable registration (pythonfmu3's types) and
the error convention differ: there is no status shim for FMI 3.0, so a reported error is logged and then
raised (pythonfmu3 turns every exception into an error of the call).

Not supported (see README.md, "Using the FMU in a system simulator"): FMU state save/restore
(canGetAndSetFMUState / canSerializeFMUState false: pythonfmu3 hands its Python object to the host as the
state, with no checks), event mode, early return, clocks, intermediate update, arrays, model exchange and
scheduled execution; Python discovery in native hosts (the FMI 2.0 FMU's shim) and recoverable errors.
"""
from pythonfmu3 import Boolean, DefaultExperiment, Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64
from pythonfmu3.enums import Fmi3Initial, Fmi3Status

from fmu_src.coil import voltage_for_field
from fmu_src.mpc_actuator import B_FACE_START, OUTPUTS, RTOL_DEFAULT, SENSOR_OUTPUTS, MpcActuator
from fmu_src.specs import EFFECT_SPECS, SPECS, TERM_SPECS, Params


class MpcActuatorFmi3(Fmi3Slave):
    """Grey-box model of a magnetic polymer composite diaphragm actuator (FMI 3.0 co-simulation)."""

    author = MpcActuator.author
    description = MpcActuator.description

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "mpc_actuator_fmi3"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=0.001)
        d = Params()
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous, description="Simulation time"))
        self.V = voltage_for_field(B_FACE_START, d.kB, d.R)
        self.register_variable(Float64(
            "V", causality=Fmi3Causality.input, variability=Fmi3Variability.continuous,
            description=f"Coil voltage (start: the voltage whose steady current gives {B_FACE_START} T at the coil "
                        "face with the default kB and R)"))
        self._outputs = None
        for name, desc in OUTPUTS:
            self.register_variable(Float64(name, causality=Fmi3Causality.output, variability=Fmi3Variability.continuous,
                                           initial=Fmi3Initial.calculated, description=desc,
                                           getter=self._getter(name)))
        self.register_variable(Boolean(
            "contact", causality=Fmi3Causality.output, variability=Fmi3Variability.discrete,
            initial=Fmi3Initial.calculated, description="True while the diaphragm rests on the coil face (x = r0)",
            getter=self._getter("contact")))
        for spec in SPECS:
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Float64(spec.name, causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.fixed, initial=Fmi3Initial.exact,
                                           description=spec.description))
        self.blocked = bool(d.blocked)
        self.register_variable(Boolean(
            "blocked", causality=Fmi3Causality.parameter, variability=Fmi3Variability.fixed,
            initial=Fmi3Initial.exact,
            description="Blocked-diaphragm mode: x = v = 0 and F is the blocked force (force-transducer tests)"))
        self.rtol = RTOL_DEFAULT
        self.register_variable(Float64(
            "rtol", causality=Fmi3Causality.parameter, variability=Fmi3Variability.fixed, initial=Fmi3Initial.exact,
            description="Relative tolerance of the internal adaptive Dormand-Prince 5(4) integrator"))
        for spec in EFFECT_SPECS:
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Float64(spec.name, causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.fixed, initial=Fmi3Initial.exact,
                                           description=spec.description))
        for name, desc in SENSOR_OUTPUTS:
            self.register_variable(Float64(name, causality=Fmi3Causality.output, variability=Fmi3Variability.continuous,
                                           initial=Fmi3Initial.calculated, description=desc,
                                           getter=self._getter(name)))
        for spec in TERM_SPECS:   # the generic term set (fmu_src.terms), after the outputs as in the FMI 2.0 slave
            setattr(self, spec.name, float(spec.default))
            self.register_variable(Float64(spec.name, causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.fixed, initial=Fmi3Initial.exact,
                                           description=spec.description))
        self._shim = False
        self._apply_baked_start_values()
        self.model = None
        self._t0 = 0.0

    # the FMI 2.0 slave's methods (one implementation)
    _apply_baked_start_values = MpcActuator._apply_baked_start_values
    setup_experiment = MpcActuator.setup_experiment
    exit_initialization_mode = MpcActuator.exit_initialization_mode
    _getter = MpcActuator._getter

    def _report_error(self, message) -> bool:
        """Log ``message`` at error status; True: the caller raises (no status shim for FMI 3.0)."""
        self.log(f"{self.instance_name}: {message}", Fmi3Status.error)
        return True

    def enter_initialization_mode(self):
        self.time = self._t0

    def do_step(self, current_time, step_size):
        ok = MpcActuator.do_step(self, current_time, step_size)
        self.time = current_time + step_size
        return ok
