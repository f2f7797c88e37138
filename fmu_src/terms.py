"""The generic term set: candidate terms the physics of the device allows beyond the paper's model and the
catalogue of effects, each a signed coefficient ``c_<name>`` times a basis function, in one equation.

``TERMS`` is the one table a term is added to (with its basis function below): the Params fields, the FMU
parameters with units and descriptions, validation, the compiled integrator, the vectorized simulator, the
statics and the docs' table all follow from it. Every coefficient is 0 (= off) by default; with every term
off the model is bit for bit the model without them (the integrator skips them behind one switch).

Where a term enters (``TermSpec.equation``; x toward the coil [m], v = x' [m/s], I coil current [A], F the
magnetic force [N], z the term's lag state, ``LAGS``):

* "force": the diaphragm's force balance, m x'' = F - C v - spring(x) + sum c_k phi_k [N];
  also in the net contact force (at x = r0, v = 0);
* "coil": the coil's voltage balance, L I' = V - R I + sum c_k psi_k [V];
* "x_reading", "F_reading": the readings, x_sensor = x_b + sum c_k chi_k, F_sensor = F_b + sum c_k chi_k, x_b
  and F_b the readings without terms (x and F, or the lagged ones with sensor_lag on); a reading's basis is a
  function of x_b and F_b.

Lag states (history terms, ``LAGS``): z' = (u - z)/tau_<lag>, u the lag's input (the coil's dissipated power
I^2 R(T), the magnetic force, the current, ...), or a lag's own rate (``LagSpec.rate``: Dahl's presliding
friction state, z' = (v - |v| z)/x_c, its constant a length). While any term is on every lag state is in the state vector
(after the effect states) so that the integrator and the native code have one code path; a lag that no term
with a nonzero coefficient uses is frozen at 0 (its rate is 0) and needs no time constant.

The basis functions are plain arithmetic (floats, numpy arrays, SymPy for the native code generator; numba
compiles them: ``fmu_src.effects`` registers them with ``register_jitable``), all with the signature
(x, v, I, F, z). This module is pure Python (imports only dataclasses and ``fmu_src.paramspec``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .paramspec import ParamSpec

V_FRICTION = 1e-3   # velocity [m/s] below which dry friction fades (smooth sign v/sqrt(v^2 + V_F^2))
B_OPERATING = 0.2   # field [T] at the coil face of the operating point of the scales (``TermSpec.scale``)
T_OPERATING = 0.1   # time [s] in which the operating point's motion crosses the gap (``TermSpec.scale``)


# -------------------------------------------------------------------------------------- basis functions
# signature (x [m], v [m/s], I [A], F [N], z [the lag's unit]); plain arithmetic only (numba, numpy, SymPy)
def quad_drag(x, v, I, F, z):
    """-v*|v| [m2/s2]."""
    return -v * abs(v)


def dry_friction(x, v, I, F, z):
    """-v/sqrt(v^2 + V_F^2) [1], a smooth -sign(v) (V_F = ``V_FRICTION``)."""
    return -v / (v * v + V_FRICTION * V_FRICTION) ** 0.5


def even_spring(x, v, I, F, z):
    """-x^2 [m2]."""
    return -x * x


def cubic_damping(x, v, I, F, z):
    """-x^2*v [m3/s]."""
    return -x * x * v


def remanence(x, v, I, F, z):
    """I [A]."""
    return I


def heat_softening(x, v, I, F, z):
    """x*z_P [m.W]."""
    return x * z


def force_lag(x, v, I, F, z):
    """z_F - F [N]."""
    return z - F


def eddy_current(x, v, I, F, z):
    """z_I - I [A]."""
    return z - I


def current_cubic(x, v, I, F, z):
    """-I^3 [A3]."""
    return -I * I * I


def x_quadratic(x, v, I, F, z):
    """x^2 [m2] (x the reading without terms)."""
    return x * x


def x_cubic(x, v, I, F, z):
    """x^3 [m3] (x the reading without terms)."""
    return x * x * x


def F_quadratic(x, v, I, F, z):
    """F^2 [N2] (F the reading without terms)."""
    return F * F


def F_creep(x, v, I, F, z):
    """z_Fs - F [N] (F the reading without terms)."""
    return z - F


def dahl_friction(x, v, I, F, z):
    """-z_dahl [1] (z_dahl the Dahl friction state, between -1 and 1)."""
    return -z


# ------------------------------------------------------------------------------------ lag inputs u
# signature (x [m], v [m/s], I [A], F [N], Rc [Ohm]: the coil's resistance, hot with coil_heating)
def power_input(x, v, I, F, Rc):
    """I^2*R(T) [W]: the coil's dissipated power."""
    return I * I * Rc


def force_input(x, v, I, F, Rc):
    """F [N]: the magnetic force."""
    return F


def current_input(x, v, I, F, Rc):
    """I [A]: the coil current."""
    return I


def slip_sign(x, v, I, F, Rc):
    """v/sqrt(v^2 + V_F^2) [1]: the value the Dahl state tends to while the diaphragm slides (a smooth sign)."""
    return v / (v * v + V_FRICTION * V_FRICTION) ** 0.5


# ------------------------------------------------------------------------------ lag rates z' (own form)
# signature (x [m], v [m/s], I [A], F [N], Rc [Ohm], z [the lag's unit], tau [the lag's constant's unit]);
# plain arithmetic; a lag without one has z' = (u - z)/tau
def dahl_rate(x, v, I, F, Rc, z, tau):
    """Dahl's presliding state: z' = (v - |v|*z)/x_c [1/s] = (|v|/x_c)*(sign(v) - z), x_c = tau [m] the
    presliding length: z follows the displacement (z = dx/x_c) at the start of a motion, saturates at
    sign(v) while sliding and stays where it is when the motion stops (rate-independent hysteresis)."""
    return (v - abs(v) * z) / tau


# ------------------------------------------------------------------------------------------ the tables
@dataclass(frozen=True)
class LagSpec:
    """A lag state z of the term set: z' = (u - z)/tau, u = ``input``(x, v, I, F, R(T)), or its own rate
    ``rate``(x, v, I, F, R(T), z, tau) (a history state that is not a first-order lag in time, e.g. Dahl's
    presliding friction state, whose constant is a length).

    Parameters
    ----------
    name : str
        The lag's name; its state is ``z_<name>``, its time constant ``tau_<name>``.
    unit : str
        SI unit of u and z.
    input : callable
        u(x, v, I, F, Rc), plain arithmetic.
    description : str
        What u is.
    atol_scale : float
        Absolute-tolerance scale of the FMU's integrator for z [unit].
    mechanical : bool
        Its steady value may enter the force balance (False: only the coil's, ``fmu_src.statics``).
    electrical_input : bool
        Its input depends on the electrical states (the winding temperature): ``fmu_src.statics`` then
        needs them for the force balance too.
    rate : callable or None
        None: z' = (u - z)/tau (a first-order lag in time, tau [s]). Else z'(x, v, I, F, Rc, z, tau), plain
        arithmetic like the basis functions; u is then the value z tends to (for step-size bounds) and the
        rate must vanish at rest (v = 0) or at z = u, so that ``fmu_src.statics``' rule "rate zero" holds.
    constant_unit : str
        SI unit of its constant tau_<name> ("s" for a lag in time).
    constant_text : str
        What its constant is (for the parameter's description); "" : the time constant.
    rate_text : str
        Its rate as a formula (docs, parameter descriptions); "" : z' = (u - z)/tau.
    """
    name: str
    unit: str
    input: object = field(repr=False, compare=False)
    description: str = ""
    atol_scale: float = 1e-3
    mechanical: bool = True
    electrical_input: bool = False
    rate: object = field(default=None, repr=False, compare=False)
    constant_unit: str = "s"
    constant_text: str = ""
    rate_text: str = ""

    @property
    def first_order(self) -> bool:
        """True for a first-order lag in time, z' = (u - z)/tau (no own ``rate``)."""
        return self.rate is None

    @property
    def rate_formula(self) -> str:
        """Its rate as a formula."""
        return self.rate_text or f"z' = (u - z)/tau, u = {self.description}"

    @property
    def state(self) -> str:
        """Name of the lag state."""
        return f"z_{self.name}"

    @property
    def tau(self) -> ParamSpec:
        """Its constant tau_<name> (a time constant [s] for a first-order lag; 0 by default; > 0 while a term
        using it is on)."""
        what = self.constant_text or "time constant"
        return ParamSpec(f"tau_{self.name}", self.constant_unit, 0.0, f"term set: {what} of the lag state "
                         f"z_{self.name} ({self.rate_formula}); must be > 0 while a term using it is on",
                         positive=False, nonnegative=True)


LAGS: dict[str, LagSpec] = {g.name: g for g in (
    LagSpec("P", "W", power_input, "I^2*R(T) [W], the coil's dissipated power", atol_scale=1e-3,
            electrical_input=True),
    LagSpec("F", "N", force_input, "F [N], the magnetic force", atol_scale=1e-3),
    LagSpec("I", "A", current_input, "I [A], the coil current", atol_scale=1e-3, mechanical=False),
    LagSpec("Fs", "N", force_input, "F [N], the magnetic force as the slow part of the force transducer "
                                    "follows it", atol_scale=1e-3),
    LagSpec("dahl", "1", slip_sign, "sign(v) [1] while sliding (Dahl's presliding friction state)", atol_scale=1e-4,
            rate=dahl_rate, constant_unit="m", constant_text="presliding length x_c",
            rate_text="z' = (v - |v|*z)/x_c, x_c = tau_dahl [m]: Dahl's presliding friction state"),
)}

EQUATIONS = ("force", "coil", "x_reading", "F_reading")
KINDS = {"force": "mechanical", "coil": "coil", "x_reading": "reading", "F_reading": "reading"}
EQUATION_TEXT = {"force": "m*x'' = F - C*v - spring(x) + c*phi [N]", "coil": "L*I' = V - R*I + c*psi [V]",
                 "x_reading": "x_sensor = x + c*chi [m]", "F_reading": "F_sensor = F + c*chi [N]"}


@dataclass(frozen=True)
class TermSpec:
    """One candidate term: c_<name> * basis, in one equation (``EQUATIONS``).

    Parameters
    ----------
    name : str
        The term's name (its coefficient is ``c_<name>``).
    equation : str
        Where it enters: "force", "coil", "x_reading" or "F_reading".
    unit : str
        SI unit of the coefficient (``fmu_src.specs.si_exponents`` reads it).
    function : callable
        The basis function (x, v, I, F, z), plain arithmetic.
    basis : str
        The basis function with its unit, e.g. "-v*|v| [m2/s2]".
    reading : str
        Its physical reading: which mechanisms produce a term of that shape.
    scale : callable
        Params -> the coefficient's natural scale [unit]: where the term is comparable to the paper model's own
        terms at the operating point (gap r0, speed r0/``T_OPERATING``, field ``B_OPERATING``); a discovery
        fits c/scale.
    lag : str or None
        The lag state it uses (``LAGS``), or None.
    nonnegative : bool
        The physics fixes the sign: c >= 0 (a dissipative term: it must not feed energy into the motion).
    shares : str or None
        A lag term c*(z - u), z' = (u - z)/tau, whose equation has a parameter ``shares`` (a Params field) times
        u' (the coil's L times I'): for changes of u much slower than tau, z = u - tau*u' and the term adds c*tau
        to that parameter, so the data's slow value of it is ``shares`` + c*tau and the model's own ``shares``
        is the fast value (a shorted secondary of coupling k^2: L(1 - k^2) fast, L slow, c = k^2 L/tau). A
        discovery fits the share s = c*tau/(``shares`` + c*tau) in [0, 1) and keeps the slow value the paper
        model identified as the fitted parameter (``harness.analysis.discovery.library``). None: no such
        parameter.

    Examples
    --------
    >>> t = TERMS["quad_drag"]
    >>> t.coef.name, t.coef.unit, t.kind, t.lag
    ('c_quad_drag', 'N.s2/m2', 'mechanical', None)
    """
    name: str
    equation: str
    unit: str
    function: object = field(repr=False, compare=False)
    basis: str = ""
    reading: str = ""
    scale: object = field(default=None, repr=False, compare=False)
    lag: str | None = None
    nonnegative: bool = False
    shares: str | None = None

    def __post_init__(self):
        if self.equation not in EQUATIONS:
            raise ValueError(f"TermSpec {self.name!r}: equation must be one of {EQUATIONS}, got {self.equation!r}")
        if self.lag is not None and self.lag not in LAGS:
            raise ValueError(f"TermSpec {self.name!r}: lag must be one of {tuple(LAGS)}, got {self.lag!r}")
        if self.shares is not None and self.lag is None:
            raise ValueError(f"TermSpec {self.name!r}: shares={self.shares!r} needs a lag (c*tau is the share)")

    @property
    def kind(self) -> str:
        """"mechanical", "coil" or "reading"."""
        return KINDS[self.equation]

    @property
    def coef(self) -> ParamSpec:
        """Its coefficient c_<name> (signed, 0 = off)."""
        sign = ", >= 0" if self.nonnegative else ""
        return ParamSpec(f"c_{self.name}", self.unit, 0.0, f"term {self.name} ({self.kind}): coefficient of "
                         f"{self.basis} in {EQUATION_TEXT[self.equation]} (0 = off{sign})", positive=False,
                         nonnegative=self.nonnegative)


def _gap(p):
    """Length scale [m]: the gap r0 (at least 1 mm)."""
    return max(p.r0, 1e-3)


def _current(p):
    """Current scale [A]: the current of ``B_OPERATING`` at the coil face."""
    return B_OPERATING / p.kB


def _speed(p):
    return _gap(p) / T_OPERATING


TERMS: dict[str, TermSpec] = {t.name: t for t in (
    TermSpec("quad_drag", "force", "N.s2/m2", quad_drag, "-v*|v| [m2/s2]",
             "fluid load: orifice/turbulent drag of the pumped fluid or of the air in front of the diaphragm",
             lambda p: p.C / _speed(p), nonnegative=True),
    TermSpec("dry_friction", "force", "N", dry_friction, "-v/sqrt(v^2 + (1 mm/s)^2) [1]",
             "Coulomb (dry) friction in the clamping or on a guide: a force opposing the motion, of fixed size",
             lambda p: p.C * _speed(p), nonnegative=True),
    TermSpec("even_spring", "force", "N/m2", even_spring, "-x^2 [m2]",
             "asymmetric stiffness: pre-stress or an initial dome of the diaphragm, an asymmetric clamp",
             lambda p: p.K2 / _gap(p)),
    TermSpec("cubic_damping", "force", "N.s/m3", cubic_damping, "-x^2*v [m3/s]",
             "amplitude-dependent damping: squeeze film between diaphragm and coil face, material damping that "
             "grows with the strain", lambda p: p.C / _gap(p) ** 2, nonnegative=True),
    TermSpec("remanence", "force", "N/A", remanence, "I [A]",
             "a force linear in the current: remanent magnetization of the filler or of the core, a permanent "
             "magnet's field (the force changes sign with the current)", lambda p: p.K2 * _gap(p) / _current(p)),
    TermSpec("heat_softening", "force", "N/m.W", heat_softening, "x*z_P [m.W]",
             "the diaphragm's stiffness falls as the silicone warms with the coil's heat (z_P the lagged power)",
             lambda p: p.K2 / (p.R * _current(p) ** 2), lag="P"),
    TermSpec("force_lag", "force", "1", force_lag, "z_F - F [N]",
             "the magnetic force lags the current: eddy currents or magnetic after-effect in the core or the "
             "filler (a fraction c of the force follows with tau_F)", lambda p: 1.0, lag="F"),
    TermSpec("eddy_current", "coil", "Ohm", eddy_current, "z_I - I [A]",
             "eddy currents in the core, a shorted secondary: slow current changes see the inductance "
             "L + c*tau_I, fast ones only L (the leakage inductance) and the extra resistance c",
             lambda p: p.R, lag="I", shares="L"),
    TermSpec("current_cubic", "coil", "Ohm/A2", current_cubic, "-I^3 [A3]",
             "resistance rising with the current: the driver's output stage, fast heating of the winding (a falling "
             "one, c < 0, would run away: no steady current above a bound)", lambda p: p.R / _current(p) ** 2,
             nonnegative=True),
    TermSpec("x_quadratic", "x_reading", "1/m", x_quadratic, "x^2 [m2]",
             "even nonlinearity of the displacement sensor: laser triangulation gain over its range",
             lambda p: 1.0 / _gap(p)),
    TermSpec("x_cubic", "x_reading", "1/m2", x_cubic, "x^3 [m3]",
             "odd nonlinearity of the displacement sensor: linearity error at the ends of its range",
             lambda p: 1.0 / _gap(p) ** 2),
    TermSpec("F_quadratic", "F_reading", "1/N", F_quadratic, "F^2 [N2]",
             "nonlinearity of the force transducer", lambda p: 1.0 / (p.K2 * _gap(p))),
    TermSpec("F_creep", "F_reading", "1", F_creep, "z_Fs - F [N]",
             "creep of the load cell: a slow part of the reading follows the force with tau_Fs",
             lambda p: 1.0, lag="Fs"),
    TermSpec("dahl_friction", "force", "N", dahl_friction, "-z_dahl [1]",
             "presliding (Dahl) friction in the clamping or at the rim: a friction force that builds up over the "
             "presliding length tau_dahl as a motion starts, is c while sliding, and holds the diaphragm where "
             "it stops (hysteresis of x in the force)", lambda p: p.C * _speed(p), lag="dahl", nonnegative=True),
)}

TERM_COEF_SPECS: tuple[ParamSpec, ...] = tuple(t.coef for t in TERMS.values())
LAG_TAU_SPECS: tuple[ParamSpec, ...] = tuple(g.tau for g in LAGS.values())
#: every parameter of the term set, in FMU order (coefficients, then time constants)
TERM_SPECS: tuple[ParamSpec, ...] = TERM_COEF_SPECS + LAG_TAU_SPECS
LAG_STATES: tuple[str, ...] = tuple(g.state for g in LAGS.values())


def active_terms(p) -> tuple:
    """Names of the terms with a nonzero coefficient in p (Params or a mapping name -> value)."""
    get = p.get if isinstance(p, dict) else (lambda k, d=0.0: getattr(p, k, d))
    return tuple(n for n, t in TERMS.items() if float(get(t.coef.name, 0.0)) != 0.0)


def lags_in_use(p) -> tuple:
    """Names of the lags (``LAGS``) that a term with a nonzero coefficient in p uses."""
    used = {TERMS[n].lag for n in active_terms(p)}
    return tuple(g for g in LAGS if g in used)


def check_terms(values: dict) -> None:
    """``ValueError`` naming the parameter if a term is on (nonzero coefficient) without its lag's time
    constant > 0 (values: {parameter name: value})."""
    for n, t in TERMS.items():
        if t.lag is None or float(values.get(t.coef.name, 0.0)) == 0.0:
            continue
        tau = LAGS[t.lag].tau
        if not float(values.get(tau.name, 0.0)) > 0.0:
            raise ValueError(f"parameter {tau.name} [s] must be > 0 when {t.coef.name} != 0 (term {n} on), got "
                             f"{values.get(tau.name, 0.0)!r}")


def markdown_table() -> str:
    """The term library as a Markdown table (docs/model.md holds it; tests/sim/test_terms.py checks it is
    the table's): term, equation, kind, coefficient [unit], basis, lag, physical reading."""
    rows = ["| term | equation | kind | coefficient [unit] | basis | lag | physical reading |",
            "|---|---|---|---|---|---|---|"]
    for t in TERMS.values():
        sign = " (>= 0)" if t.nonnegative else ""
        lag = f"z_{t.lag}, tau_{t.lag}" if t.lag else ""
        basis = t.basis.replace("|", "\\|")      # a literal | inside a Markdown table cell
        rows.append(f"| `{t.name}` | {t.equation} | {t.kind} | `{t.coef.name}` [{t.unit}]{sign} | {basis} | {lag} "
                    f"| {t.reading} |")
    rows += ["", "| lag state | input u | rate | constant |", "|---|---|---|---|"]
    for g in LAGS.values():
        rate = (g.rate_text or "z' = (u - z)/tau").replace("|", "\\|")
        rows.append(f"| `{g.state}` [{g.unit}] | {g.description} | {rate} | `tau_{g.name}` [{g.constant_unit}] |")
    return "\n".join(rows) + "\n"


assert len({t.coef.name for t in TERMS.values()}) == len(TERMS)
assert all(t.scale is not None for t in TERMS.values())
