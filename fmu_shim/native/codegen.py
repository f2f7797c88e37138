"""C code of the model's equations, generated from the Python model by symbolic tracing (SymPy).

Nothing here restates an equation: every formula is obtained by calling the very function objects of
``fmu_src`` (``effects.rates``, ``effects.force``, ``effects.contact_force``, ``effects.sensor_readings``,
``effects.stability_step``, ``field.field_per_amp``, ``field.dfield_dr_per_amp``, ``field.theta_max``,
``field.axial_field``, ``model.Dynamics.scales``) with SymPy symbols in place of floats, and printing the
expressions they return as C (``sympy.ccode``, common subexpressions eliminated). Where a function calls numpy
(``np.sin``, ``np.maximum``, ...) or a Python builtin (``max``), it is re-bound for the trace to a namespace
of the SymPy equivalents (:func:`traced`): the function's code object is the same.

The effects switched on select branches (Python ``if`` on the switch values of the parameter block), so the
whole model is traced once per combination of effects and of the generic term set's switch
(``2**(len(EFFECTS) + 1)`` masks: bit k = the k-th effect of ``fmu_src.specs.EFFECTS`` on, bit ``len(EFFECTS)``
(``TERMS_BIT``) = any term of ``fmu_src.terms.TERMS`` on); identical function bodies are emitted once. With the
term set on, the trace runs through ``fmu_src.termsum`` (the term sums and lag rates generated from the TERMS/LAGS
tables), so every term, basis function and lag input (or rate) of the tables is in the C code: the coefficients
``c_<term>``, time constants ``tau_<lag>`` and lag switches (``BLOCK.lag_on``, set at initialisation from the
table ``TERM_LAG``) are read from the parameter block at run time, a coefficient 0 adds 0*basis as in Python.
Constants of the integrator (DP5 tableau, dense-output matrix, block and array layout, step limits) are read from
``fmu_src.integrator`` and ``fmu_src.model`` and written as ``#define``s / arrays, never retyped.

``generate_header()`` returns the whole header ``mpc_native_gen.h`` that ``mpc_native.c`` includes.
"""
from __future__ import annotations

import inspect
import math
import re
import types
from dataclasses import dataclass

import numpy as np
import sympy as sp

from fmu_src import effects as fx
from fmu_src import field, model
from fmu_src import integrator as J
from fmu_src import mpc_actuator as slave
from fmu_src.specs import ALL_SPECS, BASE_STATES, BLOCK, EFFECTS, Params
from fmu_src.terms import LAGS, TERM_COEF_SPECS, TERMS

EFFECT_NAMES = tuple(EFFECTS)
TERMS_BIT = 1 << len(EFFECT_NAMES)   # mask bit of the generic term set (fmu_src.terms)
N_MASKS = TERMS_BIT << 1


def c_double(v: float) -> str:
    """A C double literal that reads back as exactly ``v`` (shortest round-trip repr)."""
    v = float(v)
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
    s = repr(v)
    return s if ("." in s or "e" in s or "n" in s) else s + ".0"


# ------------------------------------------------------------------------------------- tracing
_SYMPY_NUMPY = types.SimpleNamespace(
    asarray=lambda x, dtype=None: x, sin=sp.sin, cos=sp.cos, arctan2=sp.atan2, sqrt=sp.sqrt,
    maximum=lambda a, b: sp.Max(a, b), minimum=lambda a, b: sp.Min(a, b),
    # for basis functions, lag inputs and rates of the term set that call numpy (fmu_src.terms)
    abs=sp.Abs, tanh=sp.tanh, exp=sp.exp, log=sp.log, sign=sp.sign, arctan=sp.atan, fabs=sp.Abs)


def traced(func, **overrides):
    """``func`` with the same code object, its globals' ``np`` (and the names in ``overrides``) bound to SymPy."""
    glb = dict(func.__globals__)
    if "np" in glb:
        glb["np"] = _SYMPY_NUMPY
    glb.update(overrides)
    return types.FunctionType(func.__code__, glb, func.__name__, func.__defaults__, func.__closure__)


def param_symbol(name: str) -> sp.Symbol:
    return sp.Symbol(f"p_{name}", real=True)


def state_symbols(n: int) -> list:
    return [sp.Symbol(f"y_{i}", real=True) for i in range(n)]


def mask_effects(mask: int) -> tuple:
    """Names of the effects on in ``mask`` (catalogue order)."""
    return tuple(e for k, e in enumerate(EFFECT_NAMES) if mask >> k & 1)


def mask_on(mask: int) -> tuple:
    """``mask_effects`` plus "terms" if the term set's bit is set (``fmu_src.model.switched_on``'s form)."""
    return mask_effects(mask) + (("terms",) if mask & TERMS_BIT else ())


def n_states(mask: int) -> int:
    return len(model.state_names(mask_on(mask)))


def lag_on_symbol(lag: str) -> sp.Symbol:
    """The lag's switch (``BLOCK.lag_on``): a run-time value of the parameter block (1.0 while a term with a nonzero
    coefficient uses the lag)."""
    return sp.Symbol(f"lagon_{lag}", real=True)


def symbolic_block(mask: int) -> list:
    """The head of the parameter block (``fmu_src.specs.BLOCK``) with a symbol per parameter, and the
    switches and state indices of the effects in ``mask`` as numbers (``model.block_head``'s layout)."""
    on = mask_on(mask)
    index = {n: i for i, n in enumerate(model.state_names(on))}
    head = [None] * BLOCK.size
    for name, i in BLOCK.param.items():
        head[i] = param_symbol(name)
    for name, i in BLOCK.switch.items():
        head[i] = 1.0 if name in on else 0.0
    for name, i in BLOCK.state.items():
        head[i] = float(index.get(name, -1))
    # the generic term set (fmu_src.terms): its switch fixed by the mask, the lag switches run-time values (which
    # lags the nonzero coefficients use: setup_model in mpc_native.c, from TERM_LAG), the lag states' positions
    head[BLOCK.terms] = 1.0 if "terms" in on else 0.0
    for name, i in BLOCK.lag_on.items():
        head[i] = lag_on_symbol(name) if "terms" in on else 0.0
    for name, i in BLOCK.lag_state.items():
        head[i] = float(index.get(name, -1))
    return head


# ------------------------------------------------------------------------------------- C printing
@dataclass
class CFunction:
    name: str
    code: str


def _inputs(exprs, known: dict) -> list[str]:
    """Declarations of the symbols the expressions use, from ``known`` {symbol name: C expression}."""
    used = set()
    for e in exprs:
        if isinstance(e, sp.Basic):
            used |= {s.name for s in e.free_symbols}
    missing = used - set(known)
    if missing:
        raise ValueError(f"codegen: unknown symbols {sorted(missing)}")
    return [f"    const double {n} = {known[n]};" for n in sorted(used) if known[n] != n]


def _param_inputs() -> dict:
    return {**{f"p_{name}": f"P[{i}]" for name, i in BLOCK.param.items()},
            **{lag_on_symbol(name).name: f"P[{i}]" for name, i in BLOCK.lag_on.items()}}


def c_body(exprs: list, targets: list[str], known: dict) -> str:
    """C statements assigning ``exprs`` to ``targets`` (lvalues), common subexpressions as locals."""
    exprs = [sp.sympify(e) for e in exprs]
    repl, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t_"), optimizations="basic")
    lines = _inputs(exprs, known)
    for sym, e in repl:
        lines.append(f"    const double {sym} = {sp.ccode(e, standard='c99')};")
    for tgt, e in zip(targets, reduced):
        lines.append(f"    {tgt} = {sp.ccode(e, standard='c99')};")
    return "\n".join(lines)


class Emitter:
    """Collects generated functions; identical bodies (same signature and code) are emitted once."""

    def __init__(self):
        self.functions: list[CFunction] = []
        self._by_code: dict[str, str] = {}

    def add(self, prefix: str, signature: str, body: str) -> str:
        key = signature + "\n" + body
        if key in self._by_code:
            return self._by_code[key]
        name = f"{prefix}_{len(self.functions)}"
        args = re.findall(r"(\w+)\s*(?=[,)])", signature.split("(", 1)[1])
        unused = "".join(f"    (void){a};\n" for a in args)   # not every combination uses every argument
        self.functions.append(CFunction(name, f"static {signature.format(name=name)}\n{{\n{unused}{body}\n}}\n"))
        self._by_code[key] = name
        return name


# ------------------------------------------------------------------------------------- the model
X, V_, VEL, F_, I_, G_, R_, TH, FFACE = sp.symbols("x V v F I G r theta F_face", real=True)
_LOCALS = {"x": "x", "V": "V", "v": "v", "F": "F", "I": "I", "G": "G", "r": "r", "theta": "theta",
           "F_face": "F_face"}


def _known(n: int) -> dict:
    return {**_param_inputs(), **{f"y_{i}": f"y[{i}]" for i in range(n)}, **_LOCALS}


def trace_mask(em: Emitter, mask: int) -> dict:
    """The generated C functions of the model with the effects of ``mask`` on: {role: function name}."""
    n = n_states(mask)
    P = symbolic_block(mask)
    y = state_symbols(n)
    known = _known(n)
    out = {}
    for free in (False, True):
        res = [sp.Integer(0)] * n
        fx.rates(P, y, V_, X, VEL, F_, free, res)
        out[f"rates{int(free)}"] = em.add(
            "rates", "void {name}(const double *P, const double *y, double V, double x, double v, double F, "
                     "double *out)", c_body(res, [f"out[{i}]" for i in range(n)], known))
    out["force"] = em.add("force", "double {name}(const double *P, double I, double G)",
                          "    double F;\n" + c_body([fx.force(P, I_, G_)], ["F"], known) + "\n    return F;")
    out["contact"] = em.add("contact", "double {name}(const double *P, const double *y, double F_face)",
                            "    double f;\n" + c_body([fx.contact_force(P, y, FFACE)], ["f"], known)
                            + "\n    return f;")
    xs, Fs = fx.sensor_readings(P, y, X, F_)
    out["sensor"] = em.add("sensor", "void {name}(const double *P, const double *y, double x, double F, "
                                     "double *xs, double *Fs)", c_body([xs, Fs], ["*xs", "*Fs"], known))
    out["drives"] = 1 if fx.force_drives_states(P) else 0
    for blocked in (False, True):
        h = traced(fx.stability_step)(P, blocked)
        out[f"stab{int(blocked)}"] = em.add("stability_step", "double {name}(const double *P)",
                                            "    double h;\n" + c_body([h], ["h"], known) + "\n    return h;")
    fake = types.SimpleNamespace(p=types.SimpleNamespace(**{n_: param_symbol(n_) for n_ in BLOCK.param}),
                                 on=mask_effects(mask), terms=bool(mask & TERMS_BIT))
    sc = traced(model.Dynamics.scales, max=lambda a, b: sp.Max(a, b))(fake)
    assert len(sc) == n
    out["scales"] = em.add("scales", "void {name}(const double *P, double *sc)",
                           c_body(sc, [f"sc[{i}]" for i in range(n)], known))
    out["n"] = n
    return out


def field_functions(em: Emitter) -> dict:
    """Eq. 2's field per ampere and its r-derivative, the quadrature's upper limit, the axial field."""
    a, kB, D = param_symbol("a"), param_symbol("kB"), param_symbol("D")
    known = {"p_a": "a", "p_kB": "kB", "p_D": "D", **_LOCALS}
    names = {}
    for role, f in (("field_per_amp", field.field_per_amp), ("dfield_dr_per_amp", field.dfield_dr_per_amp)):
        names[role] = em.add(role, "double {name}(double r, double theta, double a, double kB)",
                             "    double b;\n" + c_body([traced(f)(R_, TH, a, kB)], ["b"], known) + "\n    return b;")
    names["theta_max"] = em.add("theta_max", "double {name}(double r, double D)",
                                "    double t;\n" + c_body([traced(field.theta_max)(R_, D)], ["t"], known)
                                + "\n    return t;")
    names["axial_field"] = em.add("axial_field", "double {name}(double I, double r, double a, double kB)",
                                  "    double B;\n" + c_body([field.axial_field(I_, R_, a, kB)], ["B"], known)
                                  + "\n    return B;")
    return names


# ------------------------------------------------------------------------------------- constants
def integrator_constants() -> dict:
    """Every layout index, mode, status and tableau coefficient of ``fmu_src.integrator`` (UPPER-case ints and
    floats of the module), plus the model's step cap and the reset's first step size."""
    consts = {k: v for k, v in vars(J).items() if k.isupper() and isinstance(v, (int, float))
              and not isinstance(v, bool)}
    for status in ("OK", "UNDERFLOW", "TOO_MANY_STEPS"):   # ST_*: UNDERFLOW is also a macro of macOS's math.h
        consts[f"ST_{status}"] = consts.pop(status)
    consts["MAX_STEPS_PER_ADVANCE"] = model.MAX_STEPS_PER_ADVANCE
    consts["MIN_TIME_SCALE_S"] = model.MIN_TIME_SCALE_S
    consts["MAX_TIME_SCALE_S"] = model.MAX_TIME_SCALE_S
    consts["MAX_FACE_TRACTION"] = model.MAX_FACE_TRACTION
    consts["R0_MAX_PER_A"] = model.R0_MAX_PER_A
    # the first step size the reset sets (read off a reset integrator, not retyped)
    integ = model.Integrator(model.Dynamics(Params()))
    consts["H_FIRST"] = float(integ.S[J.S_H])
    consts["RTOL_DEFAULT"] = slave.RTOL_DEFAULT
    consts["RTOL_MIN"], consts["RTOL_MAX"] = slave.RTOL_MIN, slave.RTOL_MAX
    consts["TIME_REL_TOL"] = slave.TIME_REL_TOL
    consts["B_FACE_START"] = slave.B_FACE_START
    consts["N_KERNEL_POINTS"] = field.ForceKernel.__init__.__defaults__[0]
    consts["N_EFFECTS"] = len(EFFECT_NAMES)
    consts["N_MASKS"] = N_MASKS
    consts["N_PARAMS"] = len(ALL_SPECS)
    consts["N_BASE_STATES"] = len(BASE_STATES)
    return consts


def kernel_span() -> str:
    """C expression of the table span r_max of ``field.make_kernel`` in terms of ``r0`` (traced: the kernel class
    replaced by one that returns its r_max)."""
    r0 = sp.Symbol("r0", real=True)
    span = traced(field.make_kernel, ForceKernel=lambda a, D, kB, r_max: r_max)(0.0, 0.0, 0.0, r0)
    return sp.ccode(span, standard="c99")


def output_slots() -> dict:
    """{output name: index in the integrator's outputs array} (``model._output_dict`` applied to 0, 1, ..., 7;
    "contact", a bool there, is the one index left)."""
    d = model._output_dict(np.arange(8.0))
    slots = {k: int(v) for k, v in d.items() if k != "contact"}
    slots["contact"] = next(i for i in range(8) if i not in slots.values())
    return slots


def _array(ctype: str, name: str, values) -> str:
    vals = ", ".join(c_double(v) if ctype == "double" else str(int(v)) for v in values)
    return f"static const {ctype} {name}[{len(values)}] = {{{vals}}};\n"


def generate_header() -> str:
    """The generated header: constants, parameter metadata, the traced equations and the mask table."""
    em = Emitter()
    fields = field_functions(em)
    masks = [trace_mask(em, m) for m in range(N_MASKS)]
    parts = ["/* Generated by fmu_shim/native/codegen.py from fmu_src (python build_fmu.py --native): do not edit. */",
             "#ifndef MPC_NATIVE_GEN_H", "#define MPC_NATIVE_GEN_H", "#include <math.h>", ""]
    for k, v in sorted(integrator_constants().items()):
        parts.append(f"#define {k} {v if isinstance(v, int) else c_double(v)}")
    parts += [f"#define KERNEL_R_MAX(r0) ({kernel_span()})", f"#define MU0 {c_double(model.MU0)}",
              f"#define MAX_STEP_DEFAULT {c_double(inspect.signature(model.Integrator).parameters['max_step'].default)}",
              ""]
    assert output_slots()["contact"] == 5   # mpc_native.c reads contact from out[5] (integrator.outputs)
    parts.append(_array("double", "DENSE_P", J.DENSE_P.ravel().tolist()))
    nodes, weights = field._GL_NODES, field._GL_WEIGHTS
    parts.append(f"#define N_GL {len(nodes)}")
    parts.append(_array("double", "GL_NODES", nodes.tolist()))
    parts.append(_array("double", "GL_WEIGHTS", weights.tolist()))
    # parameters in block order: names, units, sign rules; effects: switch parameter, rules
    names = [s.name for s in ALL_SPECS]
    assert [BLOCK.param[n] for n in names] == list(range(len(names)))
    parts.append("static const char *const PARAM_NAMES[N_PARAMS] = {" + ", ".join(f'"{n}"' for n in names) + "};")
    parts.append("static const char *const PARAM_UNITS[N_PARAMS] = {" + ", ".join(f'"{s.unit}"' for s in ALL_SPECS)
                 + "};")
    parts.append(_array("int", "PARAM_POSITIVE", [s.positive for s in ALL_SPECS]))
    parts.append(_array("int", "PARAM_NONNEGATIVE", [s.nonnegative for s in ALL_SPECS]))
    parts.append(_array("int", "PARAM_IS_TIME", [s.unit == "s" for s in ALL_SPECS]))
    # the generic term set: per term its coefficient and the lag it uses (-1: none), per lag its switch's slot and
    # its time constant (setup_model sets the switches as model.block_head does; check_parameters: terms.check_terms
    # and the lags' time scales of model.check_integrable)
    terms, lags = list(TERMS.values()), list(LAGS)
    assert len(TERM_COEF_SPECS) == len(terms)
    parts.append(f"#define N_TERMS {len(terms)}")
    parts.append(f"#define N_LAGS {len(lags)}")
    parts.append(f"#define TERMS_BIT {TERMS_BIT}")
    parts.append(f"#define TERMS_SLOT {BLOCK.terms}")
    parts.append(_array("int", "TERM_COEF", [BLOCK.param[t.coef.name] for t in terms]))
    parts.append(_array("int", "TERM_LAG", [lags.index(t.lag) if t.lag else -1 for t in terms]))
    parts.append("static const char *const TERM_NAMES[N_TERMS] = {" + ", ".join(f'"{t.name}"' for t in terms) + "};")
    parts.append(_array("int", "LAG_ON_SLOT", [BLOCK.lag_on[g] for g in lags]))
    parts.append(_array("int", "LAG_TAU", [BLOCK.param[LAGS[g].tau.name] for g in lags]))
    eff = list(EFFECTS.values())
    parts.append("static const char *const EFFECT_NAMES[N_EFFECTS] = {" + ", ".join(f'"{e.name}"' for e in eff) + "};")
    parts.append(_array("int", "EFFECT_SWITCH", [BLOCK.param[e.switch] for e in eff]))
    parts.append(_array("int", "EFFECT_SWITCH_SLOT", [BLOCK.switch[e.name] for e in eff]))
    # effect -> parameters (for its time scales) and positive_when_on rules, as (effect, param) pairs
    owner = [(k, BLOCK.param[p]) for k, e in enumerate(eff) for p in e.params]
    parts.append(_array("int", "OWNER_EFFECT", [o[0] for o in owner]))
    parts.append(_array("int", "OWNER_PARAM", [o[1] for o in owner]))
    parts.append(f"#define N_OWNED {len(owner)}")
    rules = [(k, BLOCK.param[p]) for k, e in enumerate(eff) for p in e.positive_when_on]
    parts.append(f"#define N_RULES {len(rules)}")
    parts.append(_array("int", "RULE_EFFECT", [r[0] for r in rules] or [0]))
    parts.append(_array("int", "RULE_PARAM", [r[1] for r in rules] or [0]))
    parts.append(_array("int", "STATE_SLOT", list(BLOCK.state.values())))
    parts.append(f"#define N_EFFECT_STATES {len(BLOCK.state)}")
    parts.append(f"#define N_LAG_STATES {len(BLOCK.lag_state)}")
    parts.append(_array("int", "LAG_STATE_SLOT", list(BLOCK.lag_state.values())))
    parts.append(_array("int", "STATE_EFFECT", [next(k for k, e in enumerate(eff) if s in e.states)
                                                  for s in BLOCK.state]))
    for name in ("a", "r0", "D", "kB", "R", "L", "Em", "K1", "K2", "C", "m"):
        parts.append(f"#define PI_{name} {BLOCK.param[name]}")
    parts.append("")
    parts += [f.code for f in em.functions]
    parts.append("typedef struct {\n    void (*rates[2])(const double *, const double *, double, double, double, "
                 "double, double *);\n    double (*force)(const double *, double, double);\n"
                 "    double (*contact)(const double *, const double *, double);\n"
                 "    void (*sensor)(const double *, const double *, double, double, double *, double *);\n"
                 "    int drives;\n    double (*stab[2])(const double *);\n    void (*scales)(const double *, double *);\n"
                 "    int n;\n} Physics;\n")
    rows = [f"    {{{{{m['rates0']}, {m['rates1']}}}, {m['force']}, {m['contact']}, {m['sensor']}, {m['drives']}, "
            f"{{{m['stab0']}, {m['stab1']}}}, {m['scales']}, {m['n']}}}" for m in masks]
    parts.append("static const Physics PHYSICS[N_MASKS] = {\n" + ",\n".join(rows) + "\n};\n")
    for role, name in fields.items():
        parts.append(f"#define {role.upper()} {name}")
    parts += ["", "#endif", ""]
    return "\n".join(parts)


if __name__ == "__main__":   # print the header (for reading)
    print(generate_header())
