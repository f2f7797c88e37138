"""A second importer: fmu-manipulation-toolbox (PyPI: fmu-manipulation-toolbox, the `test` extra).

* its checker (``fmutool -input FMU -check``: generic conformity against the FMI 2.0 schema, then semantic
  checks) on every build;
* an FMU container built with its container tool (``fmucontainer``): a stock pythonfmu source FMU producing the
  voltage V, linked to the actuator's input V, the actuator's x and F exposed; the container (the toolbox's own
  C binary, which loads both FMUs in one process) runs under fmpy and equals the actuator alone.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BIN = Path(sys.executable).parent

SOURCE_SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class source_slave(Fmi2Slave):
    """A stock pythonfmu FMU: a voltage step V = V0 [V] from t = 0."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.V0 = 11.9
        self.V = 11.9
        self.register_variable(Real("V0", causality=Fmi2Causality.parameter, variability="tunable"))
        self.register_variable(Real("V", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.V = self.V0
        return True
'''


def _tool(name):
    exe = BIN / name
    if not exe.exists():
        pytest.fail(f"{exe} not found: install the test extra (pip install -e '.[test]': fmu-manipulation-toolbox)")
    return str(exe)


def test_toolbox_checker_is_clean(fmu_path):
    proc = subprocess.run([_tool("fmutool"), "-input", str(fmu_path), "-check"], capture_output=True, text=True,
                          timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "This FMU seems to be compliant with FMI-2.0." in out, out
    assert "No semantic error against the FMI-2 standard." in out, out
    assert "ERROR" not in out, out


def test_container_with_a_source_fmu_runs_under_fmpy(fmu_path, tmp_path):
    d = tmp_path / "container"
    d.mkdir()
    (d / "source_slave.py").write_text(SOURCE_SLAVE)
    proc = subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", "source_slave.py", "-d", "."], cwd=d,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    shutil.copyfile(fmu_path, d / "mpc_actuator.fmu")
    (d / "chain.csv").write_text("rule;from_fmu;from_port;to_fmu;to_port\n"
                                 "LINK;source_slave.fmu;V;mpc_actuator.fmu;V\n"
                                 "OUTPUT;mpc_actuator.fmu;x;;x\n"
                                 "OUTPUT;mpc_actuator.fmu;F;;F\n")
    proc = subprocess.run([_tool("fmucontainer"), "-container", "chain.csv:0.001", "-fmu-directory", "."], cwd=d,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and (d / "chain.fmu").is_file(), proc.stdout + proc.stderr
    # the container under fmpy (in a subprocess: it loads two pythonfmu FMUs into the process)
    code = ("import sys, numpy as np, fmpy\n"
            "r = fmpy.simulate_fmu(sys.argv[1], stop_time=0.3, output_interval=1e-3, output=['x', 'F'])\n"
            "np.save(sys.argv[2], np.array([r['time'], r['x'], r['F']]))\n")
    proc = subprocess.run([sys.executable, "-c", code, str(d / "chain.fmu"), str(d / "chain.npy")], cwd=d,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    t, x, F = np.load(d / "chain.npy")
    from fmpy import simulate_fmu
    ref = simulate_fmu(str(fmu_path), stop_time=0.3, output_interval=1e-3, output=["x", "F"],
                       start_values={"V": 11.9})
    assert np.array_equal(t, ref["time"])
    for got, want in ((x, ref["x"]), (F, ref["F"])):
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))
    assert 0.0 < x[-1] < 0.009
