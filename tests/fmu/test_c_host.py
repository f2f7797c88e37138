"""The FMU in a non-Python host: tests/fmu/c_host/fmi2_cs_host.c, compiled here and run in a subprocess.

Every other test drives the FMU from Python (fmpy), where pythonfmu finds a running interpreter. A C host
has none. These runs use the classic manual set-up (``host_env``), which the status shim respects (it loads or
sets nothing the host already provides); tests/fmu/test_fmu_hosts.py runs the same host with no set-up at all
(the shim finds the interpreter in resources/python.json):

* ``LD_PRELOAD=<LIBDIR>/<LDLIBRARY>`` of this Python: pythonfmu's binary does not link libpython;
* ``PYTHONHOME=sys.base_prefix``: without it the embedded interpreter takes its standard library from the
  first ``python3`` on the host's PATH;
* ``PYTHONPATH=`` the venv's site-packages (numpy, scipy): PYTHONHOME ignores the venv; the slave module
  and pythonfmu's Python package come from the FMU's resources (pythonfmu puts them first on sys.path).

The runs use PATH=/usr/local/bin:/usr/bin:/bin (a host outside the venv), so PYTHONHOME is exercised.
Value references come from modelDescription.xml, never hard-coded.
"""
from __future__ import annotations

import importlib.util
import math
import os
import re
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
HOST_SRC = REPO / "tests" / "fmu" / "c_host" / "fmi2_cs_host.c"
# -ffp-contract=off: no fused multiply-add, so the host's V0*sin(2*pi*f*t) equals Python's bit for bit
HOST_CFLAGS = ("-std=c11", "-O2", "-Wall", "-Wextra", "-ffp-contract=off")
OUTS = ("x", "I", "F")
H, T = 1e-3, 1.0
RTOL = 1e-12
HOST_PATH = "/usr/local/bin:/usr/bin:/bin"   # a plain shell's PATH: not the venv's, maybe a system python3


def _find_c_compiler():
    spec = importlib.util.spec_from_file_location("build_fmu_for_c_host", REPO / "build_fmu.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.find_c_compiler()   # $CC, sysconfig's CC, cc, gcc (zig cc from PyPI as a last resort)


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    cc = _find_c_compiler()
    if cc is None:
        pytest.fail(f"no C compiler found ($CC, cc, gcc, or `pip install ziglang`): needed to build {HOST_SRC}")
    exe = tmp_path_factory.mktemp("c_host") / "fmi2_cs_host"
    proc = subprocess.run([*cc, *HOST_CFLAGS, "-o", str(exe), str(HOST_SRC), "-ldl", "-lm"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"compiling {HOST_SRC} failed:\n{proc.stderr}"
    assert not proc.stderr.strip(), f"compiler warnings (-Wall -Wextra):\n{proc.stderr}"
    return exe


def host_env() -> dict:
    """The environment a non-Python host needs to run this (pythonfmu) FMU with this Python and venv."""
    libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
    assert libpython.suffix == ".so" and libpython.is_file(), \
        f"{libpython}: this Python has no shared libpython (build it with --enable-shared)"
    site = list(dict.fromkeys([sysconfig.get_path("purelib"), sysconfig.get_path("platlib")]))
    home = sys.base_prefix if sys.base_exec_prefix == sys.base_prefix else f"{sys.base_prefix}:{sys.base_exec_prefix}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "LD_PRELOAD"}
    env.update(LD_PRELOAD=str(libpython), PYTHONHOME=home, PYTHONPATH=os.pathsep.join(site), PATH=HOST_PATH)
    return env


def run_host(host, unzipdir, args, expect_rc=0, stop=T, env=None):
    """Run the host; returns (process, {column: array}) with columns 'time' and '<instance>:<vr>'."""
    cmd = [str(host), str(unzipdir), "--step", repr(H), "--stop", repr(stop), *map(str, args)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env or host_env())
    assert proc.returncode == expect_rc, (proc.returncode, proc.stderr[-3000:])
    if not proc.stdout.strip():
        return proc, {}
    header, *rows = proc.stdout.strip().splitlines()
    data = np.array([[float(v) for v in row.split(",")] for row in rows])
    return proc, dict(zip(header.split(","), data.T))


def vrs(md) -> dict:
    return {v.name: v.valueReference for v in md.modelVariables}


def start(md, name) -> float:
    return float(next(v.start for v in md.modelVariables if v.name == name))


def run_args(md, name, params, V0, freq=None, outs=OUTS):
    """Host arguments for --output and one instance."""
    vr = vrs(md)
    args = ["--output", ",".join(str(vr[o]) for o in outs), "--instance", name, "--input", f"{vr['V']}={V0!r}"]
    if freq is not None:
        args += ["--sine", repr(freq)]
    return args + [f"{vr[k]}={float(v)!r}" for k, v in params.items()]


def columns(md, table, name, outs=OUTS) -> dict:
    vr = vrs(md)
    return {o: table[f"{name}:{vr[o]}"] for o in outs}


def fmpy_sim(unzipdir, params, V0=None, stop=T, **kw):
    from fmpy import simulate_fmu
    sv = dict(params)
    if V0 is not None:
        sv["V"] = V0
    return simulate_fmu(str(unzipdir), start_time=0.0, stop_time=stop, output_interval=H, start_values=sv,
                        output=list(kw.pop("output", OUTS)), **kw)


def assert_close(c, ref, what):
    """max |c - ref| <= RTOL * max |ref| for every output (and the same time grid)."""
    assert np.array_equal(c["time"], ref["time"]), what
    for o in OUTS:
        err = float(np.max(np.abs(c[o] - ref[o])))
        assert err <= RTOL * float(np.max(np.abs(ref[o]))), (what, o, err)


def test_embedded_python_is_this_python_with_the_venv(host, unzipdir, model_description):
    """With host_env the embedded interpreter imports the standard library of this Python and numpy/scipy
    from the venv (PYTHONVERBOSE=1 logs every module's source file)."""
    env = {**host_env(), "PYTHONVERBOSE": "1"}
    proc, table = run_host(host, unzipdir, run_args(model_description, "A", {}, 1.0), stop=0.002, env=env)
    # "# <pyc> matches <source>", or "# code object from <source>" (quoted or not) when there is no .pyc yet
    found = re.findall(r"^# (?:\S+ matches |code object from '?)"
                       r"(\S+/(encodings|numpy|scipy|pythonfmu)/__init__\.py)'?$", proc.stderr, re.M)
    src = {}
    for path, name in found:
        src.setdefault(name, path)   # the first import of that name (later: e.g. scipy/_lib/.../numpy)
    assert set(src) == {"encodings", "numpy", "scipy", "pythonfmu"}, proc.stderr[-2000:]
    assert Path(src["encodings"]).parent.parent == Path(sysconfig.get_path("stdlib")), src
    for name in ("numpy", "scipy"):
        assert Path(src[name]).parent.parent == Path(sysconfig.get_path("platlib")), src
    assert Path(src["pythonfmu"]).parent.parent.resolve() == Path(unzipdir).resolve() / "resources", src  # FMU's copy
    assert len(table["time"]) == 3


# ----------------------------------------------------------------------------------------
# 1. step response == fmpy (default parameters; a pull-in to contact; another parameter set)
# ----------------------------------------------------------------------------------------
STEP_CASES = {"default": ({}, 1.0), "contact_r0_4.5mm": ({"r0": 0.0045}, 1.0),
              "r0_3mm_C_m_0.8V": ({"r0": 0.003, "C": 0.3, "m": 0.006}, 0.8)}


@pytest.mark.parametrize("case", STEP_CASES)
def test_step_response_equals_fmpy(host, unzipdir, model_description, case):
    params, v_scale = STEP_CASES[case]
    V0 = v_scale * start(model_description, "V")
    proc, table = run_host(host, unzipdir, run_args(model_description, "A", params, V0))
    c = {"time": table["time"], **columns(model_description, table, "A")}
    assert len(c["time"]) == round(T / H) + 1 and proc.stderr == ""
    ref = fmpy_sim(unzipdir, params, V0)
    assert_close(c, ref, case)
    r0 = params.get("r0", start(model_description, "r0"))
    assert 0.0 < c["x"].max() <= r0
    assert (c["x"].max() == r0) == (case != "default")     # 4.5 mm and 3 mm pull in, 9 mm does not


# ----------------------------------------------------------------------------------------
# 2. sine input == fmpy with the same samples, both held over the step (zero-order hold)
# ----------------------------------------------------------------------------------------
def test_sine_input_equals_fmpy(host, unzipdir, model_description):
    """V(t) = V0 sin(2 pi f t). fmpy sets an input at each communication point t_k by linear interpolation in
    its table; with the samples given exactly at t_k = k*H (computed as fmpy does: start + k*interval) the
    interpolation returns the sample itself, so fmpy sets V(t_k) before doStep(t_k, H) as the C host does; the
    FMU (canInterpolateInputs="false") holds it over the step. Checked by reading V back: after the step from t_k
    both give exactly V(t_k), and a one-step-shifted hold changes x by far more than the tolerance."""
    md = model_description
    V0, f = 1.3 * start(md, "V"), 3.0
    n = round(T / H)
    t = np.array([0.0 + k * H for k in range(n + 1)])
    V = np.array([V0 * math.sin(2 * math.pi * f * tk) for tk in t])   # libm sin, as the C host
    outs = OUTS + ("V",)
    _, table = run_host(host, unzipdir, run_args(md, "A", {}, V0, freq=f, outs=outs))
    c = {"time": table["time"], **columns(md, table, "A", outs)}
    signal = np.array(list(zip(t, V)), dtype=[("time", float), ("V", float)])
    ref = fmpy_sim(unzipdir, {}, input=signal, output=outs)
    # the same zero-order hold: V read back after the step [t_k, t_k+1) is the sample V(t_k), in both hosts
    assert np.array_equal(c["time"], t)
    held = np.concatenate([[V[0]], V[:-1]])
    assert np.array_equal(c["V"], held) and np.array_equal(ref["V"], held)
    assert_close(c, ref, "sine")
    assert np.ptp(c["x"]) > 0.0 and np.min(c["F"]) >= 0.0 and np.min(c["I"]) < 0.0 < np.max(c["I"])
    # the check can tell the hold apart: V(t_k+1) held over [t_k, t_k+1) instead
    shifted = np.array(list(zip(t, np.append(V[1:], V0 * math.sin(2 * math.pi * f * (T + H))))), dtype=signal.dtype)
    other = fmpy_sim(unzipdir, {}, input=shifted)
    assert np.max(np.abs(other["x"] - c["x"])) > 1e3 * RTOL * np.max(np.abs(c["x"]))


# ----------------------------------------------------------------------------------------
# 3. a bad parameter: fmi2Error from fmi2ExitInitializationMode, named, no crash; fmi2Reset recovers
# ----------------------------------------------------------------------------------------
def test_bad_parameter_is_an_error_and_reset_recovers(host, unzipdir, model_description):
    md = model_description
    vr, V0, stop = vrs(md), start(md, "V"), 0.1
    bad = run_args(md, "bad", {"m": -1.0}, V0)
    proc, table = run_host(host, unzipdir, bad, expect_rc=13, stop=stop)   # exit 10 + fmi2Error, not a signal
    assert table == {} and proc.stdout == ""
    assert "fmi2_cs_host: fmi2ExitInitializationMode(bad) returned status 3 (fmi2Error)" in proc.stderr
    assert re.search(r"^\[fmi2Error 3\] bad .*\bparameter m\b.*-1", proc.stderr, re.M), proc.stderr
    assert "fmi2Fatal" not in proc.stderr and "status 4" not in proc.stderr
    reports = re.findall(r"^fmi2_cs_host: .*", proc.stderr, re.M)
    assert reports == ["fmi2_cs_host: fmi2ExitInitializationMode(bad) returned status 3 (fmi2Error)"], reports

    # the same process carries on: fmi2Reset (m back to its start value), r0 = 4.5 mm, initialize, run
    proc, table = run_host(host, unzipdir, bad + ["--reset", f"{vr['r0']}=0.0045"], stop=stop)
    reports = re.findall(r"^fmi2_cs_host: .*", proc.stderr, re.M)
    assert reports == ["fmi2_cs_host: fmi2ExitInitializationMode(bad) returned status 3 (fmi2Error)"], reports
    assert re.search(r"^\[fmi2Error 3\] bad .*\bparameter m\b", proc.stderr, re.M)
    c = {"time": table["time"], **columns(md, table, "bad")}
    ref = fmpy_sim(unzipdir, {"r0": 0.0045}, V0, stop=stop)
    assert_close(c, ref, "after reset")
    assert c["x"][-1] > 0.0


# ----------------------------------------------------------------------------------------
# 4. two instances in one host process, interleaved: each as if alone
# ----------------------------------------------------------------------------------------
def test_two_instances_interleaved_equal_single_runs(host, unzipdir, model_description):
    md = model_description
    V0, stop = start(md, "V"), 0.5
    runs = {"A": ({"r0": 0.0045}, V0, None),                                    # step, pulls in
            "B": ({"r0": 0.003, "C": 0.3, "m": 0.006}, 1.2 * V0, 4.0)}          # sine input
    alone = {}
    for name, (params, v0, f) in runs.items():
        _, table = run_host(host, unzipdir, run_args(md, name, params, v0, f), stop=stop)
        alone[name] = columns(md, table, name)
    args = run_args(md, "A", *runs["A"])
    args += run_args(md, "B", *runs["B"])[2:]        # second instance (--output given once)
    proc, table = run_host(host, unzipdir, args, stop=stop)
    assert list(table) == ["time"] + [f"{n}:{vrs(md)[o]}" for n in runs for o in OUTS]
    for name in runs:
        both = columns(md, table, name)
        for o in OUTS:
            assert np.array_equal(both[o], alone[name][o]), (name, o)
    assert not np.allclose(alone["A"]["x"], alone["B"]["x"])


# ----------------------------------------------------------------------------------------
# 5. the host process exits normally (the status shim finalizes Python before SciPy's C++ destructors)
# ----------------------------------------------------------------------------------------
def test_host_process_exits_normally_every_time(host, unzipdir, model_description):
    """pythonfmu finalizes Python in its library destructor during exit(), after SciPy's C++ static
    destructors: without the shim's atexit handler 8 of 10 such runs segfaulted (exit -11) after their work;
    and a Python exception passing through pythonfmu corrupts the interpreter's heap, so a bad parameter run
    crashed at exit (6 of 6) until the slave stopped raising under the shim. Twelve short runs (one
    instance, two instances, a bad parameter, a bad parameter then fmi2Reset): each exits with its own code."""
    md = model_description
    V0 = start(md, "V")
    one = run_args(md, "A", {}, V0)
    two = one + run_args(md, "B", {"r0": 0.003}, V0, 4.0)[2:]
    bad = run_args(md, "bad", {"m": -1.0}, V0)
    bad_reset = bad + ["--reset", f"{vrs(md)['r0']}=0.0045"]
    cases = [(one, 0), (two, 0), (bad, 13), (bad_reset, 0)] * 3
    codes = []
    for args, rc in cases:
        cmd = [str(host), str(unzipdir), "--step", repr(H), "--stop", "0.02", *map(str, args)]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=host_env())
        codes.append((proc.returncode, rc))
        if rc == 0:
            assert len(proc.stdout.strip().splitlines()) == 1 + 21, proc.stdout[-500:]
    assert all(got == want for got, want in codes), (codes, proc.stderr[-2000:])
