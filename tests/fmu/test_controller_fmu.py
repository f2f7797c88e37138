"""The controller FMU (fmu_src/mpc_controller.py, ``build_fmu.py --controller``): fmpy validates it; its PI
with back-calculation anti-windup against a hand-computed case; its feed-forward against the independent
static force balance; bad parameters give fmi2Error; the two FMUs in one plain Python process (either
instantiated first) and at exit."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import fmpy
import pytest
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from fmu_src.specs import Params
from test_c_host import H, host  # noqa: F401  (the C host's fixture and step)
from test_fmu import logging_callbacks
from test_fmu_hosts import run, table

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "independent"))
from physics import kernel_G  # noqa: E402  (independent: imports nothing of the project)


def test_validates(controller_fmu_path):
    assert validate_fmu(str(controller_fmu_path)) == []
    md = fmpy.read_model_description(str(controller_fmu_path), validate=True)
    units = {v.name: v.unit for v in md.modelVariables}
    assert (units["x_ref"], units["x_meas"], units["V"], units["Kp"], units["Ki"]) == ("m", "m", "V", "V/m", "V/m.s")
    out = md.outputs[0]
    assert out.variable.name == "V" and {d.name for d in out.dependencies} == {"x_ref", "x_meas"}
    assert md.coSimulation.canGetAndSetFMUstate


def test_ships_what_its_slave_imports(controller_fmu_path):
    import zipfile
    names = set(zipfile.ZipFile(controller_fmu_path).namelist())
    shipped = {n.rsplit("/", 1)[1] for n in names if n.startswith("resources/fmu_src/") and n.endswith(".py")}
    assert {"statics.py", "model.py", "integrator.py", "specs.py", "effects.py", "field.py"} <= shipped
    assert not {"mpc_actuator.py", "mpc_controller.py", "coil.py"} & shipped   # (the slave is resources/mpc_controller.py)
    assert {"resources/mpc_controller.py", "binaries/linux64/mpc_controller.so",
            "binaries/linux64/mpc_controller_pythonfmu.so", "resources/status_shim.json"} <= names
    assert any(n.startswith("resources/fmu_src/__pycache__/") and n.endswith(".nbc") for n in names)


class Controller:
    """The controller FMU through fmpy's FMU2Slave, with its own logger (``messages``, kept alive with the
    instance: fmpy's logger proxy is process-wide, and a logger another test freed must not be called)."""

    def __init__(self, path, values):
        self.md = fmpy.read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.dir = fmpy.extract(str(path))
        self.f = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                           modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="ctl")
        self.messages = []
        self.callbacks = logging_callbacks(self.messages)
        self.f.instantiate(callbacks=self.callbacks)
        self.f.setupExperiment(startTime=0.0)
        self.f.enterInitializationMode()
        for k, v in values.items():
            if isinstance(v, bool):
                self.f.setBoolean([self.vr[k]], [v])
            else:
                self.f.setReal([self.vr[k]], [v])
        self.t = 0.0

    def init(self):
        self.f.exitInitializationMode()

    def step(self, x_ref, x_meas, h):
        self.f.setReal([self.vr["x_ref"], self.vr["x_meas"]], [x_ref, x_meas])
        V = self.f.getReal([self.vr["V"]])[0]
        self.f.doStep(self.t, h)
        self.t += h
        return V

    def close(self):
        self.f.terminate()
        self.f.freeInstance()


def test_pi_anti_windup_hand_computed(controller_fmu_path):
    # Kp = 100 V/m, Ki = 1000 V/(m.s), limits [0, 1] V, h = 10 ms, e = 0.02 m (u = 2 V: saturated).
    # With Tt = 10 ms: q1 = 0.01*(1000*0.02 + (1 - 2)/0.01) = -0.8 V, then u = 1.2 V and
    # q2 = q1 + 0.01*(20 + (1 - 1.2)/0.01) = -0.8 V: q stays at -0.8 V while saturated. When the measurement
    # passes the setpoint (e = -0.01 m): u = -1 - 0.8 = -1.8 V -> V = 0 at once.
    # Without anti-windup (Tt = 0) q grows by 0.2 V per step: after 10 steps 2 V, and at e = -0.01 m
    # u = -1 + 2 = 1 V: still at the upper limit (wind-up).
    common = {"Kp": 100.0, "Ki": 1000.0, "V_min": 0.0, "V_max": 1.0, "feedforward": False}
    for Tt, expect_after in ((0.01, 0.0), (0.0, 1.0)):
        c = Controller(controller_fmu_path, {**common, "Tt": Tt})
        c.init()
        Vs = [c.step(0.02, 0.0, 0.01) for _ in range(10)]
        assert Vs == [1.0] * 10
        assert c.step(0.02, 0.03, 0.01) == pytest.approx(expect_after, abs=1e-12)
        c.close()
    # unsaturated: V = Kp*e + q exactly (q after one step = h*Ki*e)
    c = Controller(controller_fmu_path, {**common, "V_max": 10.0, "Tt": 0.01})
    c.init()
    assert c.step(0.002, 0.0, 0.01) == pytest.approx(0.2, rel=1e-12)
    assert c.step(0.002, 0.0, 0.01) == pytest.approx(0.2 + 0.01 * 1000 * 0.002, rel=1e-12)
    c.close()


def test_feedforward_is_the_independent_static_inverse(controller_fmu_path):
    p = Params()
    c = Controller(controller_fmu_path, {"Kp": 0.0, "Ki": 0.0, "V_max": 100.0})
    c.init()
    for x in (0.5e-3, 1e-3, 3e-3):
        K = (p.K1 * x * x + p.K2) * x
        V_indep = p.R * math.sqrt(K / (p.Em * kernel_G(p.r0 - x, p.a, p.D, p.kB)))
        assert c.step(x, x, 1e-3) == pytest.approx(V_indep, rel=2e-3)   # linear table interpolation
    c.close()


def test_bad_parameter_is_fmi2error(controller_fmu_path):
    c = Controller(controller_fmu_path, {"Tf": 0.0})
    with pytest.raises(Exception, match=r"fmi2ExitInitializationMode failed with status 3 \(error\)"):
        c.init()
    assert any(status == 3 and "parameter Tf [s] must be > 0, got 0.0" in m for _, status, m in c.messages), c.messages
    c.f.freeInstance()


TWO_FMUS = """
import sys
import fmpy
from fmpy.fmi2 import FMU2Slave
def inst(path):
    md = fmpy.read_model_description(path)
    f = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=path)
    f.instantiate(); f.setupExperiment(startTime=0.0); f.enterInitializationMode(); f.exitInitializationMode()
    return f, {v.name: v.valueReference for v in md.modelVariables}
first = inst(sys.argv[1]); second = inst(sys.argv[2])
(a, va), (c, vc) = (first, second) if "actuator" in sys.argv[1] else (second, first)
t = 0.0
for k in range(300):
    c.setReal([vc["x_ref"], vc["x_meas"]], [1e-3, a.getReal([va["x"]])[0]])
    a.setReal([va["V"]], c.getReal([vc["V"]])); a.doStep(t, 1e-3); c.doStep(t, 1e-3); t += 1e-3
print(a.getReal([va["x"]])[0])
"""


@pytest.mark.parametrize("actuator_first", [True, False])
def test_two_fmus_in_one_plain_python_process(fmu_path, controller_fmu_path, tmp_path, actuator_first):
    # a Python without the project installed (no site: fmu_src comes from the first FMU instantiated)
    import fmpy as _f
    site = str(Path(_f.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": site}
    order = [str(fmu_path), str(controller_fmu_path)]
    if not actuator_first:
        order.reverse()
    proc = subprocess.run([sys.executable, "-S", "-c", TWO_FMUS, *order], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert float(proc.stdout.strip()) == pytest.approx(1e-3, abs=1e-5)   # PI + feed-forward: 1 mm after 0.3 s


NATIVE_CASES = [pytest.param(True, "reverse", 1), pytest.param(False, "reverse", 1)] + [
    pytest.param(first, unload, 5, marks=pytest.mark.slow) for first in (True, False) for unload in ("reverse", "forward")]


@pytest.mark.parametrize("actuator_first, unload, runs", NATIVE_CASES)
def test_both_fmus_in_a_native_host(host, unzipdir, model_description, controller_fmu_path, tmp_path, actuator_first,
                                    unload, runs):
    """The C host of tests/fmu/c_host (strict logger: aborts on NULL strings) with both FMUs, no environment
    (``env -i``): either instantiated first (it starts the interpreter), a clean exit every time (slow: both
    unload orders, 5 runs each); the controller's V = feed-forward + Kp*e (its default gains) at the first
    point."""
    ctl_dir = fmpy.extract(str(controller_fmu_path), unzipdir=str(tmp_path / "ctl"))
    md_c = fmpy.read_model_description(str(controller_fmu_path))
    vc = {v.name: v.valueReference for v in md_c.modelVariables}
    va = {v.name: v.valueReference for v in model_description.modelVariables}
    act = ["--output", str(va["x"]), "--instance", "A", "--input", f"{va['V']}=12.0"]
    ctl = ["--output", str(vc["V"]), "--instance", "C", "--input", f"{vc['x_ref']}=0.001", f"{vc['x_meas']}=0.0"]
    first, second = ([unzipdir, act], [ctl_dir, ctl]) if actuator_first else ([ctl_dir, ctl], [unzipdir, act])
    args = [first[0], "--step", H, "--stop", 0.02, "--unload", unload, *first[1], "--fmu", second[0], *second[1]]
    for _ in range(runs):
        proc = run(host, args, env={})
        assert proc.returncode == 0, proc.stderr[-3000:]
    t = table(proc.stdout)
    V = t[f"C:{vc['V']}"]
    assert V[0] == pytest.approx(13.4464 + 6000.0 * 1e-3, rel=2e-3) and t[f"A:{va['x']}"][-1] > 0.0


def test_fmu_state_rollback_and_serialization(controller_fmu_path):
    c = Controller(controller_fmu_path, {"Kp": 100.0, "Ki": 1000.0, "V_max": 10.0})
    c.init()
    for _ in range(3):
        c.step(0.002, 0.0, 0.01)
    st = c.f.getFMUstate()
    data = c.f.serializeFMUstate(st)
    ahead = [c.step(0.002, 0.001, 0.01) for _ in range(3)]
    c.f.setFMUstate(st)
    c.t -= 0.03
    assert [c.step(0.002, 0.001, 0.01) for _ in range(3)] == ahead   # rollback: bit-identical
    fresh = Controller(controller_fmu_path, {})
    fresh.init()
    fresh.f.setFMUstate(fresh.f.deSerializeFMUstate(data))            # another instance: gains and states
    fresh.t = c.t - 0.03
    assert [fresh.step(0.002, 0.001, 0.01) for _ in range(3)] == ahead
    c.f.freeFMUstate(st)
    c.close()
    fresh.close()


def test_derivative_on_the_filtered_measurement_hand_computed(controller_fmu_path):
    # Kd = 1 V.s/m, Tf = 10 ms, h = 10 ms, no P/I/feed-forward; x_f starts at x_meas = 0 (initialization).
    # x_meas = 1 mm: V = -Kd*(x_meas - x_f)/Tf = -0.1 V; then x_f = (1 - exp(-1))*1 mm, V = -exp(-1)*0.1 V.
    c = Controller(controller_fmu_path, {"Kp": 0.0, "Ki": 0.0, "Kd": 1.0, "Tf": 0.01, "V_min": -1.0,
                                         "feedforward": False})
    c.init()
    assert c.step(0.0, 1e-3, 0.01) == pytest.approx(-0.1, rel=1e-12)
    assert c.step(0.0, 1e-3, 0.01) == pytest.approx(-0.1 * math.exp(-1.0), rel=1e-12)
    c.close()
