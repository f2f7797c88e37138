"""The discovery's term library (harness.analysis.discovery.library): what the fit sees of a term table.

A planted table (two terms sharing a lag, one sign-fixed term) checks the derivation itself: one fitted ratio
per term with the sign rule of its coefficient, one time constant per lag, coefficients = ratio x the term's
natural scale evaluated on the sample's parameters (computed here independently). The real table
(``fmu_src.terms.TERMS``) is checked for what the verdict must state: units, kind, reading, a scale.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from fmu_src.specs import ParamSpec, Params
from harness.analysis.discovery.library import TermLibrary, ratio_key, tau_key


@dataclass(frozen=True)
class Spec:              # the fields of fmu_src.terms.TermSpec the library reads
    name: str
    equation: str
    kind: str
    coef: ParamSpec
    lag: str | None
    basis: str
    reading: str
    scale: object


class P:                 # a Params stand-in with the planted coefficient fields
    def __init__(self, **kw):
        self.__dict__.update(kw)

    def with_(self, **kw):
        return P(**{**self.__dict__, **kw})


PLANTED = {
    "drag": Spec("drag", "force", "mechanical", ParamSpec("c_drag", "N.s2/m2", 0.0, "drag", positive=False),
                 None, "-v|v| [m2/s2]", "fluid load", lambda p: p.C / 0.01),
    "lagA": Spec("lagA", "force", "mechanical", ParamSpec("c_lagA", "1", 0.0, "a", positive=False), "F", "z_F - F [N]",
                 "eddy", lambda p: 1.0),
    "lagB": Spec("lagB", "F_reading", "reading", ParamSpec("c_lagB", "1", 0.0, "b", positive=False, nonnegative=True),
                 "F", "z_F [N]", "creep", lambda p: 2.0),
}


def test_planted_table():
    lib = TermLibrary(PLANTED, {"F": (1e-3, 1.0, 0.02)})
    assert lib.names == ("drag", "lagA", "lagB")
    (r,) = lib.params("drag")
    assert (r.key, r.log, r.lo, r.hi, r.init) == (ratio_key("drag"), False, -100.0, 100.0, 0.0)   # signed
    rb, tb = lib.params("lagB")
    assert rb.lo == 0.0                                                    # sign fixed by the physics
    assert tb.key == tau_key("F") == lib.params("lagA")[1].key            # one time constant per lag
    assert tb.log and math.isclose(math.exp(tb.lo), 1e-3) and math.isclose(tb.natural(tb.init), 0.02)
    p = P(C=0.3, c_drag=0.0, c_lagA=0.0, c_lagB=0.0, tau_F=0.0)
    q = lib.apply(p, {ratio_key("drag"): -0.5, ratio_key("lagB"): -3.0, tau_key("F"): math.log(0.05), "Rth": 9.0})
    assert q.c_drag == pytest.approx(-0.5 * 0.3 / 0.01) and q.c_lagB == 0.0 and q.tau_F == pytest.approx(0.05)
    assert q.c_lagA == 0.0 and lib.apply(p, {"Rth": 1.0}) is p            # keys of others: untouched
    # a lag not yet fitted: a fast and a slow start; once fitted (by another term), the reference's value
    from harness.analysis.discovery.library import TAU_STARTS_S
    assert lib.starts("drag", {}) == [{}]
    assert TAU_STARTS_S == (0.01, 2.0)                                    # the slow start lies above this range:
    assert [math.exp(s[tau_key("F")]) for s in lib.starts("lagA", {})] == pytest.approx([0.01, 1.0])   # at its top
    assert lib.starts("lagB", {tau_key("F"): 0.0}) == [{}]


def test_the_real_table_states_units_kind_and_reading():
    from fmu_src.specs import si_exponents
    from fmu_src.terms import TERMS
    from harness.analysis.diagnosis import CANDIDATES
    from harness.analysis.discovery import default_library
    lib = default_library()
    assert lib.names == tuple(TERMS) and not set(lib.names) & set(CANDIDATES)
    assert {TERMS[n].kind for n in TERMS} >= {"mechanical", "coil", "reading"}
    p = Params()
    for n, s in TERMS.items():
        assert s.kind in ("mechanical", "coil", "reading") and s.equation in ("force", "coil", "x_reading", "F_reading")
        assert s.reading.strip() and "[" in s.basis and si_exponents(s.coef.unit) is not None, n
        assert getattr(p, s.coef.name) == 0.0                             # off by default
        sc = s.scale(p)
        assert math.isfinite(sc) and sc > 0, (n, sc)
        if s.shares:          # fitted as its share of the slow value (test_eddy_share_is_the_shorted_secondary)
            q = p.with_(**{f"tau_{s.lag}": 0.01})
            sc = lib.natural_scale(q, n)
            fit = {ratio_key(n): 0.5, tau_key(s.lag): math.log(0.01)}
            assert lib.apply(p, fit).__getattribute__(s.coef.name) == pytest.approx(0.5 * sc)
            continue
        assert lib.apply(p, {ratio_key(n): 1.0}).__getattribute__(s.coef.name) == pytest.approx(sc)


# ----------------------------------------------------------------- a term that shares the coil's inductance
def _secondary_current(L, R, k2, tau, V, t):
    """Current [A] of a coil with a shorted secondary, [L M; M Le] d[I, Ie]/dt = [V - R I, -Re Ie], Le = L,
    M^2 = k2 L Le, Re = Le/tau, from rest under the step V at t = 0: the two-circuit matrix exponential (written here,
    not the term's reduction)."""
    from scipy.linalg import expm
    M = math.sqrt(k2) * L
    Minv = np.linalg.inv(np.array([[L, M], [M, L]]))
    A = Minv @ np.array([[-R, 0.0], [0.0, -L / tau]])
    xs = -np.linalg.solve(A, Minv @ np.array([V, 0.0]))
    return np.array([(xs - expm(A * s) @ xs)[0] for s in t])


@pytest.mark.parametrize("k2,tau", [(0.8, 0.02), (0.3, 0.005)])
def test_eddy_share_is_the_shorted_secondary(k2, tau):
    """The discovery fits eddy_current as the share k^2 of the slow inductance (the base parameter L the paper
    model identifies): by hand, a shorted secondary of coupling k^2 is L (1 - k^2) I' = V - R I + (k^2 L/tau)
    (z - I), z' = (I - z)/tau. The library's Params at share k^2 must be exactly that (fast L (1 - k^2),
    c = k^2 L/tau, the slow L + c tau unchanged), and the project's model with them must carry the current of
    the two-circuit matrix exponential."""
    from fmu_src.model import simulate
    from harness.analysis.discovery import default_library
    L, R, V = 0.12, 15.0, 11.9
    lib = default_library()
    (share, tk) = lib.params("eddy_current")
    assert (share.lo, share.hi) == (0.0, pytest.approx(0.95)) and tk.key == tau_key("I")
    p = Params(R=R, L=L, r0=0.004, blocked=True)
    q = lib.apply(p, {ratio_key("eddy_current"): k2, tau_key("I"): math.log(tau)})
    assert q.L == pytest.approx(L * (1.0 - k2), rel=1e-12)
    assert q.c_eddy_current == pytest.approx(k2 * L / tau, rel=1e-12) and q.tau_I == pytest.approx(tau, rel=1e-12)
    assert lib.natural_scale(q, "eddy_current") == pytest.approx(L / tau, rel=1e-12)     # d c / d share
    assert lib.apply(p, {ratio_key("eddy_current"): 0.0, tau_key("I"): math.log(tau)}).L == L   # share 0: the paper coil
    t = np.linspace(0.0, 0.15, 601)
    got = simulate(q, t, V, rtol=1e-10)["I"]
    want = _secondary_current(L, R, k2, tau, V, t)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-7 * V / R)
