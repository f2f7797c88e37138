"""The FMI 3.0 co-simulation FMU (``build_fmu.py --fmi 3``, pythonfmu3): valid, complete, and equal to the FMI 2.0
FMU on the cross-check references (references/W20-D45: both run by harness.sim.fmurun through fmpy)."""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
REFS = REPO / "references" / "W20-D45"


def test_fmpy_validate_clean(fmu3_path):
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(fmu3_path)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0 and "No problems found" in proc.stdout, proc.stdout + proc.stderr


def test_model_description_complete(fmu3_path, fmu_path):
    root = ET.fromstring(zipfile.ZipFile(fmu3_path).read("modelDescription.xml"))
    assert root.get("fmiVersion") == "3.0"
    cs = root.find("CoSimulation")
    assert cs.get("modelIdentifier") == "mpc_actuator_fmi3"
    assert cs.get("canGetAndSetFMUState") == "false" and cs.get("canSerializeFMUState") == "false"
    units = {u.get("name") for u in root.find("UnitDefinitions")}
    variables = {v.get("name"): v for v in root.find("ModelVariables")}
    for name, v in variables.items():
        if v.tag == "Float64":
            assert v.get("unit") in units, name
    assert variables["x"].get("displayUnit") == "mm" and variables["time"].get("unit") == "s"
    # the same variables, units, causalities and start values as the FMI 2.0 FMU
    root2 = ET.fromstring(zipfile.ZipFile(fmu_path).read("modelDescription.xml"))
    for sv in root2.find("ModelVariables"):
        v = variables[sv.get("name")]
        t2 = sv.find("*")
        assert v.get("causality") == sv.get("causality") and v.get("unit") == t2.get("unit"), sv.get("name")
        assert v.get("start") == t2.get("start") or (v.get("start"), t2.get("start")) == ("false", "false"), sv.get("name")
    vr = {n: v.get("valueReference") for n, v in variables.items()}
    ms = root.find("ModelStructure")
    outputs = [e for e in ms if e.tag == "Output"]
    assert sorted(e.get("valueReference") for e in outputs) == sorted(
        vr[n] for n in ("x", "v", "F", "I", "B", "contact", "x_sensor", "F_sensor"))
    assert all(e.get("dependencies") == "" for e in outputs)
    init = {e.get("valueReference"): e.get("dependencies") for e in ms if e.tag == "InitialUnknown"}
    assert sorted(init[vr["contact"]].split()) == sorted([vr["r0"], vr["blocked"]])


def test_equals_the_fmi2_fmu_on_the_crosscheck_references(fmu3_path, fmu_path):
    """Every stored input of references/W20-D45 with its parameters, through both FMUs: identical outputs;
    and the FMI 3.0 FMU passes the cross-check itself."""
    from harness.analysis.validation import crosscheck
    from harness.sim import fmurun
    n = 0
    for inp in sorted(REFS.glob("*_in.csv")):
        test = inp.name.split("_")[0]
        p = crosscheck.load_reference_params(REFS, test, None)
        data = crosscheck.read_reference_csv(inp)
        r2 = fmurun.run(p, data["time"], data["V"], fmu_path=fmu_path)
        r3 = fmurun.run(p, data["time"], data["V"], fmu_path=fmu3_path)
        for k in r2:
            assert np.array_equal(np.asarray(r2[k], float), np.asarray(r3[k], float)), (test, k)
        n += 1
    assert n >= 5
    rep = crosscheck.check_references(REFS, fmu_path=fmu3_path)
    assert rep.passed, list(rep.lines())


def test_invalid_parameter_is_reported(fmu3_path, tmp_path):
    """No status shim for FMI 3.0: an invalid parameter fails fmi3ExitInitializationMode, the message names it."""
    code = ("import sys, fmpy\n"
            "try:\n"
            "    fmpy.simulate_fmu(sys.argv[1], stop_time=0.01, start_values={'m': -1.0}, debug_logging=True)\n"
            "except Exception as e:\n"
            "    print('FAILED', type(e).__name__, e)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(fmu3_path)], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    out = proc.stdout + proc.stderr
    assert "FAILED" in out and "parameter m" in out, out[-3000:]
