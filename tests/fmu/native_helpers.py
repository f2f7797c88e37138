"""Helpers shared by the native FMU's tests (tests/fmu/test_native_fmu*.py): one FMU instance driven through fmpy
(FMI 2.0 or 3.0 co-simulation), the output comparisons, and the Python side's verdict on a parameter set."""
from __future__ import annotations

import numpy as np

from fmu_src.model import check_integrable
from fmu_src.specs import Params, validate

REALS = ("x", "v", "F", "I", "B", "x_sensor", "F_sensor")
RTOL_OUT = 1e-9
# Below the smallest normal double (2.2e-308) IEEE doubles are subnormal: a fixed absolute spacing of 2**-1074
# (4.9e-324) instead of 53 significant bits. The C code evaluates each formula in SymPy's order (the factors of
# Em*I*I*G as G*pow(I, 2)*Em), numba in the order fmu_src writes it; in the normal range the two orders differ
# by an ulp (1e-16), but an output that is itself subnormal (F at I ~ 1e-157 A, B at I ~ 1e-309 A: inputs of
# 1e-150 V and less, which Hypothesis draws as "nasty" floats) keeps only the bits above 2**-1074, and the two
# orders round different intermediates away: 1e-9 relative and more (up to every bit of an output at 1e-318).
# Differences that small are not compared relatively: an output may also differ by up to TINY_OUT absolute
# (test_subnormal_outputs_differ_by_the_operation_order shows one such case bit for bit).
TINY_OUT = float(np.finfo(float).tiny)
# effect parameters that switch each effect on (moderate values; tests scale them)
EFFECT_VALUES = {"coil_heating": {"Rth": 8.0, "tau_th": 0.5}, "filler_saturation": {"ksat": 3.0},
                 "viscoelastic_creep": {"Kc": 8.0, "tau_c": 0.3}, "edge_stiffening": {"K5": 1e9},
                 "motional_emf": {"lam": 0.3}, "sensor_lag": {"tau_s": 0.005}}


def read_md(path):
    """fmpy's model description of an FMU file or folder, validated."""
    from fmpy import read_model_description
    return read_model_description(str(path), validate=True)


class Run:
    """One instance of a co-simulation FMU (FMI 2.0, or 3.0 with ``fmi3``) through fmpy: parameters, then a held
    input per step; the FMI 3.0 log messages collected in ``log`` as (status, message)."""

    def __init__(self, unzipdir, params: dict, blocked=False, fmi3=False, md=None):
        self.md = md if md is not None else read_md(unzipdir)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmi3, self.log, self._open = fmi3, [], True
        kw = dict(guid=self.md.guid, unzipDirectory=unzipdir, modelIdentifier=self.md.coSimulation.modelIdentifier,
                  instanceName="run")
        if fmi3:
            from fmpy.fmi3 import FMU3Slave
            self.fmu = FMU3Slave(**kw)
            self.fmu.instantiate(logMessage=lambda env, status, cat, msg: self.log.append((status, msg.decode())))
            self._set, self._get = self.fmu.setFloat64, self.fmu.getFloat64
        else:
            from fmpy.fmi2 import FMU2Slave
            self.fmu = FMU2Slave(**kw)
            self.fmu.instantiate()
            self.fmu.setupExperiment(startTime=0.0)
            self._set, self._get = self.fmu.setReal, self.fmu.getReal
        if params:
            self._set([self.vr[k] for k in params], [float(v) for v in params.values()])
        self.fmu.setBoolean([self.vr["blocked"]], [bool(blocked)])
        if fmi3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.enterInitializationMode()

    def init(self) -> bool:
        """exitInitializationMode; False on an error status (the instance stays: ``close`` it)."""
        from fmpy.fmi1 import FMICallException
        try:
            self.fmu.exitInitializationMode()
        except FMICallException:
            return False
        return True

    def outputs(self) -> list:
        return list(self._get([self.vr[o] for o in REALS])) + [float(self.fmu.getBoolean([self.vr["contact"]])[0])]

    def simulate(self, V, h, each=None, t0=0.0) -> np.ndarray:
        """Outputs at t0 and after each step of size h under the held inputs V; ``each(run, k)`` after step k."""
        rows = [self.outputs()]
        for k, v in enumerate(V):
            self.step(v, t0 + k * h, h)
            rows.append(self.outputs())
            if each is not None:
                each(self, k)
        return np.array(rows)

    def step(self, V: float, t: float, h: float) -> None:
        """Set the input V [V] and do one step from t [s] of size h [s] (fmpy raises on an error status)."""
        self._set([self.vr["V"]], [float(V)])
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def close(self):
        if self._open:
            self._open = False
            self.fmu.freeInstance()


def max_rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference of a and b over every output, relative to the output's largest magnitude in b."""
    scale = np.max(np.abs(b), axis=0)
    err = np.max(np.abs(a - b), axis=0)
    return float(np.max(np.where(err == 0.0, 0.0, err / np.where(scale > 0.0, scale, 1.0))))


def assert_same_outputs(a: np.ndarray, b: np.ndarray, what, rtol: float = RTOL_OUT, tiny: float = TINY_OUT):
    """Every output within rtol of its largest magnitude, or within ``tiny`` (subnormal: see TINY_OUT)."""
    assert a.shape == b.shape, what
    for j, name in enumerate(REALS + ("contact",)):
        scale = float(np.max(np.abs(b[:, j])))
        err = float(np.max(np.abs(a[:, j] - b[:, j])))
        assert err <= rtol * scale + tiny or err == 0.0, (what, name, err, scale)


def row_ok(a: np.ndarray, b: np.ndarray, rtol: float) -> np.ndarray:
    """Per row: every output within rtol of its largest magnitude over the run, or within TINY_OUT."""
    scale = np.max(np.abs(b), axis=0)
    return np.all(np.abs(a - b) <= rtol * scale + TINY_OUT, axis=1)


GRAZING_RTOL_FACTOR = 100.0
EVENT_ROWS = 5


def assert_same_outputs_or_grazing_event(a: np.ndarray, b: np.ndarray, rtol: float, what):
    """assert_same_outputs, except after an impact or release whose time rounding decides: there the outputs may
    part, from the row of that event on, to GRAZING_RTOL_FACTOR times the integrator's tolerance rtol.

    Why: an event is located on the step's dense output. When the diaphragm reaches the coil face with almost no
    velocity (it comes to rest there: the held force's equilibrium is at the face) the dense output stays within
    rounding of the face over much of the step, and where the root lies (even whether it is inside the step) is
    decided by the last bits of the state: from arrays 1e-12 apart fmu_src finds it at 64 % of the step and the C
    code at its end (test_grazing_impact_is_decided_by_rounding). From there the two integrations take different
    step sequences, each within its tolerance: their outputs agree to the integration error, not to rounding.
    Everything before that event is still compared to RTOL_OUT, and the relaxed comparison applies only if the
    first row that differs is the row where contact changes (on either side) or one of the next EVENT_ROWS rows
    (the step sequences part at the event; the outputs drift apart over the following steps)."""
    ok = row_ok(a, b, RTOL_OUT)
    if ok.all():
        return
    f = int(np.argmin(ok))
    events = np.flatnonzero((a[1:, -1] != a[:-1, -1]) | (b[1:, -1] != b[:-1, -1])) + 1
    near = [e for e in events if 0 <= f - e <= EVENT_ROWS]
    assert near, (what, "first difference at row", f, "not at or just after an impact/release row", events.tolist())
    assert row_ok(a[near[-1]:], b[near[-1]:], GRAZING_RTOL_FACTOR * rtol).all(), (what, "after the event", near)


def python_accepts(p: dict, blocked: bool) -> bool:
    """True if the Python model accepts the parameters (``specs.validate`` and ``model.check_integrable``, as the
    pythonfmu FMU's fmi2ExitInitializationMode does; rtol is the FMU's and not checked here)."""
    values = {k: v for k, v in p.items() if k != "rtol"}
    try:
        validate(values)
        check_integrable(Params(**values, blocked=blocked))
    except ValueError:
        return False
    return True


def all_terms_on(r0: float, factor: float = 0.3, tau: float = 0.02, presliding_m: float | None = None) -> dict:
    """Every term of the generic term set (``fmu_src.terms.TERMS``) on: c = factor times the term's natural scale at
    the gap r0 [m] (``TermSpec.scale``, defaults otherwise), alternating in sign where the sign is free; every lag's
    time constant tau [s] (a lag with its own rate: ``presliding_m`` [m], default ``PRESLIDING_M``)."""
    from fmu_src.terms import LAGS, TERMS
    p = Params(r0=r0)
    out = {}
    for k, t in enumerate(TERMS.values()):
        sign = 1.0 if t.nonnegative or k % 2 == 0 else -1.0
        out[t.coef.name] = sign * factor * t.scale(p)
    out.update({g.tau.name: tau if g.first_order else (presliding_m or PRESLIDING_M) for g in LAGS.values()})
    return out


PRESLIDING_M = 5e-5     # [m] the constant of a lag that has its own rate (Dahl's presliding length: 1 um..1 mm)


def draw_terms(draw, p: dict, min_size: int = 1) -> list:
    """Hypothesis: switch on min_size.. terms of the term set in the parameters p (in place): coefficients from -2 to
    2 times their natural scale at p (``TermSpec.scale``; >= 0 where the physics fixes the sign), each used lag's
    time constant from 1 ms to 0.5 s (a presliding length from 1 um to 1 mm). Returns the names of the terms on."""
    from hypothesis import strategies as st

    from fmu_src.terms import LAGS, TERMS
    base = Params(**{k: v for k, v in p.items() if k != "rtol"})
    names = draw(st.lists(st.sampled_from(sorted(TERMS)), min_size=min_size, max_size=len(TERMS), unique=True))
    for n in names:
        t = TERMS[n]
        u = draw(st.floats(-2.0, 2.0).filter(lambda x: abs(x) > 1e-3))
        p[t.coef.name] = (abs(u) if t.nonnegative else u) * t.scale(base)
        if t.lag:        # a time constant [s], or a lag's own constant (Dahl: a presliding length [m], 1 um..1 mm)
            g = LAGS[t.lag]
            p[g.tau.name] = draw(st.floats(1e-3, 0.5) if g.first_order else st.floats(1e-6, 1e-3))
    return names
