"""FMU state save/restore through fmpy's FMU2Slave (fmi2GetFMUstate ... fmi2DeSerializeFMUstate).

The state covers everything that determines the future: the integrator's arrays S and W (front and view
state, stages, dense record, step size, contact/blocked mode, the held input), the effect and sensor states
(columns of W), the parameters and the slave's own fields (V, parameters, rtol, start time). The status shim
(fmu_shim/fmi2_status_shim.c) keeps its own FMU-state objects and serializes them with a header naming the
model; a freed or foreign state, garbage bytes or a state of another model are fmi2Error, never a crash.
The C host runs the same checks natively (tests/fmu/test_fmu_hosts.py, --state-check).
"""
from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

from test_fmu import OUT_REALS, V_START, Slave, value_refs

DT = 1e-3
EFFECTS_ON = {"r0": 0.003, "Rth": 8.0, "tau_th": 0.5, "ksat": 3.0, "Kc": 8.0, "tau_c": 0.3, "K5": 1e9,
              "lam": 0.3, "tau_s": 0.005}
CASES = {"default": {}, "contact_r0_3mm": {"r0": 0.003}, "effects_and_sensor_lag": EFFECTS_ON,
         "blocked": {"blocked": True}}


def _fmi_error(fn, *args):
    """Call fn; return the FMI status of the FMICallException it must raise."""
    from fmpy.fmi1 import FMICallException
    with pytest.raises(FMICallException) as info:
        fn(*args)
    return info.value.status


def _advance(s, t0, n, V):
    rows, t = [], t0
    for _ in range(n):
        rows.append(s.step(t, DT, V))
        t = round(t + DT, 12)
    return rows


def test_capability_flags_true(fmu_path):
    root = ET.fromstring(zipfile.ZipFile(fmu_path).read("modelDescription.xml"))
    cs = root.find("CoSimulation")
    assert cs.get("canGetAndSetFMUstate") == "true" and cs.get("canSerializeFMUstate") == "true"


@pytest.mark.parametrize("case", CASES)
def test_get_step_set_step_is_bit_identical(unzipdir, model_description, case):
    """Rollback: get the state at t, run 40 steps, set the state, run the same 40 steps: identical outputs, and
    identical to an instance that never rolled back. The state is taken in the middle of a held input (the
    integrator runs ahead of the view: dense output in use) and, for r0 = 3 mm, before the pull-in."""
    ref = Slave(unzipdir, model_description, "ref", CASES[case])
    ref.init(V_START)
    s = Slave(unzipdir, model_description, "rb", CASES[case])
    s.init(V_START)
    _advance(ref, 0.0, 7, V_START)
    _advance(s, 0.0, 7, V_START)
    state = s.fmu.getFMUstate()
    first = _advance(s, 0.007, 40, V_START)
    s.fmu.setFMUstate(state)
    again = _advance(s, 0.007, 40, V_START)
    straight = _advance(ref, 0.007, 40, V_START)
    assert first == again == straight
    if case == "contact_r0_3mm":
        assert any(r["contact"] for r in first)   # the rollback crosses the contact event
    # a rollback to a state before a change of the input (the held input is part of the state)
    s.fmu.setFMUstate(state)
    changed = _advance(s, 0.007, 5, 0.5 * V_START)
    assert changed != first[:5]
    s.fmu.setFMUstate(state)
    assert _advance(s, 0.007, 40, V_START) == first
    s.fmu.freeFMUstate(state)
    s.free()
    ref.free()


def test_pending_input_and_parameters_are_part_of_the_state(unzipdir, model_description):
    """V set after the last doStep (held for the next one) and the parameters are restored with the state."""
    vr = value_refs(model_description)
    s = Slave(unzipdir, model_description, "pending")
    s.init(V_START)
    _advance(s, 0.0, 3, V_START)
    s.fmu.setReal([vr["V"]], [0.7 * V_START])
    state = s.fmu.getFMUstate()
    s.fmu.setReal([vr["V"]], [0.1])
    s.fmu.setFMUstate(state)
    assert s.fmu.getReal([vr["V"]]) == [0.7 * V_START]
    s.fmu.doStep(currentCommunicationPoint=0.003, communicationStepSize=DT)
    a = s.outputs()
    s.fmu.setFMUstate(state)
    b = s.step(0.003, DT, 0.7 * V_START)
    assert a == b
    s.fmu.freeFMUstate(state)
    s.free()


def test_state_before_initialization_and_parameters(unzipdir, model_description):
    """A state taken in initialization mode (no model yet) restores the parameter values set then."""
    vr = value_refs(model_description)
    s = Slave(unzipdir, model_description, "early")
    f = s.fmu
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.setReal([vr["r0"]], [0.004])
    state = f.getFMUstate()
    f.setReal([vr["r0"]], [0.008])
    f.setFMUstate(state)
    assert f.getReal([vr["r0"]]) == [0.004]
    f.exitInitializationMode()
    f.freeFMUstate(state)
    s.free()


@pytest.mark.parametrize("case", ["contact_r0_3mm", "effects_and_sensor_lag"])
def test_serialize_then_deserialize_in_a_fresh_instance(unzipdir, model_description, case):
    """Serialize in one instance, deserialize in a fresh one (default parameters: the state brings its own),
    continue both: identical outputs for 150 steps."""
    a = Slave(unzipdir, model_description, "src", CASES[case])
    a.init(V_START)
    _advance(a, 0.0, 25, V_START)
    sa = a.fmu.getFMUstate()
    data = a.fmu.serializeFMUstate(sa)
    assert data[:8] == b"MPCFMUST"
    b = Slave(unzipdir, model_description, "fresh")
    b.init(0.3 * V_START)
    sb = b.fmu.deSerializeFMUstate(data)
    b.fmu.setFMUstate(sb)
    assert b.outputs() == a.outputs()
    assert _advance(a, 0.025, 150, V_START) == _advance(b, 0.025, 150, V_START)
    # serialization is deterministic and round-trips
    assert b.fmu.serializeFMUstate(sb) == data
    for s, st in ((a, sa), (b, sb)):
        s.fmu.freeFMUstate(st)
        s.free()


def _retarget(data: bytes, model_id: bytes = None, guid: bytes = None) -> bytes:
    """The serialized state with another model identifier / GUID (and a valid checksum)."""
    magic, version = data[:8], data[8:12]
    off = 12
    n = struct.unpack_from("<I", data, off)[0]
    mid = data[off + 4: off + 4 + n]
    off += 4 + n
    n = struct.unpack_from("<I", data, off)[0]
    g = data[off + 4: off + 4 + n]
    off += 4 + n
    n = struct.unpack_from("<Q", data, off)[0]
    payload = data[off + 8: off + 8 + n]
    mid, g = model_id or mid, guid or g
    body = (magic + version + struct.pack("<I", len(mid)) + mid + struct.pack("<I", len(g)) + g
            + struct.pack("<Q", len(payload)) + payload)
    h = 1469598103934665603
    for byte in body:
        h = ((h ^ byte) * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return body + struct.pack("<Q", h)


def test_wrong_model_garbage_freed_state_are_errors(unzipdir, model_description):
    from fmpy.fmi2 import fmi2FMUstate
    messages = []
    s = Slave(unzipdir, model_description, "errors", messages=messages)
    s.init(V_START)
    _advance(s, 0.0, 5, V_START)
    st = s.fmu.getFMUstate()
    data = s.fmu.serializeFMUstate(st)
    assert _retarget(data) == data   # the test's re-encoding is the shim's

    cases = {
        "another model": (_retarget(data, model_id=b"other_model"), "of model 'other_model'"),
        "another GUID": (_retarget(data, guid=b"{00000000-0000-0000-0000-000000000000}"), "not of this model"),
        "garbage": (b"\x00garbage bytes, not a state" * 3, "no MPCFMUST header"),
        "truncated": (data[:-9], "truncated"),
        "one byte changed": (data[:40] + bytes([data[40] ^ 1]) + data[41:], "damaged"),
        "a newer format": (data[:8] + struct.pack("<I", 2) + data[12:], "format version 2"),
    }
    for what, (bad, text) in cases.items():
        messages.clear()
        assert _fmi_error(s.fmu.deSerializeFMUstate, bad) == 3, what
        assert any(text in m for _, status, m in messages if status == 3), (what, messages)
    # a state of this model and GUID whose slave part is not a state (checksum valid): the slave says so
    payload_start = data.index(b'{"format"')
    junk = b"[1, 2, 3]".ljust(len(data) - 8 - payload_start)
    forged = _retarget(data[:payload_start] + junk + data[-8:])
    st2 = s.fmu.deSerializeFMUstate(forged)
    messages.clear()
    assert _fmi_error(s.fmu.setFMUstate, st2) == 3
    assert any("not a usable state" in m for _, _, m in messages), messages
    s.fmu.freeFMUstate(st2)
    # a freed state and a pointer that is no state
    stale = fmi2FMUstate(st.value)
    s.fmu.freeFMUstate(st)
    assert st.value is None
    assert _fmi_error(s.fmu.setFMUstate, stale) == 3
    assert _fmi_error(s.fmu.setFMUstate, fmi2FMUstate(id(messages))) == 3
    assert _fmi_error(s.fmu.serializeFMUstate, stale) == 3
    # after all that the instance works and its results are those of an instance without errors
    ref = Slave(unzipdir, model_description, "noerrors")
    ref.init(V_START)
    _advance(ref, 0.0, 5, V_START)
    assert _advance(s, 0.005, 20, V_START) == _advance(ref, 0.005, 20, V_START)
    s.free()
    ref.free()


def test_a_state_of_another_instance_is_refused_and_moves_serialized(unzipdir, model_description):
    """FMI 2.0 ties an FMU state to the instance it came from: the pointer of another instance's state is fmi2Error
    naming both instances (in every state function); serialized and deserialized in the other instance it brings
    its parameters along (a new model is built)."""
    vr = value_refs(model_description)
    messages = []
    a = Slave(unzipdir, model_description, "a", {"r0": 0.003, "C": 0.3})
    a.init(V_START)
    _advance(a, 0.0, 10, V_START)
    st = a.fmu.getFMUstate()
    b = Slave(unzipdir, model_description, "b", messages=messages)
    b.init(V_START)
    for call, args in ((b.fmu.setFMUstate, (st,)), (b.fmu.serializeFMUstate, (st,)),
                       (b.fmu.freeFMUstate, (st,))):
        messages.clear()
        assert _fmi_error(call, *args) == 3
        assert any("the FMUstate belongs to the instance 'a', not to this one ('b')" in m
                   for _, status, m in messages if status == 3), messages
    assert st.value is not None                      # b did not free a's state
    assert b.fmu.getReal([vr["r0"], vr["C"]]) != [0.003, 0.3]
    sb = b.fmu.deSerializeFMUstate(a.fmu.serializeFMUstate(st))
    b.fmu.setFMUstate(sb)
    assert b.fmu.getReal([vr["r0"], vr["C"]]) == [0.003, 0.3]
    assert _advance(a, 0.01, 30, V_START) == _advance(b, 0.01, 30, V_START)
    b.fmu.freeFMUstate(sb)
    a.fmu.freeFMUstate(st)
    a.free()
    b.free()


def _with_payload(data: bytes, edit) -> bytes:
    """The serialized state with its slave part (JSON) changed by ``edit(doc)`` and a valid checksum."""
    import json
    start = data.index(b'{"format"')
    doc = json.loads(data[start:-8])
    edit(doc)
    payload = json.dumps(doc, allow_nan=True).encode()
    head = data[:start - 8]
    body = head + struct.pack("<Q", len(payload)) + payload
    return _retarget(body + b"\0" * 8)


def _set_array(doc, key, row, col, value):
    import base64
    d = doc["model"][key]
    a = np.frombuffer(base64.b64decode(d["f8"]), "<f8").reshape(d["shape"]).copy()
    a[row, col] = value
    d["f8"] = base64.b64encode(a.tobytes()).decode()


@pytest.mark.parametrize("what, edit, named", [
    ("time NaN", lambda d: d["model"].__setitem__("t", float("nan")), "the model's time t = nan is not finite"),
    ("time inf", lambda d: d["model"].__setitem__("t", float("inf")), "the model's time t = inf is not finite"),
    ("time before start", lambda d: d["model"].__setitem__("t", -1.0), "t = -1.0 is before the start time"),
    ("view time differs", lambda d: d["model"].__setitem__("t", 0.5), "differs from its view time"),
    ("input NaN", lambda d: d["fields"].__setitem__("V", float("nan")), "field V = nan is not finite"),
    ("start time NaN", lambda d: d["fields"].__setitem__("_t0", float("nan")), "field _t0 = nan is not finite"),
    ("rtol", lambda d: d["fields"].__setitem__("rtol", 0.5), "field rtol = 0.5 is outside"),
    ("parameter", lambda d: d["fields"].__setitem__("m", -1.0), "parameter m [kg] must be > 0"),
    ("absurd parameter", lambda d: d["fields"].__setitem__("Em", 1e30), "parameters Em = 1e+30"),
    ("fields and model differ", lambda d: d["fields"].__setitem__("K2", 41.0), "the model's parameters differ"),
    ("x beyond r0", lambda d: _set_array(d, "W", 15, 1, 0.0095), "displacement x = 0.0095 m at the view is beyond "
                                                                   "the coil face r0 = 0.009 m"),
    ("state NaN", lambda d: _set_array(d, "W", 0, 2, float("nan")), "row 0, state 2 = nan is not finite"),
])
def test_a_restored_state_is_checked_field_by_field(unzipdir, model_description, what, edit, named):
    """A state of this model with a valid checksum but a field no run can produce (forged or damaged before it
    was serialized): fmi2SetFMUstate is fmi2Error naming the field, and the instance goes on as before."""
    messages = []
    s = Slave(unzipdir, model_description, "forged", messages=messages)
    s.init(V_START)
    _advance(s, 0.0, 5, V_START)
    st = s.fmu.getFMUstate()
    data = s.fmu.serializeFMUstate(st)
    assert _with_payload(data, lambda d: None) == data
    bad = s.fmu.deSerializeFMUstate(_with_payload(data, edit))
    messages.clear()
    assert _fmi_error(s.fmu.setFMUstate, bad) == 3
    assert any(named in m for _, status, m in messages if status == 3), (what, messages)
    ref = Slave(unzipdir, model_description, "unforged")
    ref.init(V_START)
    _advance(ref, 0.0, 5, V_START)
    assert _advance(s, 0.005, 10, V_START) == _advance(ref, 0.005, 10, V_START)
    for x in (st, bad):
        s.fmu.freeFMUstate(x)
    s.free()
    ref.free()


def test_slave_state_bytes_carry_the_integrator_arrays(unzipdir, model_description):
    """The slave part of the serialized state holds S and W bit-exactly (base64 of float64)."""
    import base64
    import json
    s = Slave(unzipdir, model_description, "bytes", EFFECTS_ON)
    s.init(V_START)
    _advance(s, 0.0, 12, V_START)
    st = s.fmu.getFMUstate()
    data = s.fmu.serializeFMUstate(st)
    doc = json.loads(data[data.index(b'{"format"'):-8])
    assert doc["format"] == "mpc_actuator-slave-state/1"
    model = doc["model"]
    W = np.frombuffer(base64.b64decode(model["W"]["f8"]), "<f8").reshape(model["W"]["shape"])
    S = np.frombuffer(base64.b64decode(model["S"]["f8"]), "<f8")
    assert W.shape[1] > 3          # effect and sensor states are columns of W
    assert model["t"] == pytest.approx(0.012, abs=1e-15) and S.size > 0
    assert set(doc["fields"]) >= {"V", "blocked", "rtol", "_t0", "r0", "tau_s"}
    s.fmu.freeFMUstate(st)
    s.free()


_STOCK_FOREIGN_STATE = r"""
import sys
sys.path.insert(0, sys.argv[2])
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from test_fmu import Slave, V_START
unz = sys.argv[1]
md = read_model_description(unz)
messages = []
a = Slave(unz, md, "a", {"r0": 0.003, "C": 0.3}, messages=messages, logging_on=True)
a.init(V_START)
for k in range(5):
    a.step(k * 1e-3, 1e-3, V_START)
st = a.fmu.getFMUstate()
data = a.fmu.serializeFMUstate(st)
# serialized, the state moves to another instance: restored there, it is that instance's
c = Slave(unz, md, "c", messages=messages, logging_on=True)
c.init(V_START)
sc = c.fmu.deSerializeFMUstate(data)
c.fmu.setFMUstate(sc)
print("moved", c.fmu.getReal([c.vr["r0"], c.vr["C"]]) == [0.003, 0.3])
a.fmu.setFMUstate(st)                              # a's own state: fine
print("own ok")
for name, state in (("b", st), ("d", sc)):         # a's state pointer in b; c's restored state in d
    other = Slave(unz, md, name, messages=messages, logging_on=True)
    other.init(V_START)
    messages.clear()
    try:
        other.fmu.setFMUstate(state)
        print(name, "accepted", other.fmu.getReal([other.vr["r0"]]))
    except FMICallException as e:
        print(name, "status", e.status, [m for _, s, m in messages if s >= 3 and "belongs to the instance" in m])
"""


def test_a_state_of_another_instance_is_refused_by_the_stock_binary_too(tmp_path):
    """Issue 24.4: without the status shim (``build_fmu.py --no-status-shim``; the win64 binary is pythonfmu's stock
    one everywhere) pythonfmu hands the slave's state object to the host as the FMUstate and passes it back to
    whichever instance it is given to: another instance took it and ran on with a's parameters. The slave's states
    name their instance: another instance's is refused (fmi2Fatal: the stock binary's only error status) with the
    message naming both; a serialized state still moves. In a subprocess (the stock instance is broken after
    fmi2Fatal)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from fmpy import extract
    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "stock.fmu"
    proc = subprocess.run([sys.executable, str(repo / "build_fmu.py"), "--out", str(out), "--no-status-shim"],
                          cwd=repo, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    unz = extract(str(out), unzipdir=str(tmp_path / "x"))
    env = dict(os.environ, PYTHONPATH=str(repo))     # this checkout's fmu_src (shared by the process's FMUs)
    run = subprocess.run([sys.executable, "-c", _STOCK_FOREIGN_STATE, unz, str(Path(__file__).parent)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    lines = run.stdout.splitlines()
    assert run.returncode == 0 and lines[:2] == ["moved True", "own ok"], run.stdout + run.stderr
    for name, owner in (("b", "a"), ("d", "c")):
        line = next(ln for ln in lines if ln.split()[0] == name)
        assert line.startswith(f"{name} status 4 ["), line
        assert f"the FMUstate belongs to the instance '{owner}', not to this one ('{name}')" in line, line
