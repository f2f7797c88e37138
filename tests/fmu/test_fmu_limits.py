"""The FMU refuses what it cannot do right (issue 12): rtol out of range, physically absurd parameters, a doStep
that would take too many internal steps, and FMI 2.0's time rules; and x <= r0 whatever the step control does.
Every refusal is fmi2Error (the status shim) with a message naming the reason."""
import re

import numpy as np
import pytest

from fmu_src.coil import voltage_for_field
from fmu_src.model import simulate
from fmu_src.specs import Params
from test_fmu import logging_callbacks, restore_default_logger

ERROR = 3   # fmi2Error


class Instance:
    """An fmpy FMU2Slave of the built FMU whose log messages (status, text) are collected in ``messages``."""

    def __init__(self, unzipdir, md, name):
        from fmpy.fmi2 import FMU2Slave
        self.log = []                          # (instance name, status, message)
        cb = logging_callbacks(self.log)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=name)
        self.fmu.instantiate(callbacks=cb, loggingOn=False)

    @property
    def messages(self) -> list:
        """The log messages as (status, text)."""
        return [(st, m) for _, st, m in self.log]

    def init(self, params=None, start=0.0, stop=None):
        f = self.fmu
        f.setupExperiment(startTime=start, stopTime=stop)
        f.enterInitializationMode()
        for k, v in (params or {}).items():
            f.setReal([self.vr[k]], [float(v)])
        f.exitInitializationMode()

    def error(self, call, *args, **kw) -> str:
        """Call an FMI function that must fail with fmi2Error; return the error messages it logged."""
        from fmpy.fmi1 import FMICallException
        n = len(self.messages)
        with pytest.raises(FMICallException) as exc:
            call(*args, **kw)
        assert exc.value.status == ERROR, (exc.value, self.messages)
        return " | ".join(m for st, m in self.messages[n:] if st == ERROR)

    def free(self):
        self.fmu.freeInstance()
        restore_default_logger()


@pytest.fixture
def inst(unzipdir, model_description, request):
    i = Instance(unzipdir, model_description, request.node.name[:40])
    yield i
    i.free()


# ---------------------------------------------------------------------------------------- (a) rtol range
@pytest.mark.parametrize("rtol", [1e-11, 2e-3, 0.5])
def test_rtol_outside_the_documented_range_is_refused(inst, rtol):
    msg = inst.error(inst.init, {"rtol": rtol})
    assert re.search(r"\bparameter rtol must be in \[1e-10, 0\.001\]", msg), msg


@pytest.mark.parametrize("rtol", [1e-10, 1e-3])
def test_rtol_at_the_ends_of_the_range_is_accepted(inst, rtol):
    inst.init({"rtol": rtol})
    inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    assert inst.fmu.getReal([inst.vr["x"]])[0] > 0.0


# ---------------------------------------------------------------------------------------- (b) x <= r0
def test_displacement_never_passes_the_coil_face_at_loose_tolerance():
    """A pull that ends just as the diaphragm reaches the coil face, at rtol = 1e-3: the DP5 dense output between
    step ends passes r0 (by 9e-9 m before the fix); x stays <= r0 at every communication point."""
    t = np.round(np.arange(0.0, 0.3, 1e-4), 12)
    p = Params(r0=0.00580537494025796, C=0.011341865083372567)
    V = np.where(t < 0.04171340993546895, voltage_for_field(0.2837681059469421, p.kB, p.R), 0.0)
    res = simulate(p, t, V, rtol=1e-3)
    assert np.max(res["x"]) <= p.r0
    assert np.max(res["x"]) > 0.999 * p.r0   # it does get there


# ---------------------------------------------------------------------------------------- (c) absurd parameters
@pytest.mark.parametrize("params,named", [
    ({"r0": 1e300}, r"\bparameter r0\b"),
    ({"m": 1e-30}, r"sqrt\(m/K2\) \(parameters m, K2\)"),
    ({"L": 1e-20}, r"L/R \(parameters L, R\)"),
    ({"Rth": 8.0, "tau_th": 1e-13}, r"\btau_th \(parameter tau_th\)"),
    ({"Em": 1e30}, r"parameters Em = 1e\+30 N.m/T2, a = 0.015 m, D = 0.045 m: the magnetic force at the coil face, "
                   r"1e\+32 N at a coil-face field of 1 T, is 1.58e\+29 times the most a 1 T field can pull"),
    ({"L": 1e7}, r"L/R \(parameters L, R\) = 6.67e\+05 s above 100000 s"),
    ({"K2": 1e-14, "K1": 0.0}, r"sqrt\(m/K2\) \(parameters m, K2\) = 6.32e\+05 s above 100000 s"),
    ({"Kc": 8.0, "tau_c": 1e9}, r"\btau_c \(parameter tau_c\) = 1e\+09 s above 100000 s"),
])
def test_physically_absurd_parameters_are_refused_and_named(inst, params, named):
    msg = inst.error(inst.init, params)
    assert re.search(named, msg), msg


def test_the_rigs_and_the_papers_parameters_are_far_from_the_bounds():
    """check_integrable's force and time-scale bounds leave the virtual rig's whole sample range (with every
    effect at magnitude 3), the paper's defaults and the shipped reference parameters alone."""
    from fmu_src.model import check_integrable
    from harness.data import rig
    from harness.analysis.validation.crosscheck import load_reference_params
    check_integrable(Params())
    for w in np.linspace(5, 35, 7):
        for d in np.linspace(20, 70, 6):
            base = rig.true_params(w, d)
            for gap in (0.0, 2e-3, 12e-3):
                check_integrable(base.with_(r0=gap))
                for name in rig.EFFECT_MAGNITUDES:
                    check_integrable(base.with_(r0=gap, **rig.effect_params(name, 3.0, base)))
    from pathlib import Path
    refs = Path(__file__).resolve().parents[2] / "references" / "W20-D45"
    tests = sorted(f.name.split("_")[0] for f in refs.glob("*_params.json"))
    assert len(tests) == 8
    for test in tests:
        check_integrable(load_reference_params(refs, test, None))


# ---------------------------------------------------------------------------------------- (d) step cap
def test_a_do_step_that_needs_too_many_internal_steps_is_an_error(inst):
    inst.init()
    msg = inst.error(inst.fmu.doStep, currentCommunicationPoint=0.0, communicationStepSize=1e5)
    assert "more than 500000 internal steps" in msg and "StepLimitError" in msg, msg


# ---------------------------------------------------------------------------------------- (e) FMI 2.0 time rules
def test_stop_time_before_start_time_is_an_error(inst):
    msg = inst.error(inst.fmu.setupExperiment, startTime=1.0, stopTime=0.5)
    assert "stopTime 0.5 is before startTime 1.0" in msg, msg


@pytest.mark.parametrize("start, stop, named", [
    (float("nan"), 1.0, "fmi2SetupExperiment: startTime nan is not a finite number"),
    (float("inf"), None, "fmi2SetupExperiment: startTime inf is not a finite number"),
    (0.0, float("nan"), "fmi2SetupExperiment: stopTime nan is not a finite number"),
    (0.0, float("inf"), "fmi2SetupExperiment: stopTime inf is not a finite number"),
])
def test_non_finite_experiment_times_are_errors(inst, start, stop, named):
    msg = inst.error(inst.fmu.setupExperiment, startTime=start, stopTime=stop)
    assert named in msg and "before" not in msg, msg
    inst.init()                                      # a valid setup afterwards: the instance works
    inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)


def test_fixed_parameters_cannot_be_set_after_initialization(inst):
    """FMI 2.0: a parameter of variability fixed may be set only before and in initialization mode; after it
    fmi2SetReal/fmi2SetBoolean are fmi2Error naming it, and nothing of the call is set; the input may change."""
    inst.init({"Em": 0.05})
    vr = inst.vr
    msg = inst.error(inst.fmu.setReal, [vr["V"], vr["Em"]], [1.0, 0.07])
    assert "fmi2SetReal: parameter Em has variability fixed" in msg and "initialization mode" in msg, msg
    assert inst.fmu.getReal([vr["Em"]]) == [0.05] and inst.fmu.getReal([vr["V"]]) != [1.0]
    for name in ("r0", "rtol", "tau_s"):
        assert f"parameter {name} has variability fixed" in inst.error(inst.fmu.setReal, [vr[name]], [0.001])
    msg = inst.error(inst.fmu.setBoolean, [vr["blocked"]], [True])
    assert "fmi2SetBoolean: parameter blocked has variability fixed" in msg, msg
    inst.fmu.setReal([vr["V"]], [2.0])               # the input: any time
    inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    assert inst.fmu.getReal([vr["V"]]) == [2.0]
    inst.fmu.reset()                                 # after fmi2Reset they may be set again
    inst.init({"Em": 0.07})
    assert inst.fmu.getReal([vr["Em"]]) == [0.07]


def test_do_step_past_the_stop_time_is_an_error(inst):
    inst.init(stop=0.002)
    inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    inst.fmu.doStep(currentCommunicationPoint=1e-3, communicationStepSize=1e-3)   # ends at the stop time: fine
    msg = inst.error(inst.fmu.doStep, currentCommunicationPoint=2e-3, communicationStepSize=1e-3)
    assert "after stopTime 0.002" in msg, msg


def test_skipped_communication_point_is_an_error(inst):
    inst.init(start=0.5)
    inst.fmu.doStep(currentCommunicationPoint=0.5, communicationStepSize=1e-3)
    msg = inst.error(inst.fmu.doStep, currentCommunicationPoint=0.503, communicationStepSize=1e-3)
    assert "currentCommunicationPoint 0.503 is not where the previous step ended (0.501)" in msg, msg


def test_first_step_must_start_at_the_start_time(inst):
    inst.init(start=0.0)
    msg = inst.error(inst.fmu.doStep, currentCommunicationPoint=0.1, communicationStepSize=1e-3)
    assert "skipped or repeated communication point" in msg, msg


def test_time_arithmetic_of_a_master_is_tolerated(unzipdir):
    """fmpy's own loop (t_k = t0 + k*h, steps t_(k+1) - t_k, a stop time) runs to the end without errors."""
    from fmpy import simulate_fmu
    res = simulate_fmu(unzipdir, start_time=0.1, stop_time=0.4, output_interval=1e-3 / 3)
    assert res["time"][-1] == pytest.approx(0.4, abs=1e-12) and res["x"][-1] > 0.0
