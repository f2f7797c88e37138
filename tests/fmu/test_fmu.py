"""Tests of the packaged FMU (mpc_actuator.fmu) against independent formulas and references.

The FMU is built once per session into a temp dir (see conftest.py). References:
* static equilibrium K1 x^3 + K2 x = Em I^2 G(r0 - x), I = V/R, by brentq;
* a tight scipy DOP853 solution of the mechanical ODE with the exact RL current,
  a terminal event at x = r0 and the (inelastic) contact phase handled analytically;
* G(0) = 1.5 kB^2/a derived by hand, and G(r) by adaptive quadrature with a
  complex-step derivative of Eq. 2 (independent of fmu_src.field's analytic derivative).
"""
from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

from fmu_src.field import force_kernel
from fmu_src.specs import EFFECT_SPECS, SPECS, Params

REPO = Path(__file__).resolve().parents[2]
DEFAULT = Params()
RTOL = 1e-7                               # the FMU's default rtol parameter
V_START = 0.23 / DEFAULT.kB * DEFAULT.R   # the FMU's start value of V
OUT_REALS = ("x", "v", "F", "I", "B", "x_sensor", "F_sensor")


# ----------------------------------------------------------------------------------------
# independent references
# ----------------------------------------------------------------------------------------
def G_quad(r: float, p: Params) -> float:
    """G(r) from Eq. 2/3 by scipy.quad with a complex-step dB/dr (independent of field.py's derivative)."""
    a, kB = p.a, p.kB

    def b(rr, th):  # B/I, Eq. 2 (rr may be complex)
        s = math.sin(th)
        return kB * 0.5 * a**3 * math.cos(th) * (2 * a * a + 2 * rr * rr + a * rr * s) \
            / (a * a + rr * rr + 2 * a * rr * s) ** 2.5

    h = 1e-20
    integrand = lambda th: -b(r, th).real * (b(complex(r, h), th).imag / h)
    val, _ = quad(integrand, 0.0, math.atan2(0.5 * p.D, r), epsabs=0.0, epsrel=1e-13, limit=200)
    return val


def static_equilibrium(p: Params, V: float) -> float:
    """Smallest x in [0, r0) with K1 x^3 + K2 x = Em (V/R)^2 G(r0 - x) (G by quadrature)."""
    I = V / p.R
    f = lambda x: (p.K1 * x * x + p.K2) * x - p.Em * I * I * float(force_kernel(p.r0 - x, p.a, p.D, p.kB)[0])
    xs = np.linspace(0.0, p.r0, 2001)
    fs = [f(x) for x in xs]
    k = next(i for i in range(len(xs) - 1) if fs[i] < 0.0 <= fs[i + 1])
    return brentq(f, xs[k], xs[k + 1], xtol=1e-16, rtol=1e-15)


def reference_solution(p: Params, V: float, t_grid, rtol: float = 1e-10) -> dict:
    """x, v, I on t_grid for a voltage step V at t = 0 from rest (I = 0, x = v = 0).

    I(t) = V/R (1 - exp(-R t/L)) exactly; the mechanics by DOP853 (rtol 1e-10: itself
    accurate to ~3e-10 relative, checked against rtol 1e-13) with the
    force kernel by quadrature (fmu_src.field.force_kernel, not the spline table), a
    terminal event at x = r0, and the contact phase (x = r0, v = 0 while the magnetic
    force exceeds the spring force at r0) written down analytically.
    """
    t_grid = np.asarray(t_grid, dtype=float)
    tau, Iinf = p.L / p.R, V / p.R
    I_of = lambda t: Iinf * (-math.expm1(-t / tau))
    G = lambda r: float(force_kernel(r, p.a, p.D, p.kB)[0])
    G0 = G(0.0)
    spring_r0 = (p.K1 * p.r0 * p.r0 + p.K2) * p.r0
    net_contact = lambda t: p.Em * I_of(t) ** 2 * G0 - spring_r0

    def rhs(t, y):
        x, v = y
        F = p.Em * I_of(t) ** 2 * G(p.r0 - x)
        return [v, (F - p.C * v - (p.K1 * x * x + p.K2) * x) / p.m]

    def hit(t, y):
        return y[0] - p.r0
    hit.terminal, hit.direction = True, 1.0

    x = np.full(t_grid.shape, np.nan)
    v = np.full(t_grid.shape, np.nan)
    t0, y0, T = float(t_grid[0]), [0.0, 0.0], float(t_grid[-1])
    sc = max(p.r0, 1e-3)
    while t0 < T:
        sol = solve_ivp(rhs, (t0, T), y0, method="DOP853", rtol=rtol, atol=[1e-2 * rtol * sc, 1e-1 * rtol * sc],
                        dense_output=True, events=hit)
        assert sol.success, sol.message
        t1 = float(sol.t[-1])
        sel = (t_grid >= t0) & (t_grid <= t1)
        x[sel], v[sel] = sol.sol(t_grid[sel])
        if sol.status != 1:
            break
        tc = float(sol.t_events[0][0])
        if net_contact(tc) >= 0.0:
            # contact; with V constant from rest I(t) increases, so the net force only grows: no release
            sel = t_grid >= tc
            x[sel], v[sel] = p.r0, 0.0
            break
        t0, y0 = tc, [p.r0 * (1.0 - 1e-12), 0.0]  # touched without sticking: falls back
    return {"t": t_grid, "x": x, "v": v, "I": np.array([I_of(t) for t in t_grid])}


def rel_err(a, ref) -> float:
    a, ref = np.asarray(a, float), np.asarray(ref, float)
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


# ----------------------------------------------------------------------------------------
# helpers that drive the FMU
# ----------------------------------------------------------------------------------------
def value_refs(md) -> dict:
    return {v.name: v.valueReference for v in md.modelVariables}


LIVE_CALLBACKS: list = []   # every callback structure ever registered with fmpy's logger proxy, kept alive


def logging_callbacks(messages: list):
    """fmi2CallbackFunctions whose logger appends (instance name, status, message) to ``messages``.

    Like fmpy.simulate_fmu, through fmpy's logger proxy (which formats the printf-style message). The proxy
    is native and process-wide: it calls the logger registered last, also for instances that use fmpy's
    default callbacks. So the structure is kept alive for the whole process (a freed logger would be called
    later and crash the test process), and :func:`restore_default_logger` hands the proxy back to fmpy's
    printing logger when the instance is done.
    """
    from ctypes import byref
    from fmpy import calloc, free
    from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                           fmi2CallbackLoggerTYPE)
    from fmpy.logging import addLoggerProxy

    def logger(component, instance_name, status, category, message):
        messages.append(((instance_name or b"").decode(), status, (message or b"").decode()))

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(cb))
    LIVE_CALLBACKS.append(cb)
    return cb


def restore_default_logger() -> None:
    """Point fmpy's process-wide logger proxy back at fmpy's own printing logger (``printLogMessage``)."""
    from ctypes import byref
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, printLogMessage
    from fmpy.logging import addLoggerProxy
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(printLogMessage)
    addLoggerProxy(byref(cb))
    LIVE_CALLBACKS.append(cb)


class Slave:
    """A directly driven FMU2Slave instance (for interleaving, reset, feedthrough, error tests).

    ``messages``: a list that collects the FMU's log messages (see logging_callbacks);
    ``logging_on``: fmi2Instantiate's loggingOn.
    """

    def __init__(self, unzipdir, md, name="inst", params=None, messages=None, logging_on=False):
        from fmpy.fmi2 import FMU2Slave
        self.md, self.vr = md, value_refs(md)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        callbacks = None if messages is None else logging_callbacks(messages)
        self.own_logger = callbacks is not None
        self.fmu.instantiate(callbacks=callbacks, loggingOn=logging_on)
        self.params = dict(params or {})

    def init(self, V0, t0=0.0, params=None):
        f, vr = self.fmu, self.vr
        f.setupExperiment(startTime=t0)
        f.enterInitializationMode()
        for k, val in (self.params if params is None else params).items():
            if k == "blocked":
                f.setBoolean([vr[k]], [bool(val)])
            else:
                f.setReal([vr[k]], [float(val)])
        f.setReal([vr["V"]], [float(V0)])
        f.exitInitializationMode()
        return self.outputs()

    def outputs(self) -> dict:
        vals = self.fmu.getReal([self.vr[n] for n in OUT_REALS])
        o = dict(zip(OUT_REALS, vals))
        o["contact"] = bool(self.fmu.getBoolean([self.vr["contact"]])[0])
        return o

    def step(self, t, dt, V):
        self.fmu.setReal([self.vr["V"]], [float(V)])
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
        return self.outputs()

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()
        if self.own_logger:
            restore_default_logger()


def run_slave(unzipdir, md, params, t, V, name="inst") -> dict:
    """Run one instance on the grid t with V[k] held on [t[k], t[k+1])."""
    V = np.broadcast_to(np.asarray(V, float), np.shape(t))
    s = Slave(unzipdir, md, name, params)
    rows = [s.init(V[0], t0=t[0])]
    for i in range(1, len(t)):
        rows.append(s.step(t[i - 1], t[i] - t[i - 1], V[i - 1]))
    s.free()
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def sim(unzipdir, **kw):
    from fmpy import simulate_fmu
    kw.setdefault("output_interval", 1e-3)
    return simulate_fmu(str(unzipdir), **kw)


# ----------------------------------------------------------------------------------------
# package, modelDescription, validation
# ----------------------------------------------------------------------------------------
def test_zip_ships_physics_package(fmu_path):
    names = set(zipfile.ZipFile(fmu_path).namelist())
    src = {f"resources/fmu_src/{f}" for f in os.listdir(os.path.join(os.path.dirname(__file__), "..", "..", "fmu_src"))
           if f.endswith(".py") and f not in ("mpc_actuator.py", "mpc_actuator_fmi3.py", "mpc_controller.py", "statics.py")}
    # (the FMI 2 slave is resources/mpc_actuator.py; the FMI 3 slave is not imported; the controller FMU's slave
    # and the steady states it alone imports are not shipped here)
    shipped = {n for n in names if n.startswith("resources/fmu_src/") and n.endswith(".py")}
    assert shipped == src, (src - shipped, shipped - src)   # every module the slave imports, and only those
    assert {"resources/mpc_actuator.py", "resources/slavemodule.txt", "modelDescription.xml",
            "binaries/linux64/mpc_actuator.so"} <= names
    assert zipfile.ZipFile(fmu_path).read("resources/slavemodule.txt").decode().strip() == "mpc_actuator"


def test_fmpy_validate_cli_clean(fmu_path):
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(fmu_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "No problems found" in proc.stdout
    from fmpy import read_model_description
    read_model_description(str(fmu_path), validate=True, validate_variable_names=True,
                           validate_model_structure=True)


def _exponents(unit_el) -> dict:
    b = unit_el.find("BaseUnit")
    return {k: int(b.get(k, 0)) for k in ("kg", "m", "s", "A", "K")}


def test_model_description_units_structure_experiment(fmu_path):
    root = ET.fromstring(zipfile.ZipFile(fmu_path).read("modelDescription.xml"))
    units = {u.get("name"): u for u in root.find("UnitDefinitions")}
    E = {n: _exponents(u) for n, u in units.items()}

    def comb(*terms):  # product of units with integer powers
        out = {k: 0 for k in ("kg", "m", "s", "A", "K")}
        for name, pw in terms:
            base = E[name] if isinstance(name, str) else name
            for k in out:
                out[k] += pw * base[k]
        return out
    sec = {"kg": 0, "m": 0, "s": 1, "A": 0, "K": 0}
    kelvin = {"kg": 0, "m": 0, "s": 0, "A": 0, "K": 1}
    # dimensional identities (derived, not copied from the builder's table)
    assert E["m/s"] == comb(("m", 1), (sec, -1))
    assert E["N"] == comb(("kg", 1), ("m", 1), (sec, -2))
    assert E["V"] == comb(("Ohm", 1), ("A", 1))                     # Ohm's law
    assert E["T"] == comb(("N", 1), ("A", -1), ("m", -1))            # F = B I l
    assert E["H"] == comb(("V", 1), (sec, 1), ("A", -1))             # V = L dI/dt
    assert E["V"] == comb(("T", 1), ("m", 2), (sec, -1))             # V = dPhi/dt
    assert E["N/m"] == comb(("N", 1), ("m", -1))
    assert E["N/m3"] == comb(("N", 1), ("m", -3))
    assert E["N.s/m"] == comb(("N", 1), (sec, 1), ("m", -1))
    assert E["T/A"] == comb(("T", 1), ("A", -1))
    # F = Em * I^2 * G with G = integral (B/I) d(B/I)/dr  [T^2/(A^2 m)]
    assert E["N"] == comb(("N.m/T2", 1), ("A", 2), ("T/A", 2), ("m", -1))
    assert E["1"] == {"kg": 0, "m": 0, "s": 0, "A": 0, "K": 0}
    # effect parameters: dT = Rth * I^2 R (K per W), 1/B_sat^2, spring force K5 x^5, time constants
    assert E["K/W"] == comb((kelvin, 1), ("V", -1), ("A", -1))
    assert E["1/T2"] == comb(("T", -2))
    assert E["N/m5"] == comb(("N", 1), ("m", -5))
    assert E["s"] == sec
    mm = units["m"].find("DisplayUnit")
    assert mm.get("name") == "mm" and float(mm.get("factor")) == 1000.0 and float(mm.get("offset", 0)) == 0.0

    svs = root.find("ModelVariables").findall("ScalarVariable")
    by_name = {sv.get("name"): sv for sv in svs}
    for sv in svs:
        assert sv.get("description"), sv.get("name")
        real = sv.find("Real")
        if real is not None:
            assert real.get("unit") in units, sv.get("name")
    want = ({"V": "V", "x": "m", "v": "m/s", "F": "N", "I": "A", "B": "T", "x_sensor": "m", "F_sensor": "N"}
            | {s.name: s.unit for s in SPECS + EFFECT_SPECS})
    for name, unit in want.items():
        assert by_name[name].find("Real").get("unit") == unit, name
    for name in ("x", "a", "r0", "D", "x_sensor"):
        assert by_name[name].find("Real").get("displayUnit") == "mm", name
    for s in SPECS + EFFECT_SPECS:
        sv = by_name[s.name]
        assert (sv.get("causality"), sv.get("variability")) == ("parameter", "fixed")
        assert float(sv.find("Real").get("start")) == s.default
        assert sv.get("description") == s.description
    assert by_name["blocked"].find("Boolean").get("start") == "false"
    assert float(by_name["rtol"].find("Real").get("start")) == RTOL
    assert by_name["V"].get("causality") == "input"
    assert float(by_name["V"].find("Real").get("start")) == pytest.approx(0.23 / 0.29 * 15.0, rel=1e-15)

    index = {sv.get("name"): str(i + 1) for i, sv in enumerate(svs)}
    outputs = ["x", "v", "F", "I", "B", "contact", "x_sensor", "F_sensor"]
    for o in outputs:
        assert by_name[o].get("causality") == "output" and by_name[o].get("initial") == "calculated"
        assert by_name[o].find("*").get("start") is None
    ms = root.find("ModelStructure")
    out_unknowns = ms.find("Outputs").findall("Unknown")
    assert sorted(u.get("index") for u in out_unknowns) == sorted(index[o] for o in outputs)
    assert all(u.get("dependencies") == "" for u in out_unknowns)
    init_unknowns = ms.find("InitialUnknowns").findall("Unknown")
    assert [u.get("index") for u in init_unknowns] == sorted((index[o] for o in outputs), key=int)
    deps = {u.get("index"): u.get("dependencies") for u in init_unknowns}
    assert sorted(deps[index["contact"]].split()) == sorted([index["r0"], index["blocked"]])

    de = root.find("DefaultExperiment")
    assert (float(de.get("startTime")), float(de.get("stopTime")), float(de.get("stepSize"))) == (0.0, 1.0, 0.001)
    assert root.find("CoSimulation").get("modelIdentifier") == "mpc_actuator"


# ----------------------------------------------------------------------------------------
# command line, self-containedness, default experiment settles
# ----------------------------------------------------------------------------------------
def _read_result_csv(path) -> dict:
    """fmpy's CSV (booleans written as True/False, which fmpy.util.read_csv cannot parse)."""
    lines = open(path).read().splitlines()
    names = [n.strip('"') for n in lines[0].split(",")]
    cols = list(zip(*(line.split(",") for line in lines[1:])))
    conv = lambda s: 1.0 if s == "True" else 0.0 if s == "False" else float(s)
    out = {n: np.array([conv(s) for s in c]) for n, c in zip(names, cols)}
    out["contact"] = out["contact"].astype(bool)
    return out


_SHIM = """
import importlib.util, sys
# hide the repo: drop the editable-install finder; -I already drops cwd and PYTHONPATH
sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]
assert importlib.util.find_spec('fmu_src') is None, 'fmu_src importable outside the FMU'
sys.argv = ['fmpy'] + sys.argv[1:]
from fmpy.cli import main
main()
print('FMU_SRC=' + sys.modules['fmu_src'].__file__)
print('SLAVE=' + sys.modules['mpc_actuator'].__file__)
"""


def test_cli_simulate_default_experiment_settles(fmu_path, tmp_path):
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(tmp_path), "LANG": "C.UTF-8"}
    # 1) exactly the README command, no options
    bare = subprocess.run([sys.executable, "-m", "fmpy.cli", "simulate", str(fmu_path)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert bare.returncode == 0 and not bare.stderr.strip(), bare.stderr
    # 2) same run from a clean environment where the repo is not importable, saving the result
    csv = tmp_path / "out.csv"
    proc = subprocess.run([sys.executable, "-I", "-c", _SHIM, "simulate", str(fmu_path), "--output-file", str(csv)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    src = re.search(r"FMU_SRC=(.*)", proc.stdout).group(1)
    slave = re.search(r"SLAVE=(.*)", proc.stdout).group(1)
    assert src.endswith(os.path.join("resources", "fmu_src", "__init__.py")) and "/work/main/" not in src
    assert slave.endswith(os.path.join("resources", "mpc_actuator.py"))

    r = _read_result_csv(csv)
    t = r["time"]
    assert len(t) == 1001 and t[0] == 0.0 and t[-1] == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(np.diff(t), 1e-3, rtol=0, atol=1e-12)
    x_eq = static_equilibrium(DEFAULT, V_START)
    assert 0.0 < x_eq < DEFAULT.r0
    assert r["x"][-1] == pytest.approx(x_eq, rel=1e-7)
    assert abs(r["v"][-1]) < 1e-9
    assert r["I"][-1] == pytest.approx(V_START / DEFAULT.R, rel=1e-12)
    assert not r["contact"].any()
    # it is a step response: x rises from 0, overshoots (zeta = 0.625) and settles
    assert r["x"][0] == 0.0 and r["x"].max() > x_eq * 1.01
    assert np.max(np.abs(r["x"][t >= 0.5] - x_eq)) < 1e-9


# ----------------------------------------------------------------------------------------
# agreement with the pure-Python model and with the independent reference
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("r0", [0.009, 0.0045])
def test_fmu_equals_python_simulate(unzipdir, model_description, r0):
    from fmu_src.model import simulate
    t = np.round(np.arange(0.0, 0.3 + 1e-12, 1e-3), 12)
    V = V_START * (1.0 + 0.4 * np.sin(2 * np.pi * 7.0 * t)) * (t < 0.25)   # changes every step, then off
    fm = run_slave(unzipdir, model_description, {"r0": r0}, t, V)
    py = simulate(DEFAULT.with_(r0=r0), t, V, rtol=RTOL)
    for k in OUT_REALS:
        assert np.max(np.abs(fm[k] - py[k])) <= 1e-12 * np.max(np.abs(py[k])), k
    assert np.array_equal(fm["contact"], py["contact"])
    if r0 == 0.0045:
        assert fm["contact"].any() and not fm["contact"][-1]   # pulled in, then released when V = 0


@pytest.mark.parametrize("r0", [0.009, 0.0045, 0.003])
def test_communication_step_independence_vs_reference(unzipdir, r0):
    p = DEFAULT.with_(r0=r0)
    T = 0.3
    results = {}
    for h in (1e-3, 20e-3):
        res = sim(unzipdir, stop_time=T, output_interval=h, start_values={"r0": r0})
        t = res["time"]
        assert t[-1] == pytest.approx(T) and len(t) == round(T / h) + 1
        ref = reference_solution(p, V_START, t)
        results[h] = (res, ref)
        ex, eI = rel_err(res["x"], ref["x"]), rel_err(res["I"], ref["I"])
        assert ex <= 1e-6, (h, ex)
        assert eI <= 1e-6, (h, eI)
        in_contact = ref["x"] >= r0
        assert np.array_equal(res["contact"], in_contact), h
    pulled_in = results[1e-3][1]["x"][-1] >= r0
    assert pulled_in == (r0 < 0.009)   # 9 mm stays free; 4.5 mm and 3 mm pull in
    # the 20 ms grid is a subset of the 1 ms grid: same values at the shared points
    a, b = results[1e-3][0], results[20e-3][0]
    assert rel_err(a["x"][::20], b["x"]) <= 2e-6


# ----------------------------------------------------------------------------------------
# blocked mode, units of start values
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("r0", [0.0, 0.009])
def test_blocked_force(unzipdir, r0):
    p = DEFAULT
    res = sim(unzipdir, stop_time=0.3, start_values={"blocked": True, "r0": r0})
    assert np.all(res["x"] == 0.0) and np.all(res["v"] == 0.0)
    assert not res["contact"].any()
    I_end = V_START / p.R      # exp(-0.3*R/L) = exp(-37.5): steady
    G = 1.5 * p.kB ** 2 / p.a if r0 == 0.0 else G_quad(r0, p)
    if r0 == 0.0:
        assert G_quad(0.0, p) == pytest.approx(G, rel=1e-12)   # the hand derivation
    assert res["I"][-1] == pytest.approx(I_end, rel=1e-12)
    assert res["F"][-1] == pytest.approx(p.Em * I_end ** 2 * G, rel=1e-8)
    B_face = p.kB * I_end * p.a ** 3 / (p.a ** 2 + r0 ** 2) ** 1.5    # on-axis loop field
    assert res["B"][-1] == pytest.approx(B_face, rel=1e-12)
    if r0 == 0.0:
        assert res["B"][-1] == pytest.approx(0.23, rel=1e-12)  # the start voltage's design field
    # force follows the current: F/I^2 is constant in blocked mode
    k = res["I"] > 1e-3
    assert np.allclose(res["F"][k] / res["I"][k] ** 2, p.Em * G, rtol=1e-8)


def test_display_unit_start_value(unzipdir):
    a = sim(unzipdir, stop_time=0.1, start_values={"r0": (4.5, "mm")})
    b = sim(unzipdir, stop_time=0.1, start_values={"r0": 0.0045})
    assert np.array_equal(a["x"], b["x"])
    c = sim(unzipdir, stop_time=0.1)
    assert not np.array_equal(a["x"], c["x"])


def test_rtol_parameter_is_used(unzipdir):
    tight = sim(unzipdir, stop_time=0.2)
    loose = sim(unzipdir, stop_time=0.2, start_values={"rtol": 1e-4})
    ref = reference_solution(DEFAULT, V_START, tight["time"])
    assert rel_err(tight["x"], ref["x"]) < 1e-7
    assert rel_err(loose["x"], ref["x"]) > 10 * rel_err(tight["x"], ref["x"])
    assert rel_err(loose["x"], ref["x"]) < 1e-2


# ----------------------------------------------------------------------------------------
# bad parameters: fmi2Error at initialization (status shim), message names the parameter, host survives
# ----------------------------------------------------------------------------------------
BAD_PARAMETERS = [("m", 0.0), ("L", -1.0), ("R", 0.0), ("D", 0.0), ("r0", -0.001), ("Em", float("nan")),
                  ("rtol", 0.0), ("K2", float("inf")), ("Rth", -1.0)]
UNKNOWN_VR = 987654   # no such value reference: pythonfmu's set_real raises KeyError (an unexpected exception)


def _start_value(name: str) -> float:
    return RTOL if name == "rtol" else next(s.default for s in SPECS + EFFECT_SPECS if s.name == name)


@pytest.mark.parametrize("logging_on", [True, False], ids=["logging_on", "logging_off"])
@pytest.mark.parametrize("name,value", BAD_PARAMETERS)
def test_bad_parameter_is_rejected_and_named(unzipdir, model_description, name, value, logging_on):
    from fmpy.fmi1 import FMICallException
    messages = []
    s = Slave(unzipdir, model_description, f"bad_{name}", {name: value}, messages=messages, logging_on=logging_on)
    with pytest.raises(FMICallException) as exc:
        s.init(V_START)
    assert exc.value.function == "fmi2ExitInitializationMode"
    assert exc.value.status == 3  # fmi2Error (the status shim), not fmi2Fatal
    named = [(st, m) for _, st, m in messages if re.search(rf"\bparameter {re.escape(name)}\b", m)]
    assert named, messages                                       # delivered even with logging off
    assert all(st == 3 for st, _ in named), messages             # logged with status fmi2Error
    assert not any(st == 4 for _, st, _ in messages), messages   # no fmi2Fatal message
    assert all(inst == f"bad_{name}" for inst, _, _ in messages), messages

    # the same instance: fmi2Reset, valid parameters, initialize, steps == a fresh instance
    t = np.round(np.arange(0.0, 0.05 + 1e-12, 1e-3), 12)
    good = {name: _start_value(name), "r0": 0.0045}
    s.fmu.reset()
    assert s.fmu.getReal([s.vr[name]])[0] == _start_value(name)   # the start value again
    rows = [s.init(V_START, params=good)]
    for i in range(1, len(t)):
        rows.append(s.step(t[i - 1], t[i] - t[i - 1], V_START))
    s.free()
    fresh = run_slave(unzipdir, model_description, good, t, V_START, name="fresh")
    for k in OUT_REALS + ("contact",):
        assert np.array_equal(np.array([r[k] for r in rows]), fresh[k]), k
    assert fresh["x"][-1] > 0.0


def test_bad_parameter_through_simulate_fmu(unzipdir):
    """fmpy's high-level API without debug logging: fmi2Error, the message, and the host carries on."""
    from fmpy.fmi1 import FMICallException
    messages = []

    def logger(component, instance_name, status, category, message):
        messages.append((status, (message or b"").decode()))

    with pytest.raises(FMICallException) as exc:
        sim(unzipdir, stop_time=0.01, start_values={"Em": float("nan")}, logger=logger, debug_logging=False)
    assert exc.value.status == 3
    assert any(st == 3 and re.search(r"\bparameter Em must be finite\b", m) for st, m in messages), messages
    from fmu_src.model import simulate
    good = sim(unzipdir, stop_time=0.05)
    py = simulate(DEFAULT, good["time"], V_START, rtol=RTOL)
    assert np.max(np.abs(good["x"] - py["x"])) <= 1e-12 * np.max(np.abs(py["x"]))


def test_second_instance_keeps_working_while_first_failed(unzipdir, model_description):
    from fmpy.fmi1 import FMICallException
    t = np.round(np.arange(0.0, 0.1 + 1e-12, 1e-3), 12)
    prm = {"r0": 0.0045, "C": 0.3}
    alone = run_slave(unzipdir, model_description, prm, t, V_START, name="alone")
    b = Slave(unzipdir, model_description, "B", prm)
    rows = [b.init(V_START)]
    half = len(t) // 2
    for i in range(1, half):
        rows.append(b.step(t[i - 1], t[i] - t[i - 1], V_START))
    messages = []
    a = Slave(unzipdir, model_description, "A", {"L": 0.0}, messages=messages)
    with pytest.raises(FMICallException) as exc:
        a.init(V_START)
    assert exc.value.status == 3
    assert any(inst == "A" and st == 3 and "parameter L" in m for inst, st, m in messages), messages
    # the failed instance refuses further work with fmi2Error (until fmi2Reset) ...
    with pytest.raises(FMICallException) as exc:
        a.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    assert exc.value.status == 3
    # ... while B carries on as if alone
    for i in range(half, len(t)):
        rows.append(b.step(t[i - 1], t[i] - t[i - 1], V_START))
    a.fmu.freeInstance()   # allowed after fmi2Error
    b.free()
    for k in OUT_REALS + ("contact",):
        assert np.array_equal(np.array([r[k] for r in rows]), alone[k]), k
    assert alone["contact"].any()


def test_failed_do_step_is_an_error(unzipdir, model_description):
    """A doStep that cannot integrate (non-finite input) is a reported error too: fmi2Error, then fmi2Reset."""
    from fmpy.fmi1 import FMICallException
    messages = []
    s = Slave(unzipdir, model_description, "nan_input", messages=messages)
    s.init(V_START)
    s.step(0.0, 1e-3, V_START)
    with pytest.raises(FMICallException) as exc:
        s.step(1e-3, 1e-3, float("nan"))
    assert exc.value.function == "fmi2DoStep" and exc.value.status == 3
    assert any(st == 3 and "doStep at t=0.001" in m and "V=nan" in m for _, st, m in messages), messages
    s.fmu.reset()
    t = np.round(np.arange(0.0, 0.02 + 1e-12, 1e-3), 12)
    rows = [s.init(V_START)]
    for i in range(1, len(t)):
        rows.append(s.step(t[i - 1], t[i] - t[i - 1], V_START))
    s.free()
    fresh = run_slave(unzipdir, model_description, {}, t, V_START, name="fresh")
    assert np.array_equal(np.array([r["x"] for r in rows]), fresh["x"])


def test_unexpected_exception_stays_fatal(unzipdir, model_description):
    """An exception without a preceding error message (here pythonfmu's KeyError for an unknown value
    reference) is not a reported error: fmi2Fatal, and pythonfmu's message reaches the host."""
    from fmpy.fmi1 import FMICallException
    messages = []
    s = Slave(unzipdir, model_description, "unexpected", messages=messages, logging_on=False)
    with pytest.raises(FMICallException) as exc:
        s.fmu.setReal([UNKNOWN_VR], [1.0])
    assert exc.value.status == 4
    assert any(st == 4 and "Fatal py exception" in m for _, st, m in messages), messages   # even with logging off
    # the broken pythonfmu instance is not called again
    with pytest.raises(FMICallException) as exc:
        s.fmu.getReal([s.vr["x"]])
    assert exc.value.status == 4
    # no fmi2FreeInstance: after fmi2Fatal the standard allows no further call (see the subprocess test below)


_AFTER_FAILURE = """
import sys
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
unz, unknown_vr = sys.argv[1], int(sys.argv[2])
md = read_model_description(unz)
vr = {v.name: v.valueReference for v in md.modelVariables}

def new(name):
    f = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier='mpc_actuator', instanceName=name)
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    return f

def status(call, *args):
    try:
        call(*args)
        return 0
    except FMICallException as e:
        return e.status

a = new('a')                                   # error -> free
a.setReal([vr['m']], [0.0])
print('error', status(a.exitInitializationMode), flush=True)
a.freeInstance()
c = new('c')                                   # error -> reset -> run -> free
c.setReal([vr['R']], [-1.0])
print('error', status(c.exitInitializationMode), flush=True)
print('reset', status(c.reset), flush=True)
c.setupExperiment(startTime=0.0)
c.enterInitializationMode()
c.exitInitializationMode()
for k in range(20):
    c.doStep(k * 1e-3, 1e-3)
print('x', c.getReal([vr['x']])[0] > 0.0, flush=True)
c.terminate()
c.freeInstance()
b = new('b')                                   # fatal -> free (not allowed by the standard, but harmless)
print('fatal', status(b.setReal, [unknown_vr], [1.0]), flush=True)
b.freeInstance()
print('done', flush=True)
"""


def test_failed_instances_can_be_freed_without_crashing_the_host(unzipdir, tmp_path):
    """pythonfmu 0.7 keeps dangling pointers after a Python exception, and freeing such an instance
    crashes a PYTHONMALLOC=debug interpreter. The shim never calls the broken instance again."""
    env = {**os.environ, "PYTHONMALLOC": "debug"}
    proc = subprocess.run([sys.executable, "-c", _AFTER_FAILURE, str(unzipdir), str(UNKNOWN_VR)], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stdout, proc.stderr[-2000:])
    results = [line for line in proc.stdout.splitlines() if not line.startswith(("[", "("))]  # not fmpy's log
    assert results == ["error 3", "error 3", "reset 0", "x True", "fatal 4", "done"], proc.stdout
    assert "[ERROR] a: invalid parameter: parameter m [kg] must be > 0" in proc.stdout   # logging was off


# ----------------------------------------------------------------------------------------
# the status shim: binary layout, exports, clean compile, build without it
# ----------------------------------------------------------------------------------------
# FMI 2.0 standard: the common functions (section 2.1) and the co-simulation ones (section 4.2)
FMI2_CS_FUNCTIONS = """
fmi2GetTypesPlatform fmi2GetVersion fmi2SetDebugLogging fmi2Instantiate fmi2FreeInstance fmi2SetupExperiment
fmi2EnterInitializationMode fmi2ExitInitializationMode fmi2Terminate fmi2Reset fmi2GetReal fmi2GetInteger
fmi2GetBoolean fmi2GetString fmi2SetReal fmi2SetInteger fmi2SetBoolean fmi2SetString fmi2GetFMUstate
fmi2SetFMUstate fmi2FreeFMUstate fmi2SerializedFMUstateSize fmi2SerializeFMUstate fmi2DeSerializeFMUstate
fmi2GetDirectionalDerivative fmi2SetRealInputDerivatives fmi2GetRealOutputDerivatives fmi2DoStep fmi2CancelStep
fmi2GetStatus fmi2GetRealStatus fmi2GetIntegerStatus fmi2GetBooleanStatus fmi2GetStringStatus
""".split()


def _stock_binaries() -> Path:
    """pythonfmu's own binaries (from the installed distribution: once an FMU is instantiated in this process,
    ``import pythonfmu`` finds the copy in the FMU's resources, which has no binaries)."""
    from importlib.metadata import distribution
    return Path(distribution("pythonfmu").locate_file("pythonfmu/resources/binaries"))


def _build_fmu_module():
    import importlib.util
    spec = importlib.util.spec_from_file_location("build_fmu_for_tests", REPO / "build_fmu.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_binary_layout_and_shim_exports(fmu_path, tmp_path):
    import ctypes
    z = zipfile.ZipFile(fmu_path)
    assert sorted(n for n in z.namelist() if n.startswith("binaries/")) == [
        "binaries/linux64/mpc_actuator.so", "binaries/linux64/mpc_actuator_pythonfmu.so",
        "binaries/win64/mpc_actuator.dll"]
    stock = _stock_binaries()
    # the inner library is pythonfmu's binary unchanged; other platforms keep pythonfmu's stock binary
    assert z.read("binaries/linux64/mpc_actuator_pythonfmu.so") == (stock / "linux64" / "libpythonfmu-export.so").read_bytes()
    assert z.read("binaries/win64/mpc_actuator.dll") == (stock / "win64" / "pythonfmu-export.dll").read_bytes()
    shim = z.read("binaries/linux64/mpc_actuator.so")
    assert shim[:4] == b"\x7fELF" and len(shim) < 200_000
    assert z.getinfo("binaries/linux64/mpc_actuator.so").external_attr == \
        z.getinfo("binaries/linux64/mpc_actuator_pythonfmu.so").external_attr
    assert len(FMI2_CS_FUNCTIONS) == 34
    path = tmp_path / "mpc_actuator.so"
    path.write_bytes(shim)
    lib = ctypes.CDLL(str(path))   # only the shim: the inner library is loaded by fmi2Instantiate
    missing = [f for f in FMI2_CS_FUNCTIONS if not hasattr(lib, f)]
    assert not missing, missing
    for f in ("fmi2GetVersion", "fmi2GetTypesPlatform"):
        getattr(lib, f).restype = ctypes.c_char_p
    assert lib.fmi2GetVersion() == b"2.0" and lib.fmi2GetTypesPlatform() == b"default"
    assert not hasattr(lib, "load_inner") and not hasattr(lib, "shim_logger")   # internals stay hidden


def test_status_shim_compiles_without_warnings(tmp_path):
    bf = _build_fmu_module()
    cc = bf.find_c_compiler()
    assert cc, "no C compiler"
    assert {"-Wall", "-Wextra"} <= set(bf.SHIM_CFLAGS)
    cmd = [*cc, *bf.SHIM_CFLAGS, "-Werror", "-o", str(tmp_path / "shim.so"), str(bf.SHIM_SRC), *bf.SHIM_LIBS]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and not proc.stderr.strip(), proc.stderr
    assert bf.SHIM_SRC.parent.name == "fmu_shim"   # outside fmu_src (which is shipped into the FMU)


_STOCK_BAD_PARAMETER = """
import sys
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
unz = sys.argv[1]
md = read_model_description(unz)
vr = {v.name: v.valueReference for v in md.modelVariables}
f = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier='mpc_actuator', instanceName='stock')
f.instantiate()
f.setupExperiment(startTime=0.0)
f.enterInitializationMode()
f.setReal([vr['m']], [0.0])
try:
    f.exitInitializationMode()
except FMICallException as e:
    print('status', e.status)
"""


def test_build_without_status_shim(tmp_path):
    out = tmp_path / "stock.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--out", str(out), "--no-status-shim"],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "without the status shim" in proc.stderr and "fmi2Fatal" in proc.stderr
    z = zipfile.ZipFile(out)
    assert sorted(n for n in z.namelist() if n.startswith("binaries/")) == [
        "binaries/linux64/mpc_actuator.so", "binaries/win64/mpc_actuator.dll"]
    assert z.read("binaries/linux64/mpc_actuator.so") == (_stock_binaries() / "linux64" / "libpythonfmu-export.so").read_bytes()
    from fmpy import extract
    unz = extract(str(out), unzipdir=str(tmp_path / "x"))
    # the stock binary: fmi2Fatal (in a subprocess: the broken pythonfmu instance stays behind)
    run = subprocess.run([sys.executable, "-c", _STOCK_BAD_PARAMETER, unz], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0 and run.stdout.split() == ["status", "4"], run.stdout + run.stderr


def test_built_fmu_has_the_umask_mode(tmp_path):
    """build_fmu.py writes through a temporary file (mkstemp: 0600); the FMU must get 0666 minus the umask."""
    import stat
    out = tmp_path / "modes.fmu"
    proc = subprocess.run([sys.executable, "-c", "import os, runpy, sys; os.umask(0o022); sys.argv = sys.argv[1:]; "
                           "runpy.run_path(sys.argv[0], run_name='__main__')", str(REPO / "build_fmu.py"),
                           "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert stat.S_IMODE(out.stat().st_mode) == 0o644


def test_build_without_c_compiler_fails_clearly(tmp_path):
    empty = tmp_path / "empty_path"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env["PATH"] = str(empty)
    out = tmp_path / "never.fmu"
    # hide the PyPI toolchain ziglang too, in case it is installed (sys.modules[name] = None: not importable)
    runner = ("import runpy, sys; sys.modules['ziglang'] = None; sys.argv = sys.argv[1:]; "
              "runpy.run_path(sys.argv[0], run_name='__main__')")
    proc = subprocess.run([sys.executable, "-c", runner, str(REPO / "build_fmu.py"), "--out", str(out)], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert "no C compiler found" in proc.stderr and "--no-status-shim" in proc.stderr, proc.stderr
    assert "pip install ziglang" in proc.stderr, proc.stderr
    assert not out.exists() and not list(tmp_path.glob("never.fmu*"))


def test_compiler_falls_back_to_ziglang_without_system_compiler(tmp_path):
    """No $CC, no cc/gcc on PATH: the builder takes `python -m ziglang cc` when the package ziglang is importable
    (a stand-in package here; the real one is a 400 MB toolchain that make installs only when there is no cc)."""
    empty = tmp_path / "empty_path"
    empty.mkdir()
    (tmp_path / "fake" / "ziglang").mkdir(parents=True)
    (tmp_path / "fake" / "ziglang" / "__init__.py").write_text("")
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env["PATH"] = str(empty)
    env["PYTHONPATH"] = str(tmp_path / "fake")
    code = ("import sys, sysconfig; sysconfig.get_config_vars()['CC'] = 'no-such-cc-here'; "
            f"sys.path.insert(0, {str(REPO)!r}); import build_fmu; print(build_fmu.find_c_compiler())")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str([sys.executable, "-m", "ziglang", "cc"]), proc.stdout
    # with a system compiler on PATH it is preferred over ziglang
    env["PATH"] = os.environ["PATH"]
    proc = subprocess.run([sys.executable, "-c", code.replace("no-such-cc-here", "")], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "ziglang" not in proc.stdout, proc.stdout + proc.stderr


# ----------------------------------------------------------------------------------------
# instances, repeatability, reset, no direct feedthrough
# ----------------------------------------------------------------------------------------
def test_two_instances_interleaved_share_no_state(unzipdir, model_description):
    t = np.round(np.arange(0.0, 0.2 + 1e-12, 1e-3), 12)
    cfg = {"A": ({"r0": 0.009}, V_START), "B": ({"r0": 0.003, "C": 0.3, "m": 0.006}, 0.8 * V_START)}
    alone = {k: run_slave(unzipdir, model_description, prm, t, V, name=f"alone{k}") for k, (prm, V) in cfg.items()}
    sl = {k: Slave(unzipdir, model_description, f"inter{k}", prm) for k, (prm, _) in cfg.items()}
    rows = {k: [sl[k].init(cfg[k][1])] for k in cfg}
    for i in range(1, len(t)):
        for k in ("B", "A") if i % 2 else ("A", "B"):
            rows[k].append(sl[k].step(t[i - 1], t[i] - t[i - 1], cfg[k][1]))
    for s in sl.values():
        s.free()
    for k in cfg:
        for name in OUT_REALS + ("contact",):
            assert np.array_equal(np.array([r[name] for r in rows[k]]), alone[k][name]), (k, name)
    assert not np.allclose(alone["A"]["x"], alone["B"]["x"])
    assert alone["B"]["contact"].any() and not alone["A"]["contact"].any()


def test_sequential_runs_identical(unzipdir):
    a = sim(unzipdir, stop_time=0.2, start_values={"r0": 0.003})
    b = sim(unzipdir, stop_time=0.2, start_values={"r0": 0.003})
    for name in a.dtype.names:
        assert np.array_equal(a[name], b[name]), name


def test_reset_returns_to_start_values(unzipdir, model_description):
    vr = value_refs(model_description)
    t = np.round(np.arange(0.0, 0.1 + 1e-12, 1e-3), 12)
    fresh = run_slave(unzipdir, model_description, {}, t, V_START, name="fresh")

    s = Slave(unzipdir, model_description, "resettable", {"r0": 0.003, "blocked": False, "K2": 25.0, "rtol": 1e-6,
                                                          "Rth": 5.0, "tau_th": 2.0, "tau_s": 0.01})
    s.init(0.5 * V_START)
    for i in range(1, 60):
        s.step(t[i - 1], t[i] - t[i - 1], 0.5 * V_START)
    assert s.fmu.getReal([vr["r0"]])[0] == 0.003
    s.fmu.reset()
    # after fmi2Reset every variable has its start value again
    for spec in SPECS + EFFECT_SPECS:
        assert s.fmu.getReal([vr[spec.name]])[0] == spec.default, spec.name
    assert s.fmu.getReal([vr["V"], vr["rtol"]]) == [V_START, RTOL]
    rows = [s.init(V_START, params={})]
    for i in range(1, len(t)):
        rows.append(s.step(t[i - 1], t[i] - t[i - 1], V_START))
    s.free()
    for name in OUT_REALS + ("contact",):
        assert np.array_equal(np.array([r[name] for r in rows]), fresh[name]), name


def test_outputs_have_no_direct_feedthrough_and_initial_values(unzipdir, model_description):
    # InitialUnknowns: all outputs are 0 after initialization whatever V and the parameters,
    # except contact = (r0 == 0 and not blocked)
    for prm, V0, contact in (({}, V_START, False), ({"r0": 0.0}, 3.0, True),
                             ({"r0": 0.0, "blocked": True}, 0.0, False)):
        s = Slave(unzipdir, model_description, "init", prm)
        o = s.init(V0)
        assert [o[k] for k in OUT_REALS] == [0.0] * len(OUT_REALS) and o["contact"] is contact
        s.free()
    # Outputs dependencies="": setting V changes no output before the next doStep
    s = Slave(unzipdir, model_description, "feedthrough")
    s.init(V_START)
    o1 = s.step(0.0, 0.01, V_START)
    s.fmu.setReal([s.vr["V"]], [0.0])
    assert s.outputs() == o1
    o2 = s.step(0.01, 0.01, 0.0)
    assert o2["I"] < o1["I"]
    s.free()


def test_pythonfmu_state_is_released_before_its_static_destructor(fmu_path, tmp_path):
    """pythonfmu 0.7 keeps its interpreter state in a static shared_ptr; at exit the shared_ptr's destructor
    runs first (exit handlers) and pythonfmu's library destructor then assigns nullptr to the destroyed object,
    releasing it twice (heap corruption: "corrupted double-linked list" in about 1 of 400 short fmpy runs).
    The status shim calls pythonfmu's finalizePythonInterpreter() while the shared_ptr is alive (at unload or
    from an atexit handler). Checked under gdb, deterministically: the first finalizePythonInterpreter call
    must come before the first ~shared_ptr<PyState>, and the process must exit normally."""
    import shutil
    if shutil.which("gdb") is None:
        pytest.skip("gdb is not installed (Debian package gdb): it orders the two calls")
    script = tmp_path / "run.py"
    script.write_text(f"import fmpy\nfmpy.simulate_fmu({str(fmu_path)!r}, stop_time=0.01, output_interval=1e-3, "
                      "output=['x'])\nprint('done')\n")
    cmds = tmp_path / "gdb.cmd"
    cmds.write_text("set breakpoint pending on\nset pagination off\n"
                    "break finalizePythonInterpreter\ncommands\nsilent\nprintf \"HIT finalize\\n\"\ncontinue\nend\n"
                    "break _ZNSt10shared_ptrIN9pythonfmu7PyStateEED2Ev\ncommands\nsilent\n"
                    "printf \"HIT dtor\\n\"\ncontinue\nend\nrun\n")
    proc = subprocess.run(["gdb", "-q", "-batch", "-x", str(cmds), "--args", sys.executable, str(script)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    hits = [line.split()[1] for line in proc.stdout.splitlines() if line.startswith("HIT ")]
    assert "done" in proc.stdout and "exited normally" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "dtor" in hits and "finalize" in hits, (hits, proc.stdout[-2000:])
    assert hits.index("finalize") < hits.index("dtor"), hits


def test_build_after_an_fmu_ran_in_the_same_process(tmp_path):
    """An FMU instantiated in-process puts its copy of pythonfmu (without binaries) first on sys.path; ``jobs.build``
    in that process still ships the binaries (run in a fresh interpreter, so that the order of imports is this
    one)."""
    import json
    import subprocess
    import sys
    from fmu_src.specs import Params
    from harness.data.paramsjson import params_to_json
    pf = tmp_path / "p.json"
    pf.write_text(json.dumps({"samples": {"W20-D45": {"parameters": params_to_json(Params())}}}))
    code = (f"import sys, zipfile; sys.path.insert(0, {str(REPO)!r})\n"
            "from harness import jobs\n"
            f"import fmpy; fmpy.simulate_fmu({str(REPO / 'mpc_actuator.fmu')!r}, stop_time=0.01, output_interval=1e-3)\n"
            "import pythonfmu; assert 'resources' in pythonfmu.__file__, pythonfmu.__file__\n"
            f"p, _ = jobs.build({str(pf)!r}, {str(tmp_path / 'x.fmu')!r})\n"
            "print(sorted(n for n in zipfile.ZipFile(p).namelist() if n.startswith('binaries/linux64/')))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "'binaries/linux64/mpc_actuator.so', 'binaries/linux64/mpc_actuator_pythonfmu.so'" in r.stdout
