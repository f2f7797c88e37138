"""The FMU in a native host without set-up, beside another pythonfmu FMU, and with a strict logger.

tests/fmu/c_host/fmi2_cs_host.c runs in a subprocess. Its logger abort()s on a NULL string argument, as a C++
host that builds std::string from it does (OMSimulator: "basic_string: construction from null is not valid",
exit 134), so every run here also checks that the FMU never hands the host a NULL.

* No set-up: with an empty environment (``env -i``) the status shim finds the interpreter recorded by
  build_fmu.py (resources/python.json); MPC_ACTUATOR_PYTHON overrides it. Without either (or with a broken
  one) fmi2Instantiate returns NULL with a message naming what is missing and how to provide it.
* A fatal Python error at instantiation (the scientific packages unreachable) reaches the host with a
  category, and messages of any length are cut safely.
* A stock pythonfmu FMU (a trivial slave, built here) loaded before and after the actuator, unloaded in both
  orders: 20 of 20 clean exits each (before the fix: 27 of 30 runs with the stock FMU instantiated first
  segfaulted at exit, because its interpreter was finalized after SciPy's and numba's static destructors).
* FMU state save/restore through the native API (--state-check).
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from test_c_host import H, HOST_PATH, columns, fmpy_sim, host, host_env, run_args, start, vrs  # noqa: F401

REPO = Path(__file__).resolve().parents[2]
N_EXITS = 20


def run(host, args, env, timeout=300):
    return subprocess.run([str(host), *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env)


def table(stdout) -> dict:
    header, *rows = stdout.strip().splitlines()
    data = np.array([[float(v) for v in row.split(",")] for row in rows])
    return dict(zip(header.split(","), data.T))


def copy_fmu(unzipdir, dest: Path, drop_python_json=False) -> Path:
    shutil.copytree(unzipdir, dest)
    if drop_python_json:
        (dest / "resources" / "python.json").unlink()
    return dest


# ----------------------------------------------------------------------------------------
# no set-up on a prepared machine
# ----------------------------------------------------------------------------------------
def test_python_json_records_this_interpreter(unzipdir):
    import sysconfig
    doc = json.loads((Path(unzipdir) / "resources" / "python.json").read_text())
    assert doc["format"] == "mpc_actuator-python/1" and doc["version"] == "3.11"
    assert Path(doc["libpython"]).is_file() and doc["home"] == sys.base_prefix
    assert sysconfig.get_path("purelib") in doc["paths"]


def test_empty_environment_runs_and_equals_fmpy(host, unzipdir, model_description):
    """env -i: no LD_PRELOAD, no PYTHONHOME, no PYTHONPATH, no PATH."""
    md = model_description
    V0 = start(md, "V")
    proc = run(host, [unzipdir, "--step", H, "--stop", 0.2, *run_args(md, "A", {"r0": 0.0045}, V0)], env={})
    assert proc.returncode == 0, proc.stderr[-3000:]
    c = columns(md, table(proc.stdout), "A")
    ref = fmpy_sim(unzipdir, {"r0": 0.0045}, V0, stop=0.2)
    for o in c:
        assert np.max(np.abs(c[o] - ref[o])) <= 1e-12 * np.max(np.abs(ref[o])), o


def test_system_python_first_on_path_is_not_used(host, unzipdir, model_description):
    """A plain shell's PATH (a system python3 may be first): the recorded home is used, not PATH's python3."""
    md = model_description
    env = {"PATH": HOST_PATH, "PYTHONVERBOSE": "1"}
    proc = run(host, [unzipdir, "--step", H, "--stop", 0.002, *run_args(md, "A", {}, start(md, "V"))], env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert f"{sys.base_prefix}/lib/python3.11/encodings/__init__.py" in proc.stderr


def test_override_variable_and_clean_failures(host, unzipdir, model_description, tmp_path):
    md = model_description
    args = ["--step", H, "--stop", 0.002, *run_args(md, "A", {}, start(md, "V"))]
    bare = copy_fmu(unzipdir, tmp_path / "no_python_json", drop_python_json=True)
    # 1. no resources/python.json, no MPC_ACTUATOR_PYTHON: NULL from fmi2Instantiate, a message saying what to do
    proc = run(host, [bare, *args], env={})
    assert proc.returncode == 3, (proc.returncode, proc.stderr[-3000:])
    assert "fmi2_cs_host: fmi2Instantiate(A) failed" in proc.stderr
    msg = proc.stderr
    assert "[fmi2Error 3] A (logStatusError)" in msg and "MPC_ACTUATOR_PYTHON" in msg and "python.json" in msg
    assert "make fmu" in msg and "numpy, scipy and numba" in msg
    # 2. MPC_ACTUATOR_PYTHON names the interpreter: the same FMU runs
    good = tmp_path / "python.json"
    good.write_text((Path(unzipdir) / "resources" / "python.json").read_text())
    proc = run(host, [bare, *args], env={"MPC_ACTUATOR_PYTHON": str(good)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    # 3. ... and overrides resources/python.json: a broken description is reported, naming the file
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({"libpython": "/nonexistent/libpython3.11.so", "home": "/nonexistent",
                                  "paths": []}))
    proc = run(host, [unzipdir, *args], env={"MPC_ACTUATOR_PYTHON": str(broken)})
    assert proc.returncode == 3, proc.stderr[-3000:]
    assert "/nonexistent/libpython3.11.so" in proc.stderr and str(broken) in proc.stderr
    proc = run(host, [unzipdir, *args], env={"MPC_ACTUATOR_PYTHON": str(tmp_path / "missing.json")})
    assert proc.returncode == 3 and str(tmp_path / "missing.json") in proc.stderr, proc.stderr[-3000:]
    broken.write_text("{not json")
    proc = run(host, [unzipdir, *args], env={"MPC_ACTUATOR_PYTHON": str(broken)})
    assert proc.returncode == 3 and "not a valid Python description" in proc.stderr, proc.stderr[-3000:]


def test_unreachable_packages_do_not_abort_the_host(host, unzipdir, model_description, tmp_path):
    """numpy, scipy, numba unreachable (the host's own PYTHONPATH without them): pythonfmu logs the fatal import
    error with a NULL category; the host must get a category (this host aborts on NULL, exit -6 before the fix)
    and fmi2Instantiate must return NULL (exit 3)."""
    md = model_description
    env = {**host_env(), "PYTHONPATH": str(tmp_path)}
    proc = run(host, [unzipdir, "--step", H, "--stop", 0.002, *run_args(md, "A", {}, start(md, "V"))], env=env)
    assert proc.returncode == 3, (proc.returncode, proc.stderr[-3000:])
    assert re.search(r"No module named '(numpy|scipy|numba)'", proc.stderr), proc.stderr[-3000:]
    assert "(logStatusFatal)" in proc.stderr and "the Python slave could not be started" in proc.stderr
    assert "NULL" not in proc.stderr


def test_long_messages_with_percent_signs_are_cut_safely(host, unzipdir, model_description, tmp_path):
    """A 200 kB error text full of printf directives (numpy, scipy and numba that fail to import with it): the
    host gets at most a few kB, '%' escaped (its logger formats the message), cut at a character boundary."""
    md = model_description
    for name in ("numpy", "scipy", "numba"):   # whichever the slave imports first
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(textwrap.dedent("""
            raise ImportError("100%s %n %d é€" * 20000 + "END")
        """))
    env = {**host_env(), "PYTHONPATH": str(tmp_path)}
    proc = run(host, [unzipdir, "--step", H, "--stop", 0.002, *run_args(md, "A", {}, start(md, "V"))], env=env)
    assert proc.returncode == 3, (proc.returncode, proc.stderr[-3000:])
    line = next(ln for ln in proc.stderr.splitlines() if "100%s %n" in ln)
    assert len(line.encode()) < 4200 and line.endswith("[... message truncated by the FMU]")
    assert "END" not in line
    line.encode("utf-8").decode("utf-8")   # valid UTF-8 (Python would have replaced a cut character)
    assert "\ufffd" not in line


# ----------------------------------------------------------------------------------------
# beside another pythonfmu FMU
# ----------------------------------------------------------------------------------------
TRIVIAL_SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class trivial_slave(Fmi2Slave):
    """A stock pythonfmu 0.7 FMU: y = k*t."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 2.0
        self.y = 0.0
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability="tunable"))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.y = self.k * (current_time + step_size)
        return True
'''


@pytest.fixture(scope="module")
def stock_fmu(tmp_path_factory) -> Path:
    """A trivial stock pythonfmu FMU (pythonfmu's own binary, no shim), unzipped."""
    d = tmp_path_factory.mktemp("stock")
    (d / "trivial_slave.py").write_text(TRIVIAL_SLAVE)
    proc = subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(d / "trivial_slave.py"), "-d",
                           str(d)], capture_output=True, text=True, timeout=300, cwd=d)
    assert proc.returncode == 0, proc.stderr
    from fmpy import extract
    return Path(extract(str(d / "trivial_slave.fmu"), unzipdir=str(d / "unzipped")))


def _stock_vr(stock) -> int:
    from fmpy import read_model_description
    return {v.name: v.valueReference for v in read_model_description(str(stock)).modelVariables}["y"]


@pytest.mark.parametrize("unload", ["reverse", "forward"])
@pytest.mark.parametrize("first", ["stock", "actuator"])
def test_beside_a_stock_pythonfmu_fmu_every_exit_is_clean(host, unzipdir, model_description, stock_fmu, first,
                                                          unload):
    """The stock FMU needs the three variables (pythonfmu alone finds no Python): host_env. The FMU listed first is
    loaded and instantiated first (with the stock one first it starts the interpreter and owns it); the libraries
    are closed in the order given. 20 runs each: all exit 0 with complete, correct results."""
    md = model_description
    act = ["--output", str(vrs(md)["x"]), "--instance", "A", "--input", f"{vrs(md)['V']}={start(md, 'V')!r}"]
    stock = ["--output", str(_stock_vr(stock_fmu)), "--instance", "S"]
    if first == "stock":
        args = [stock_fmu, "--step", H, "--stop", 0.02, "--unload", unload, *stock, "--fmu", unzipdir, *act]
    else:
        args = [unzipdir, "--step", H, "--stop", 0.02, "--unload", unload, *act, "--fmu", stock_fmu, *stock]
    codes = []
    for _ in range(N_EXITS):
        proc = run(host, args, env=host_env())
        codes.append(proc.returncode)
        if proc.returncode == 0:
            t = table(proc.stdout)
            y = t[f"S:{_stock_vr(stock_fmu)}"]
            assert len(t["time"]) == 21 and np.allclose(y[1:], 2.0 * t["time"][1:], rtol=0, atol=1e-15)
            assert t[f"A:{vrs(md)['x']}"][-1] > 0.0
    assert codes == [0] * N_EXITS, (codes, proc.stderr[-2000:])


def test_host_that_never_unloads_exits_cleanly(host, unzipdir, model_description, stock_fmu):
    """--unload none: the process exits with both libraries loaded (as some tools do)."""
    md = model_description
    act = ["--output", str(vrs(md)["x"]), "--instance", "A"]
    stock = ["--output", str(_stock_vr(stock_fmu)), "--instance", "S"]
    args = [stock_fmu, "--step", H, "--stop", 0.02, "--unload", "none", *stock, "--fmu", unzipdir, *act]
    codes = [run(host, args, env=host_env()).returncode for _ in range(10)]
    assert codes == [0] * 10, codes


# ----------------------------------------------------------------------------------------
# FMU state through the native API
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("params", [{}, {"r0": 0.003}])
def test_state_check_in_the_c_host(host, unzipdir, model_description, params):
    """Rollback bit-identical, serialize into a fresh instance bit-identical, freed state / garbage / truncated /
    NULL are fmi2Error: see fmi2_cs_host.c (--state-check). The run goes on to the end with the same results as
    a run without the check."""
    md = model_description
    base = [unzipdir, "--step", H, "--stop", 0.05, *run_args(md, "A", params, start(md, "V"))]
    proc = run(host, [*base, "--state-check", 17], env={})
    assert proc.returncode == 0, proc.stderr[-3000:]
    checks = [ln for ln in proc.stderr.splitlines() if ln.startswith("state-check A:")]
    assert len(checks) == 21 and all(ln.endswith(": ok") for ln in checks), checks
    assert "state-check A: fresh instance: bit-identical outputs: ok" in checks
    plain = run(host, base, env={})
    assert plain.returncode == 0 and plain.stdout == proc.stdout
