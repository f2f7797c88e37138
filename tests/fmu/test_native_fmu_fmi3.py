"""The FMI 3.0 native FMU (``build_fmu.py --native --fmi 3``: the native model's generated C code behind an FMI 3.0
co-simulation interface, fmu_shim/native/mpc_native_fmi3.c) against the FMI 2.0 native FMU and the pythonfmu3 FMU.

* fmpy validates it, and so does fmu-manipulation-toolbox's checker; its variables (names, value references, causality, variability, units, start values),
  units, default experiment and model structure are the pythonfmu3 FMU's (mpc_actuator_fmi3.fmu); its binary
  exports the FMI 3.0 co-simulation functions and no FMI 2.0 function;
* its outputs equal the FMI 2.0 native FMU's to 1e-12 relative on the default experiment and on random parameter,
  effect, term (fmu_src.terms), input and contact cases (Hypothesis), and it refuses the same invalid parameters
  (fmi3Error, logged);
* FMU state: a run restored to a saved (and a serialized) state repeats its outputs bit for bit.
"""
from __future__ import annotations

import ctypes
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.fmu.native_helpers import EFFECT_VALUES, REALS, assert_same_outputs, draw_terms
from tests.fmu.native_helpers import Run as _Run

REPO = Path(__file__).resolve().parents[2]
RTOL = 1e-12


@pytest.fixture(scope="module")
def native3_fmu_path(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("native3") / "mpc_actuator_native_fmi3.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--native", "--fmi", "3", "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert not proc.stderr.strip(), f"build_fmu.py --native --fmi 3 warned:\n{proc.stderr}"
    return out


@pytest.fixture(scope="module")
def dirs(native3_fmu_path, native_fmu_path, tmp_path_factory) -> tuple[str, str]:
    from fmpy import extract
    return (extract(str(native3_fmu_path), unzipdir=str(tmp_path_factory.mktemp("n3"))),
            extract(str(native_fmu_path), unzipdir=str(tmp_path_factory.mktemp("n2"))))


def Run(unzipdir: str, params: dict, blocked=False, fmi3=True):
    """One instance of the FMI 3.0 (fmi3=True) or FMI 2.0 native FMU (``native_helpers.Run``)."""
    return _Run(unzipdir, params, blocked, fmi3=fmi3)


def assert_equal_outputs(a: np.ndarray, b: np.ndarray, what):
    assert_same_outputs(a, b, what, rtol=RTOL, tiny=0.0)


# ------------------------------------------------------------------------------------------ the FMU file
def test_fmpy_validates_it(native3_fmu_path):
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(native3_fmu_path)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0 and "No problems found" in proc.stdout, proc.stdout + proc.stderr


def test_fmu_manipulation_toolbox_checker_accepts_it(native3_fmu_path):
    exe = Path(sys.executable).parent / "fmutool"
    assert exe.exists(), f"{exe} not found: install the test extra (fmu-manipulation-toolbox)"
    proc = subprocess.run([str(exe), "-input", str(native3_fmu_path), "-check"], capture_output=True, text=True,
                          timeout=1200)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "This FMU seems to be compliant with FMI-3.0." in out, out
    assert "No semantic error against the FMI-3 standard." in out, out
    assert "ERROR" not in out, out


@pytest.fixture(scope="module")
def pythonfmu3_md(fmu3_path) -> ET.Element:
    """modelDescription.xml of the pythonfmu3 FMU (build_fmu.py --fmi 3, the session's), the interface to match."""
    return ET.fromstring(zipfile.ZipFile(fmu3_path).read("modelDescription.xml"))


def test_model_description_has_the_pythonfmu3_fmus_variables(native3_fmu_path, pythonfmu3_md):
    nat = ET.fromstring(zipfile.ZipFile(native3_fmu_path).read("modelDescription.xml"))
    py = pythonfmu3_md
    assert [(v.tag, v.attrib, [(c.tag, c.attrib) for c in v]) for v in nat.find("ModelVariables")] == \
        [(v.tag, v.attrib, [(c.tag, c.attrib) for c in v]) for v in py.find("ModelVariables")]
    for tag in ("UnitDefinitions", "DefaultExperiment", "ModelStructure", "LogCategories"):
        assert ET.tostring(nat.find(tag)) == ET.tostring(py.find(tag)), tag
    for key in ("fmiVersion", "modelName", "description", "author", "variableNamingConvention"):
        assert nat.get(key) == py.get(key), key
    assert nat.get("fmiVersion") == "3.0" and nat.get("instantiationToken") != py.get("instantiationToken")
    cs = nat.find("CoSimulation")
    assert cs.get("modelIdentifier") == "mpc_actuator_native_fmi3" and cs.get("needsExecutionTool") == "false"
    assert cs.get("canGetAndSetFMUState") == cs.get("canSerializeFMUState") == "true"
    names = set(zipfile.ZipFile(native3_fmu_path).namelist())
    assert {"sources/mpc_native_fmi3.c", "sources/mpc_native.c", "sources/mpc_native_gen.h",
            "sources/mpc_native_vars.h", "sources/fmi3Functions.h", "sources/buildDescription.xml",
            "binaries/x86_64-linux/mpc_actuator_native_fmi3.so"} <= names
    assert not [n for n in names if n.startswith("resources/") or n.endswith(".py")]


def test_exports_fmi3_and_no_fmi2_functions(dirs):
    """llvm-nm's list of the library's exported functions: every FMI 3.0 co-simulation function, no FMI 2.0 one
    (mpc_native.c's FMI 2.0 layer is compiled in as static functions)."""
    from fmu_shim.native.package import exported_symbols
    from fmu_shim.native.package_fmi3 import FMI3_CS_FUNCTIONS
    names = exported_symbols(Path(dirs[0]) / "binaries" / "x86_64-linux" / "mpc_actuator_native_fmi3.so", "linux64")
    assert set(FMI3_CS_FUNCTIONS) <= names
    assert not [n for n in names if n.startswith("fmi2") or n.startswith("mpc_native")], sorted(names)


# ------------------------------------------------------------------------------------------ outputs
def test_default_experiment_equals_the_fmi2_native_fmu(native3_fmu_path, native_fmu_path):
    from fmpy import simulate_fmu
    outs = list(REALS) + ["contact"]
    a, b = (simulate_fmu(str(p), output=outs, output_interval=1e-3) for p in (native3_fmu_path, native_fmu_path))
    assert len(a) == len(b) == 1001
    assert np.array_equal(a["time"], b["time"])
    a, b = (np.column_stack([r[n].astype(float) for n in outs]) for r in (a, b))
    assert_equal_outputs(a, b, "default experiment")
    assert 0.7e-3 < a[-1, 0] < 0.8e-3   # settles near 0.741 mm (docs/fmu.md)


_EFFECT_VALUES = {k: v for d in EFFECT_VALUES.values() for k, v in d.items()}


@st.composite
def cases(draw):
    """Parameters (some refused: tau_th = 0 with Rth > 0), effects, terms, blocked, rtol, step and a piecewise
    input."""
    p = {"r0": draw(st.one_of(st.just(0.0), st.floats(0.0005, 0.012))), "a": draw(st.floats(0.008, 0.025)),
         "Em": 0.0423 * draw(st.floats(0.3, 3.0)), "C": draw(st.floats(0.01, 1.0)),
         "rtol": draw(st.sampled_from([1e-7, 1e-9, 1e-5]))}
    for k in draw(st.sets(st.sampled_from(sorted(_EFFECT_VALUES)))):
        p[k] = _EFFECT_VALUES[k] * draw(st.floats(0.2, 2.0))
    if "Rth" in p and "tau_th" not in p:
        p["tau_th"] = 0.0 if draw(st.booleans()) else 0.5
    if "Kc" in p and "tau_c" not in p:
        p["tau_c"] = 0.3
    if draw(st.booleans()):   # the generic term set (fmu_src.terms)
        draw_terms(draw, p)
    levels = draw(st.lists(st.tuples(st.floats(0.0, 25.0), st.integers(1, 60)), min_size=1, max_size=4))
    return p, draw(st.booleans()), draw(st.sampled_from([1e-3, 2.5e-4, 4e-3])), [v for v, n in levels for _ in range(n)]


def _check_case(dirs, case):
    p, blocked, h, V = case
    runs = [Run(dirs[0], p, blocked, fmi3=True), Run(dirs[1], p, blocked, fmi3=False)]
    ok = [r.init() for r in runs]
    assert ok[0] == ok[1], (case, ok, runs[0].log)
    if ok[0]:
        a, b = (r.simulate(V, h) for r in runs)
        assert_equal_outputs(a, b, case)
    else:
        assert any(status == 3 and "invalid parameter" in msg for status, msg in runs[0].log), runs[0].log
    for r in runs:
        r.close()


@settings(max_examples=10, deadline=None, suppress_health_check=list(HealthCheck))
@given(case=cases())
def test_random_cases_equal_the_fmi2_native_fmu(dirs, case):
    _check_case(dirs, case)


@pytest.mark.deep
@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck))
@given(case=cases())
def test_random_cases_equal_the_fmi2_native_fmu_deep(dirs, case):
    _check_case(dirs, case)


def test_refuses_invalid_parameters_and_recovers_after_reset(dirs):
    """An invalid parameter: fmi3ExitInitializationMode returns fmi3Error and logs the message naming it; after
    fmi3Reset the start values run normally."""
    r = Run(dirs[0], {"m": -1.0})
    assert not r.init()
    assert any(status == 3 and "parameter m [kg] must be > 0" in msg for status, msg in r.log), r.log
    r.fmu.reset()
    r.fmu.enterInitializationMode(startTime=0.0)
    r.fmu.exitInitializationMode()
    out = r.simulate([11.9] * 5, 1e-3)
    r.close()
    assert out[-1, 3] > 0.0   # the current rises


def test_fmu_state_repeats_the_run_bit_for_bit(dirs):
    """Save the state mid-run (in memory and serialized), run on, restore it: the same outputs again, bit for bit;
    and the doStep's time (the independent variable) follows."""
    r = Run(dirs[0], {"r0": 0.002})
    assert r.init()
    h, V = 1e-3, [11.9] * 60 + [0.0] * 60
    r.simulate(V[:40], h)
    state = r.fmu.getFMUState()
    blob = r.fmu.serializeFMUState(state)
    first = r.simulate(V[40:], h, t0=40 * h)
    assert r.fmu.getFloat64([r.vr["time"]])[0] == pytest.approx(len(V) * h)
    r.fmu.setFMUState(state)
    again = r.simulate(V[40:], h, t0=40 * h)
    r.fmu.setFMUState(r.fmu.deserializeFMUState(blob))
    third = r.simulate(V[40:], h, t0=40 * h)
    r.fmu.freeFMUState(state)
    r.close()
    assert np.array_equal(first, again) and np.array_equal(first, third)
    assert first[:, -1].any() and not first[-1, -1]   # contact, then release at V = 0


def test_model_exchange_is_refused_cleanly(dirs):
    """A co-simulation-only FMU: fmi3InstantiateModelExchange returns NULL with a logged error, no crash."""
    from fmpy import read_model_description
    md = read_model_description(dirs[0])
    lib = ctypes.CDLL(str(Path(dirs[0]) / "binaries" / "x86_64-linux" / "mpc_actuator_native_fmi3.so"))
    seen = []
    proto = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)
    cb = proto(lambda env, status, cat, msg: seen.append((status, msg.decode())))
    lib.fmi3InstantiateModelExchange.restype = ctypes.c_void_p
    inst = lib.fmi3InstantiateModelExchange(b"me", md.guid.encode(), None, False, False, None, cb)
    assert inst is None and seen and seen[0][0] == 3 and "co-simulation only" in seen[0][1]


@pytest.mark.slow
def test_cross_compiled_binaries_export_fmi3_only(tmp_path):
    """build_fmu.py --native <every platform> --fmi 3: each library (in its FMI 3.0 platform folder) exports every
    FMI 3.0 co-simulation function and no FMI 2.0 one (LLVM's object tools; the build checks it too)."""
    from fmu_shim.native.package import TARGETS, exported_symbols
    from fmu_shim.native.package_fmi3 import FMI3_CS_FUNCTIONS, PLATFORM_TUPLES
    out = tmp_path / "all3.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--native", ",".join(PLATFORM_TUPLES), "--fmi",
                           "3", "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr
    names = set(zipfile.ZipFile(out).namelist())
    for plat, folder in PLATFORM_TUPLES.items():
        member = f"binaries/{folder}/mpc_actuator_native_fmi3{TARGETS[plat][1]}"
        assert member in names, member
        lib = tmp_path / folder / Path(member).name
        lib.parent.mkdir()
        lib.write_bytes(zipfile.ZipFile(out).read(member))
        exported = exported_symbols(lib, plat)
        assert set(FMI3_CS_FUNCTIONS) <= exported, plat
        assert not [n for n in exported if n.startswith("fmi2")], plat
