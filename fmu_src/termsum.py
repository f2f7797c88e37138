"""The generic term set (``fmu_src.terms.TERMS``) on the parameter block: per equation the sum of its terms,
and the rates of the lag states, generated from the table (one line per term, none written by hand).

=========================  =====================================================================
``term_sum_force``         sum c_k*phi_k [N] of the force equation's terms
``term_sum_coil``          sum c_k*psi_k [V] of the coil equation's terms
``term_sum_x_reading``     sum c_k*chi_k [m] of the displacement reading's terms
``term_sum_F_reading``     sum c_k*chi_k [N] of the force reading's terms
``lag_rates``              z' = on*(u - z)/(tau + 1 - on) of every lag state into out (on: the lag's switch,
                           1.0 while a term with a nonzero coefficient uses it; 0.0: z' = 0), or
                           on*rate(x, v, I, F, Rc, z, tau + 1 - on) for a lag with its own rate
                           (``LagSpec.rate``, e.g. Dahl's presliding state)
=========================  =====================================================================

Each takes the parameter block P (``fmu_src.specs.BLOCK``: coefficients ``c_<term>``, time constants
``tau_<lag>``, lag switches ``BLOCK.lag_on``, lag-state positions ``BLOCK.lag_state``), the state y and the
arguments of the basis functions (x [m], v [m/s], I [A], F [N]); valid only while the term set's switch
``P[BLOCK.terms]`` is 1.0 (then every lag state is in y). Terms with coefficient 0 add 0*phi. Plain arithmetic
on floats and numpy arrays, compiled by numba (``register_jitable``) and traced by SymPy like
``fmu_src.effects``.
"""
from __future__ import annotations

from numba.extending import register_jitable

from .specs import BLOCK
from .terms import EQUATIONS, LAGS, TERMS

for _t in TERMS.values():
    register_jitable(_t.function)
for _g in LAGS.values():
    register_jitable(_g.input)
    if _g.rate is not None:
        register_jitable(_g.rate)


def _z(lag) -> str:
    return "0.0" if lag is None else f"y[int(P[{BLOCK.lag_state[LAGS[lag].state]}])]"


def _source_sum(equation: str) -> str:
    lines = [f"def term_sum_{equation}(P, y, x, v, I, F):",
             f'    """sum c_k*basis_k of the {equation} terms (``fmu_src.terms.TERMS``)."""',
             "    s = 0.0"]
    for name, t in TERMS.items():
        if t.equation == equation:
            lines.append(f"    s = s + P[{BLOCK.param[t.coef.name]}] * {name}(x, v, I, F, {_z(t.lag)})")
    lines.append("    return s")
    return "\n".join(lines) + "\n"


def _source_lags() -> str:
    lines = ["def lag_rates(P, y, x, v, I, F, Rc, out):",
             '    """z\' of every lag state (``fmu_src.terms.LAGS``) into out; Rc [Ohm] the coil resistance."""']
    for name, g in LAGS.items():
        on, tau, i = BLOCK.lag_on[name], BLOCK.param[g.tau.name], BLOCK.lag_state[g.state]
        lines.append(f"    i = int(P[{i}])")
        if g.first_order:
            lines.append(f"    out[i] = P[{on}] * ({g.input.__name__}(x, v, I, F, Rc) - y[i]) / (P[{tau}] + (1.0 - P[{on}]))")
        else:   # its own rate (x, v, I, F, Rc, z, tau); the constant 1 where the lag is off (no division by 0)
            lines.append(f"    out[i] = P[{on}] * {g.rate.__name__}(x, v, I, F, Rc, y[i], P[{tau}] + (1.0 - P[{on}]))")
    return "\n".join(lines) + "\n"


SOURCE = "".join(_source_sum(e) for e in EQUATIONS) + _source_lags()   # the generated code (for reading)
_namespace = {t.function.__name__: t.function for t in TERMS.values()}
_namespace.update({g.input.__name__: g.input for g in LAGS.values()})
_namespace.update({g.rate.__name__: g.rate for g in LAGS.values() if g.rate is not None})
exec(compile(SOURCE, "<fmu_src.termsum generated>", "exec"), _namespace)   # noqa: S102 (code from the table)

term_sum_force = register_jitable(_namespace["term_sum_force"])
term_sum_coil = register_jitable(_namespace["term_sum_coil"])
term_sum_x_reading = register_jitable(_namespace["term_sum_x_reading"])
term_sum_F_reading = register_jitable(_namespace["term_sum_F_reading"])
lag_rates = register_jitable(_namespace["lag_rates"])
for _f in (term_sum_force, term_sum_coil, term_sum_x_reading, term_sum_F_reading, lag_rates):
    _f.__module__ = __name__
