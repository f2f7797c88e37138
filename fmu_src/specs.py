"""Specs of the model: parameters (names, SI units, descriptions, defaults, rules), effects, ``Params``.

The bottom layer of ``fmu_src`` (pure Python: imports only math and dataclasses). Everything else
derives from the specs here: the ``Params`` fields, validation, the FMU's parameters and units
(``fmu_src.mpc_actuator``, ``build_fmu.py``), the parameter JSON keys (``harness.data.paramsjson``), and
the layout of the compiled integrator's parameter block (``BLOCK``: where each parameter, effect switch
and effect state index sits), so that adding an effect means adding its ``EffectSpec`` to ``EFFECTS``
here and its equations to ``fmu_src.effects`` (see the README, "Adding an effect").

The paper's defaults describe a plausible 20 wt%, 45 mm, 1.5 mm thick MPC diaphragm in front of a
50 mm holding electromagnet (coil radius 15 mm, 0.29 T/A at the coil face), at a gap of 9 mm.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, make_dataclass, replace

from .paramspec import ParamSpec
from .terms import LAG_STATES, LAGS, TERM_SPECS, TERMS, active_terms, check_terms

MU0 = 4e-7 * math.pi  # vacuum permeability [H/m]


# Order matters: it is the order of the FMU's parameters.
SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("a", "m", 0.015, "Radius of the single current loop that stands for the electromagnet"),
    ParamSpec("r0", "m", 0.009, "Gap between coil face and undeflected diaphragm", positive=False, nonnegative=True),
    ParamSpec("D", "m", 0.045, "Diaphragm diameter"),
    ParamSpec("kB", "T/A", 0.29, "Field per ampere at the coil face, kB = mu0*N/(2a) (what a tesla meter calibrates)"),
    ParamSpec("R", "Ohm", 15.0, "Coil resistance"),
    ParamSpec("L", "H", 0.12, "Coil inductance"),
    ParamSpec("Em", "N.m/T2", 0.0423, "Magneto-mechanical coupling factor: F = Em*I^2*G(r)"),
    ParamSpec("K1", "N/m3", 2.0e5, "Duffing spring coefficient: spring force (K1*x^2 + K2)*x", positive=False, nonnegative=True),
    ParamSpec("K2", "N/m", 40.0, "Linear spring coefficient: spring force (K1*x^2 + K2)*x"),
    ParamSpec("C", "N.s/m", 0.5, "Equivalent damping coefficient", positive=False, nonnegative=True),
    ParamSpec("m", "kg", 0.004, "Equivalent moving mass of the diaphragm"),
)
SPEC_BY_NAME = {s.name: s for s in SPECS}


def _effect_param(name, unit, description) -> ParamSpec:
    """An effect parameter: default 0 (= off), must be >= 0."""
    return ParamSpec(name, unit, 0.0, description, positive=False, nonnegative=True)


@dataclass(frozen=True)
class StateSpec:
    """A state an effect adds to y = [I, x, v]: name, unit, description, the absolute-tolerance scale
    of the integrator [unit] (None: the displacement's), and its steady state for ``fmu_src.statics``:
    ``steady`` "displacement" (it settles at x), "force" (at the magnetic force) or "rate_zero" (its own
    rate vanishes; solved from the right-hand side, which must be affine in the state, and must give a
    value >= 0 there); ``mechanical`` False for a state whose steady value changes only the electrical side
    (the voltage that drives a current), not the force balance.

    Parameters
    ----------
    name : str
        The state's name (an FMU output when it is a sensor reading).
    unit : str
        SI unit string.
    description : str
        What the state is.
    atol_scale : float or None
        Absolute-tolerance scale of the integrator [unit] (None: the displacement's).
    steady : str
        How its steady state follows: "displacement", "force" or "rate_zero" (``STEADY_RULES``).
    mechanical : bool
        Its steady value enters the force balance (False: only the electrical side).
    """
    name: str
    unit: str
    description: str
    atol_scale: float | None = None
    steady: str = "rate_zero"
    mechanical: bool = True

    def __post_init__(self):
        if self.steady not in STEADY_RULES:
            raise ValueError(f"StateSpec {self.name!r}: steady must be one of {STEADY_RULES}, got {self.steady!r}")


#: how an effect state's steady state follows (StateSpec.steady)
STEADY_RULES = ("displacement", "force", "rate_zero")


@dataclass(frozen=True)
class EffectSpec:
    """A candidate effect the paper's model leaves out (equations in ``fmu_src.effects``).

    ``param_specs``: its parameters, the first one the switch (> 0: on; all 0 by default);
    ``state_specs``: the states it adds (appended to y in catalogue order when on); ``positive_when_on``:
    parameters that must be > 0 while it is on (its rule checks); ``summary``/``signals``: what it is
    and where it shows in the rig's tests; ``rig_magnitude_1``: the parameter values of the virtual rig's
    magnitude 1.0 for a sample's true parameters (``harness.data.rig``), ``rig_fixed`` the ones that stay
    fixed (time constants) while the others scale with the magnitude, ``rig_note`` what magnitude 1.0 does.

    Parameters
    ----------
    name : str
        The effect's name in the catalogue ``EFFECTS`` (e.g. "filler_saturation").
    param_specs : tuple of ParamSpec
        Its parameters, the first one the switch.
    state_specs : tuple of StateSpec
        The states it adds.
    summary : str
        What it is.
    signals : str
        Where it shows in the rig's tests.
    rig_magnitude_1 : callable
        Params -> {parameter name: value} at the virtual rig's magnitude 1.0.
    rig_fixed : tuple of str
        Parameters that stay fixed while the others scale with the magnitude.
    rig_note : str
        What magnitude 1.0 does, in numbers.
    positive_when_on : tuple of str
        Parameters that must be > 0 while the effect is on.

    Examples
    --------
    >>> e = EFFECTS["coil_heating"]
    >>> e.switch, e.params, [s.name for s in e.state_specs]
    ('Rth', ('Rth', 'tau_th'), ['dT'])
    """
    name: str
    param_specs: tuple[ParamSpec, ...]
    state_specs: tuple[StateSpec, ...]
    summary: str
    signals: str
    rig_magnitude_1: object = field(repr=False, compare=False)   # callable: Params -> {name: value}
    rig_fixed: tuple[str, ...] = ()
    rig_note: str = ""
    positive_when_on: tuple[str, ...] = ()

    @property
    def switch(self) -> str:
        """The parameter that turns the effect on (> 0)."""
        return self.param_specs[0].name

    @property
    def params(self) -> tuple[str, ...]:
        """Names of its parameters."""
        return tuple(s.name for s in self.param_specs)

    @property
    def states(self) -> tuple[str, ...]:
        """Names of the states it adds."""
        return tuple(s.name for s in self.state_specs)


# Catalogue order matters: it is the order of the FMU's effect parameters, of the Params fields after
# "blocked", and of the effect states in y. The magnitude-1 notes are numbers computed with the model at
# 0.23 T (cold steady current 0.793 A) for W20-D45 at its T5 gap of 5 mm [W10-D30 at 3 mm, W30-D60 at
# 9 mm in brackets]; "T5 window" = the 2.8 s after the step.
EFFECTS: dict[str, EffectSpec] = {e.name: e for e in (
    EffectSpec(
        "coil_heating",
        (_effect_param("Rth", "K/W", "coil_heating: thermal resistance of the winding to ambient; dT' = (Rth*I^2*R*"
                                     "(1 + 0.0039*dT) - dT)/tau_th, coil resistance R*(1 + 0.0039*dT) (0 = off)"),
         _effect_param("tau_th", "s", "coil_heating: thermal time constant of the winding (must be > 0 when Rth > 0)")),
        (StateSpec("dT", "K", "winding temperature rise above ambient", atol_scale=1.0, mechanical=False),),
        "coil resistance rises with the winding temperature, R(T) = R*(1 + 0.0039*dT)",
        "current droops during the steady part of the step tests T2-T5 and T8 (largest at T5/T8, "
        "0.23 T); displacement/force droop with it",
        rig_magnitude_1=lambda p: {"Rth": 8.0, "tau_th": 4.0}, rig_fixed=("tau_th",),
        rig_note="Rth = 8 K/W * magnitude, tau_th = 4 s. Steady state (after ~15 s): dT = 61 K, current -19 %. "
                 "Over the T5 window the current falls 11.5 % (0.789 A 0.1 s after the step -> 0.698 A at the "
                 "end; mean of the last second 6.2 % below the mean over 0.3-1.3 s after the step) and the "
                 "final displacement is 28 % below the plain model's [24 %, 30 %]. Same current droop in "
                 "T8 (blocked force -23 % at the end); T1/T7 points (1.5 s holds from cold) read low.",
        positive_when_on=("tau_th",)),
    EffectSpec(
        "filler_saturation",
        (_effect_param("ksat", "1/T2", "filler_saturation: 1/B_sat^2; force Em*I^2*G(r0 - x)/(1 + ksat*(kB*I)^2) "
                                       "(0 = off)"),),
        (),
        "magnetization of the filler saturates: F = Em*I^2*G/(1 + (kB*I/B_sat)^2)",
        "steady displacement of T2..T5 grows more slowly than I^2; blocked force T7/T8 lower at 0.23 T "
        "relative to a model fitted at low field",
        rig_magnitude_1=lambda p: {"ksat": 3.0},
        rig_note="ksat = 1/B_sat^2 = 3 1/T^2 * magnitude (B_sat = 0.577 T). Force factor "
                 "1/(1 + ksat*(kB*I)^2) at the steady current: 0.989 (T2, 0.06 T), 0.965 (T3), 0.929 (T4), "
                 "0.863 (T5-T8, 0.23 T). T5 final displacement -17 % [-15 %, -19 %]."),
    EffectSpec(
        "viscoelastic_creep",
        (_effect_param("Kc", "N/m", "viscoelastic_creep: spring of the Maxwell branch (spring in series with a "
                                    "dashpot) beside the diaphragm spring; branch force Kc*(x - xc), xc' = "
                                    "(x - xc)/tau_c (0 = off)"),
         _effect_param("tau_c", "s", "viscoelastic_creep: relaxation time of the Maxwell branch (must be > 0 when "
                                     "Kc > 0)")),
        (StateSpec("xc", "m", "dashpot position of the Maxwell branch", steady="displacement"),),
        "viscoelastic matrix: standard linear solid (Maxwell branch Kc, tau_c beside the spring)",
        "T2-T5 displacement keeps rising after the step while the current is steady; T1 sweep values "
        "depend on the hold time",
        rig_magnitude_1=lambda p: {"Kc": 0.2 * p.K2, "tau_c": 1.0}, rig_fixed=("tau_c",),
        rig_note="Kc = 0.2*K2 * magnitude, tau_c = 1 s. In T5 the displacement keeps rising at steady "
                 "current: last-second mean 8.8 % above the 0.5-1.5 s mean [7.4 %, 10.3 %], still 2 % "
                 "below the relaxed value at the end; T1 points (1.5 s holds) up to 8 % low (-0.17 mm at "
                 "the 4 mm gap) [-6 %; W30-D60 is no longer pulled in at 7 mm].",
        positive_when_on=("tau_c",)),
    EffectSpec(
        "edge_stiffening",
        (_effect_param("K5", "N/m5", "edge_stiffening: quintic spring coefficient, spring force += K5*x^5 "
                                     "(0 = off)"),),
        (),
        "in-plane tension at large deflection: spring force += K5*x^5",
        "T1 displacement at small gaps (large deflection) below the model; T5 steady value lower",
        rig_magnitude_1=lambda p: {"K5": p.K1 / (p.D / 15.0) ** 2},
        rig_note="K5 = K1/(D/15)^2 * magnitude: the quintic term equals the Duffing term at a centre deflection "
                 "of D/15 (2, 3, 4 mm for D = 30, 45, 60 mm). Shows at large deflection, T1 near the gap of "
                 "maximum displacement: -0.16 mm (-7 %) at the 4 mm gap, T1 maximum 3.00 -> 2.86 mm "
                 "[-1 %; W30-D60: maximum 7.0 -> 5.0 mm, pull-in only from 6 mm]; T5 final value -2 % "
                 "[-0.1 %, -1.3 %]."),
    EffectSpec(
        "motional_emf",
        (_effect_param("lam", "1", "motional_emf: inductance L(x) = L*(1 + lam*(a^2/(a^2 + (r0 - x)^2))^(3/2)); "
                                   "L(x)*I' = V - R*I - I*v*dL/dx (0 = off)"),),
        (),
        "the diaphragm changes the coil's inductance: back-EMF I*v*dL/dx and a gap-dependent L",
        "current dip while the diaphragm moves after the step (T2-T6); slower current rise at small gaps",
        rig_magnitude_1=lambda p: {"lam": 0.3},
        rig_note="lam = 0.3 * magnitude: L(x) = L*(1 + 0.3*(a^2/(a^2 + r^2))^1.5), i.e. inductance +26 % at "
                 "the T5 gap [+28 %, +19 %] and +29 % at the T8 gap (2 mm): slower current rise (T5 current up "
                 "to 67 mA below the plain model's); with L refitted at the T5 gap the back-EMF of the motion "
                 "still leaves +-3.6 mA in the current while the diaphragm moves [0.9, 4.2 mA]."),
    EffectSpec(
        "sensor_lag",
        (_effect_param("tau_s", "s", "sensor_lag: first-order time constant of the displacement and force "
                                     "sensors (outputs x_sensor, F_sensor) (0 = off)"),),
        (StateSpec("x_sensor", "m", "displacement as the laser sensor reads it", steady="displacement"),
         StateSpec("F_sensor", "N", "force as the force transducer reads it", atol_scale=1e-3, steady="force")),
        "first-order lag of the laser displacement sensor and the force transducer",
        "delay of the measured displacement/force in the step rise (T2-T5, T8) and phase lag in T6; "
        "the current is not affected",
        rig_magnitude_1=lambda p: {"tau_s": 0.005},
        rig_note="tau_s = 5 ms * magnitude: first-order lag of the laser and force-transducer readings (not "
                 "the current). T5 reading up to 0.24 mm behind the true displacement during the rise "
                 "[0.09, 0.21 mm]; T6 (1 Hz) phase lag atan(2*pi*1 Hz*5 ms) = 0.031 rad."),
)}

EFFECT_SPECS: tuple[ParamSpec, ...] = tuple(s for e in EFFECTS.values() for s in e.param_specs)
EFFECT_SPEC_BY_NAME = {s.name: s for s in EFFECT_SPECS}
ALL_SPECS = SPECS + EFFECT_SPECS + TERM_SPECS
EFFECT_FIELDS: tuple[str, ...] = tuple(s.name for s in EFFECT_SPECS)   # the Params fields after "blocked"
TERM_FIELDS: tuple[str, ...] = tuple(s.name for s in TERM_SPECS)       # the generic term set's (fmu_src.terms)
BASE_STATES = ("I", "x", "v")   # coil current [A], displacement toward the coil [m], velocity [m/s]


# ----------------------------------------------------------------------------------------- Params
class _ParamsMethods:
    """Methods of ``Params`` (its fields come from the specs)."""

    def validated(self):
        """Return self after checking every value; raise ``ValueError`` naming the bad parameter."""
        validate(asdict(self))
        return self

    def with_(self, **kw):
        """A copy with the given fields replaced."""
        return replace(self, **kw)

    def as_dict(self) -> dict:
        """{field name: value}."""
        return asdict(self)


Params = make_dataclass(
    "Params",
    [(s.name, float, s.default) for s in SPECS] + [("blocked", bool, False)]
    + [(s.name, float, s.default) for s in EFFECT_SPECS + TERM_SPECS],
    bases=(_ParamsMethods,), frozen=True)
Params.__module__ = __name__
Params.__init__.__module__ = __name__      # (make_dataclass leaves "types": griffe could not resolve it)
Params.__doc__ = ("Parameters of the model (SI units), frozen: the paper's (``SPECS``), blocked (the "
                  "force-transducer mode), then every effect's (``EFFECT_SPECS``, 0 = off), then the generic "
                  "term set's (``fmu_src.terms``: coefficients c_<term>, 0 = off, and lag time constants "
                  "tau_<lag>).\n\n"
                  "Parameters\n----------\n"     # generated from the specs: the FMU's descriptions and units
                  + "".join(f"{s.name} : float\n    {s.description} [{s.unit}], default {s.default!r}.\n"
                            for s in SPECS)
                  + "blocked : bool\n    The force-transducer mode: the diaphragm held at the gap r0, default False.\n"
                  + "".join(f"{s.name} : float\n    {s.description} [{s.unit}], default {s.default!r}.\n"
                            for s in EFFECT_SPECS + TERM_SPECS)
                  + "\nExamples\n--------\n"
                  ">>> p = Params()\n"
                  ">>> p.a, p.r0, p.D                    # coil radius, gap, diaphragm diameter [m]\n"
                  "(0.015, 0.009, 0.045)\n"
                  ">>> p.with_(ksat=3.0).ksat            # filler saturation at B_sat = 1/sqrt(3) T = 0.58 T\n"
                  "3.0\n"
                  ">>> Params(R=-1.0).validated()\n"
                  "Traceback (most recent call last):\n"
                  "...\n"
                  "ValueError: parameter R [Ohm] must be > 0, got -1.0\n")


def validate(values: dict) -> None:
    """Check parameter values {name: value}; raise ``ValueError`` with the parameter's name and the rule it breaks.

    Covers the paper's parameters (``SPECS``), the effect parameters (``EFFECT_SPECS``) and each effect's
    rule (``EffectSpec.positive_when_on``), the term set's parameters (``TERM_SPECS``) and its rule (a lag's
    time constant > 0 while a term using it is on, ``fmu_src.terms.check_terms``). Names not in ``values`` are not checked.

    Parameters
    ----------
    values : dict
        {parameter name: value} in SI units (any subset of the parameters).

    Raises
    ------
    ValueError
        A value is not a finite number, breaks its sign rule, or an effect is on without its time constant.

    Examples
    --------
    >>> validate({"R": 15.0, "L": 0.12})
    >>> validate({"R": -1.0})
    Traceback (most recent call last):
    ...
    ValueError: parameter R [Ohm] must be > 0, got -1.0
    >>> validate({"Rth": 50.0})          # coil heating on without its thermal time constant
    Traceback (most recent call last):
    ...
    ValueError: parameter tau_th [s] must be > 0 when Rth > 0 (coil_heating on), got 0.0
    """
    for spec in ALL_SPECS:
        if spec.name not in values:
            continue
        v = values[spec.name]
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"parameter {spec.name} must be a number, got {v!r}") from None
        if not math.isfinite(fv):
            raise ValueError(f"parameter {spec.name} must be finite, got {fv!r}")
        if spec.positive and not fv > 0.0:
            raise ValueError(f"parameter {spec.name} [{spec.unit}] must be > 0, got {fv!r}")
        if spec.nonnegative and not fv >= 0.0:
            raise ValueError(f"parameter {spec.name} [{spec.unit}] must be >= 0, got {fv!r}")
    for effect in EFFECTS.values():
        on = effect.switch in values and float(values[effect.switch]) > 0.0
        for name in effect.positive_when_on if on else ():
            if not float(values.get(name, 0.0)) > 0.0:
                raise ValueError(f"parameter {name} [{EFFECT_SPEC_BY_NAME[name].unit}] must be > 0 when "
                                 f"{effect.switch} > 0 ({effect.name} on), got {values.get(name, 0.0)!r}")
    check_terms(values)


def param_names() -> list[str]:
    """Names of the paper's parameters, in FMU order."""
    return [s.name for s in SPECS]


def active_effects(p) -> tuple:
    """Names of the effects switched on in the Params p (in catalogue order).

    Parameters
    ----------
    p : Params
        The parameters; an effect is on when its switch parameter (its strength) is not 0.

    Returns
    -------
    tuple of str
        Effect names, e.g. ``("filler_saturation",)``.

    Examples
    --------
    >>> active_effects(Params())
    ()
    >>> active_effects(Params(ksat=3.0, K5=1e12))
    ('filler_saturation', 'edge_stiffening')
    """
    return tuple(name for name, e in EFFECTS.items() if getattr(p, e.switch) != 0.0)


# ------------------------------------------------------------------------------------------ units
# SI base-unit exponents of the unit symbols that the specs' unit strings are made of
_SYMBOLS = {"1": {}, "kg": {"kg": 1}, "m": {"m": 1}, "s": {"s": 1}, "A": {"A": 1}, "K": {"K": 1},
            "N": {"kg": 1, "m": 1, "s": -2}, "W": {"kg": 1, "m": 2, "s": -3},
            "V": {"kg": 1, "m": 2, "s": -3, "A": -1}, "T": {"kg": 1, "s": -2, "A": -1},
            "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2}, "H": {"kg": 1, "m": 2, "s": -2, "A": -2}}
_BASE_ORDER = ("kg", "m", "s", "A", "K")


def si_exponents(unit: str) -> dict:
    """SI base-unit exponents {kg, m, s, A, K: nonzero int} of a unit string as the specs write it: symbols
    (1, kg, m, s, A, K, N, W, V, T, Ohm, H) with an optional positive integer power, joined by "." with one "/" at
    most, e.g. "N.m/T2", "1/T2", "N/m5". ``ValueError`` naming the unit for anything else."""
    num, slash, den = unit.partition("/")
    exps = dict.fromkeys(_BASE_ORDER, 0)
    for sign, part in ((1, num), (-1, den)) if slash else ((1, num),):
        for term in part.split("."):
            sym = "1" if term == "1" else term.rstrip("0123456789")
            if sym not in _SYMBOLS:
                raise ValueError(f"unit {unit!r}: unknown symbol {term!r} (known: {', '.join(_SYMBOLS)})")
            power = int(term[len(sym):] or 1)
            for base, e in _SYMBOLS[sym].items():
                exps[base] += sign * power * e
    return {b: e for b, e in exps.items() if e}


# ------------------------------------------------------------------------ compiled parameter block
@dataclass(frozen=True)
class BlockLayout:
    """Layout of the head of the compiled integrator's parameter block (``fmu_src.integrator``), derived
    from the specs: every parameter value, then one switch per effect (1.0 on, 0.0 off), then for every
    effect state its index in the state vector y (-1.0 while its effect is off), then the term set's switch
    (1.0 while any term is on), one switch per lag (1.0 while a term with a nonzero coefficient uses it) and
    the index in y of every lag state (-1.0 while every term is off). The integrator appends its own entries
    (force-kernel table, tolerances) after ``size``."""
    param: dict      # parameter name -> index (paper's in SPECS order, then EFFECT_SPECS, then TERM_SPECS)
    switch: dict     # effect name -> index of its switch
    state: dict      # effect state name -> index of the entry holding its position in y
    size: int
    n_states_max: int   # length of y with every effect and the term set on
    terms: int = -1     # index of the term set's switch
    lag_on: dict = field(default_factory=dict)      # lag name -> index of its switch
    lag_state: dict = field(default_factory=dict)   # lag state name -> index of the entry holding its position


def _block_layout() -> BlockLayout:
    names = [s.name for s in ALL_SPECS]
    effects = list(EFFECTS)
    states = [s for e in EFFECTS.values() for s in e.states]
    n = len(names) + len(effects)
    t = n + len(states)
    return BlockLayout(param={k: i for i, k in enumerate(names)},
                       switch={k: len(names) + i for i, k in enumerate(effects)},
                       state={k: n + i for i, k in enumerate(states)},
                       size=t + 1 + 2 * len(LAGS),
                       n_states_max=len(BASE_STATES) + len(states) + len(LAG_STATES),
                       terms=t, lag_on={g: t + 1 + i for i, g in enumerate(LAGS)},
                       lag_state={z: t + 1 + len(LAGS) + i for i, z in enumerate(LAG_STATES)})


BLOCK = _block_layout()

assert [f.name for f in fields(Params)] == [s.name for s in SPECS] + ["blocked"] + list(EFFECT_FIELDS + TERM_FIELDS)
assert len(set(EFFECT_FIELDS) | set(TERM_FIELDS) | set(SPEC_BY_NAME)) == len(ALL_SPECS), "parameter names must be unique"
assert all(s.default == 0.0 for s in EFFECT_SPECS)
assert all(n in EFFECTS[e].params for e in EFFECTS for n in EFFECTS[e].positive_when_on)
assert all(si_exponents(s.unit) is not None for s in ALL_SPECS)   # every unit string is understood
