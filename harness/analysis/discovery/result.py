"""A discovered term as the verdict and the report state it (:class:`DiscoveredTerm`, :func:`discovered_term`).

Its equation with units (where it enters and its basis function), the fitted coefficient per sample with
its standard uncertainty (from the shared fit's covariance s^2 (J^T J)^-1, through the term's natural scale),
the lag's time constant when it has one, its physical reading, the kind of physics (mechanical, coil,
reading), and where it matters: the tests and signals whose chi-square it lowers and the samples it helps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .library import constant_unit, ratio_key, shared_field, tau_key

#: how a term enters its equation (the paper model's equation the term is added to)
EQUATION_TEXT = {
    "force": "m x'' = F - C v - (K1 x^2 + K2) x + c {basis}",
    "coil": "L I' = V - R I + c {basis}",
    "x_reading": "x_reading = x + c {basis}",
    "F_reading": "F_reading = F + c {basis}",
}


@dataclass(frozen=True)
class DiscoveredTerm:
    """A term the discovery added (values in SI units; ``coefficient`` {sample id: (value, std)})."""
    name: str
    kind: str
    equation: str
    reading: str
    coefficient_name: str
    coefficient_unit: str
    ratio: float
    ratio_std: float | None
    coefficient: dict
    tau_name: str | None = None
    tau_s: float | None = None
    tau_std_s: float | None = None
    tau_unit: str = "s"            # unit of the lag's constant (``LagSpec.constant_unit``: "m" for Dahl's x_c)
    shows_in: tuple = ()
    samples: tuple = ()
    delta_bic: float = float("nan")
    delta_chi2_heldout: float = float("nan")
    reason: str = ""
    extra: dict = field(default_factory=dict)

    def summary(self) -> str:
        """One line: the equation, the coefficient's range over the samples, the reading."""
        vals = [v for v, _ in self.coefficient.values()]
        rng = (f"{min(vals):.4g} .. {max(vals):.4g}" if vals and min(vals) != max(vals)
               else f"{vals[0]:.4g}" if vals else "?")
        tau = f", tau_{self.tau_name} = {self.tau_s:.4g} {self.tau_unit}" if self.tau_s is not None else ""
        return (f"{self.name} ({self.kind}): {self.equation}, {self.coefficient_name} = {rng} "
                f"{self.coefficient_unit}{tau}; {self.reading}")


def _f(x):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def discovered_term(library, name: str, comparison, final_params: dict, uncertainty: dict,
                    sample_drop: dict) -> DiscoveredTerm:
    """The :class:`DiscoveredTerm` of term ``name`` of ``library`` accepted with ``comparison`` (``shared``
    natural values, ``shows_in``, ``d_bic``, ``d_heldout``, ``reason``), the final model's Params
    {sample id: Params}, the shared parameters' standard uncertainties {key: std (natural)} and the chi-square
    decrease per sample {sample id: decrease} it brought."""
    spec = library.spec(name)
    r = float(comparison.shared.get(ratio_key(name), 0.0))
    r_sd = uncertainty.get(ratio_key(name))
    coef = {}
    for sid, p in final_params.items():
        sc = library.natural_scale(p, name)
        coef[sid] = (float(getattr(p, spec.coef.name)), None if r_sd is None else abs(sc) * float(r_sd))
    tau = tau_sd = None
    if spec.lag:
        tau = float(comparison.shared.get(tau_key(spec.lag), float("nan")))
        tau_sd = uncertainty.get(tau_key(spec.lag))
    eq = EQUATION_TEXT.get(spec.equation, "{basis}").format(basis=f"({spec.basis})")
    eq = f"{eq}, c = {spec.coef.name} [{spec.coef.unit}]"
    share = shared_field(spec)
    if share:
        eq = f"{eq}; {share} the fast value, {share} + c*tau_{spec.lag} the slow one"
    samples = tuple(sorted(((sid, float(v)) for sid, v in sample_drop.items()), key=lambda q: -q[1]))
    return DiscoveredTerm(name=name, kind=spec.kind, equation=eq, reading=spec.reading,
                          coefficient_name=spec.coef.name, coefficient_unit=spec.coef.unit, ratio=r,
                          ratio_std=None if r_sd is None else float(r_sd), coefficient=coef,
                          tau_name=spec.lag, tau_s=tau, tau_std_s=None if tau_sd is None else float(tau_sd),
                          tau_unit=constant_unit(spec.lag) if spec.lag else "s",
                          shows_in=tuple(comparison.shows_in), samples=samples,
                          delta_bic=float(comparison.d_bic), delta_chi2_heldout=float(comparison.d_heldout),
                          reason=comparison.reason)


def term_json(t: DiscoveredTerm, signal_name=None) -> dict:
    """The JSON entry of a discovered term (units in the keys; ``signal_name(test, channel)`` names a signal)."""
    unit = t.coefficient_unit
    return {
        "name": t.name, "kind": t.kind, "equation": t.equation, "physical_reading": t.reading,
        "coefficient": {"name": t.coefficient_name, "unit": unit,
                        "per_sample": {sid: {"value": _f(v), "std": _f(s)} for sid, (v, s) in t.coefficient.items()}},
        "ratio_to_natural_scale_1": {"value": _f(t.ratio), "std": _f(t.ratio_std)},
        "lag_time_constant_s": (None if t.tau_s is None else
                                {"name": f"tau_{t.tau_name}", "value": _f(t.tau_s), "std": _f(t.tau_std_s),
                                 "unit": t.tau_unit}),
        "delta_bic": _f(t.delta_bic), "delta_chi2_heldout": _f(t.delta_chi2_heldout), "reason": t.reason,
        "shows_in": [{"test": te, "signal": signal_name(te, ch) if signal_name else ch, "delta_chi2": _f(v)}
                     for te, ch, v in t.shows_in[:6]],
        "samples": [{"id": sid, "delta_chi2": _f(v)} for sid, v in t.samples],
    }
