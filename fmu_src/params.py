"""Model parameters: names, SI units, descriptions, defaults and validation.

The defaults describe a plausible 20 wt%, 45 mm, 1.5 mm thick MPC diaphragm in
front of a 50 mm holding electromagnet (coil radius 15 mm, 0.29 T/A at the coil
face), at a gap of 9 mm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, asdict, replace

MU0 = 4e-7 * math.pi  # vacuum permeability [H/m]


@dataclass(frozen=True)
class ParamSpec:
    name: str
    unit: str            # SI unit string as used in the modelDescription
    default: float
    description: str
    positive: bool = True      # must be > 0
    nonnegative: bool = False  # must be >= 0 (used when positive is False)


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


@dataclass(frozen=True)
class Params:
    """Parameters of the paper's model (SI units; see ``SPECS`` for descriptions)."""
    a: float = 0.015
    r0: float = 0.009
    D: float = 0.045
    kB: float = 0.29
    R: float = 15.0
    L: float = 0.12
    Em: float = 0.0423
    K1: float = 2.0e5
    K2: float = 40.0
    C: float = 0.5
    m: float = 0.004
    blocked: bool = False
    # Candidate effects (fmu_src.effects.EFFECT_SPECS has units and descriptions); 0 = off.
    Rth: float = 0.0      # coil_heating
    tau_th: float = 0.0
    ksat: float = 0.0     # filler_saturation
    Kc: float = 0.0       # viscoelastic_creep
    tau_c: float = 0.0
    K5: float = 0.0       # edge_stiffening
    lam: float = 0.0      # motional_emf
    tau_s: float = 0.0    # sensor_lag

    def validated(self) -> "Params":
        """Return self after checking every value; raise ``ValueError`` naming the bad parameter."""
        validate(asdict(self))
        return self

    def with_(self, **kw) -> "Params":
        return replace(self, **kw)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def mu0N(self) -> float:
        """mu0 * N [T.m/A] of the equivalent loop, from kB = mu0*N/(2a)."""
        return 2.0 * self.a * self.kB

    @property
    def N_turns(self) -> float:
        """Effective turn count N (dimensionless)."""
        return self.mu0N / MU0


def validate(values: dict) -> None:
    """Check parameter values; raise ``ValueError`` with the parameter's name and the rule it breaks.

    Covers the paper's parameters (``SPECS``) and the effect parameters
    (``fmu_src.effects.EFFECT_SPECS``, including rules between them).
    """
    from .effects import EFFECT_SPECS, check_effect_rules  # lazy: fmu_src.effects imports this module
    for spec in SPECS + EFFECT_SPECS:
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
    check_effect_rules(values)


def param_names() -> list[str]:
    return [s.name for s in SPECS]


assert [f.name for f in fields(Params)][: len(SPECS)] == [s.name for s in SPECS]
# fields after "blocked": the effect parameters, in the order of fmu_src.effects.EFFECT_SPECS (checked there)
EFFECT_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Params)[len(SPECS) + 1:])
assert all(getattr(Params, s.name) == s.default for s in SPECS)
