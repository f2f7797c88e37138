"""The library of candidate terms as the fit sees them, derived from ``fmu_src.terms.TERMS`` (the one table).

A :class:`Library` (PySINDy's library/optimizer split: the library says *what* may be added, the selector
(:mod:`.selector`) *which*) turns each term of the physics' term table into the parameters a fit moves:

* ``ratio_<name>`` = c_<name> / scale(p): the term's coefficient relative to its natural scale at the
  sample's operating point (``TermSpec.scale``), signed unless the term's physics fixes the sign, starting at
  0 (the term off: a candidate starts at the optimum of the model it extends), shared by the samples (one
  mechanism of the rig, its strength relative to each sample's own terms);
* ``tau_lag_<lag>``: the time constant (fitted as its logarithm) of the term's lag state (history terms), shared;
* for a term that shares a parameter of its equation (``TermSpec.shares``: the coil's L for ``eddy_current``,
  L I' = V - R I + c (z_I - I), whose slow inductance is L + c tau_I), ``ratio_<name>`` is instead the share
  s = c tau/(L + c tau) in [0, ``SHARE_BOUND``] of the slow value that the lag carries (a shorted secondary's
  coupling k^2), and the base parameter L the fit moves stays the slow value the paper model identifies (within
  its box): the model's L is (1 - s) L and c = s L/tau (:meth:`TermLibrary.apply`). Fitted as c/scale against
  the model's own L, the lag could only take over inductance by pulling the fast L below the box the fit keeps
  the slow one in (the paper model's L is the slow one: its step fit sees the rise over tens of ms).

It never lists term names itself: adding a term to ``fmu_src.terms.TERMS`` adds it here.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

from harness.analysis.core.lsq import SharedParam

#: [s] range of a lag's time constant: from a fast eddy-current lag (0.1 ms) to a thermal one (300 s)
TAU_RANGE_S = (1e-4, 300.0)
TAU_START_S = 0.3
#: a lag's time constant is fitted down to this part of the data's shortest sample period dt (and not below
#: TAU_RANGE_S[0]; :meth:`TermLibrary.at_resolution`): a lag of tau <= dt/10 has decayed by e^-10 within one sample,
#: so the readings see it as instantaneous (its delay of a step's response, at most tau, is a third of the step
#: instant's own uncertainty dt/sqrt(12)), while its simulation needs steps of 0.3 tau (deep profile, session 17: at
#: 100 Hz a lag driven to 0.1 ms cost 2.7 CPU-s per simulation and a diagnosis 166 CPU-s)
LAG_RESOLUTION = 0.1
#: [s] starts of a lag's time constant: a term with a lag not yet fitted is fitted from each (a fast one, of the
#: coil's and the diaphragm's dynamics, and a slow one, of the holds) and the better fit kept: from 0 strength the
#: fit cannot tell which way tau should go (d residual / d tau = 0 while the coefficient is 0)
TAU_STARTS_S = (0.01, 2.0)
#: [m] range, start and starts of a lag's constant that is a length (Dahl's presliding length x_c, ``LagSpec.rate``):
#: from 1 um (a stiff clamp) to 1 mm (a third of a typical stroke: beyond it the friction never slides)
LENGTH_RANGE_M = (1e-6, 1e-3)
LENGTH_START_M = 2e-5
LENGTH_STARTS_M = (1e-5, 1e-4)
#: range (lo, hi, start) and starts of a lag's constant by its unit (``LagSpec.constant_unit``)
CONSTANT_RANGES = {"s": ((TAU_RANGE_S[0], TAU_RANGE_S[1], TAU_START_S), TAU_STARTS_S),
                   "m": ((LENGTH_RANGE_M[0], LENGTH_RANGE_M[1], LENGTH_START_M), LENGTH_STARTS_M)}
#: |c / scale| is fitted within this bound (a term 100 x its natural scale is no longer a correction)
RATIO_BOUND = 100.0
#: a term sharing a parameter (``TermSpec.shares``) carries at most this share of its slow value (k^2 <= 0.95: the
#: fast value at least 5 % of the slow one; a passive secondary has 0 <= k^2 < 1)
SHARE_BOUND = 0.95


#: a fitted parameter of a term: the diagnosis's shared parameter (``key``, ``effect`` (the term's name), ``unit``
#: (of the natural value), ``log``, bounds ``lo``/``hi``, finite-difference step ``fd`` and start ``init`` in the
#: fitted scale, ``description``, ``prior_sd``)
TermParam = SharedParam


class Library(ABC):
    """Candidate terms: their names, their fitted parameters, and how fitted values set model parameters."""

    @property
    @abstractmethod
    def names(self) -> tuple:
        """The candidate terms' names, in table order."""

    @abstractmethod
    def params(self, name: str) -> tuple:
        """The :class:`TermParam` s fitted with term ``name``."""

    @abstractmethod
    def apply(self, p, fitted: dict):
        """Params ``p`` with the coefficients and time constants of the terms whose keys are in ``fitted``
        {key: fitted value} set; unchanged when none is."""

    @abstractmethod
    def spec(self, name: str):
        """The physics' description of term ``name`` (``fmu_src.terms.TermSpec``)."""

    def starts(self, name: str, fitted: dict) -> list:
        """Start values {key: fitted value} to fit term ``name`` from, given the reference model's ``fitted``
        values: one start (the term off) unless it brings a lag time constant not yet fitted."""
        return [{}]

    def natural_scale(self, p, name: str) -> float:
        """d c_<name> / d ratio_<name> [its unit] at sample parameters ``p``: the term's natural scale
        (``TermSpec.scale``)."""
        return float(self.spec(name).scale(p))


def ratio_key(name: str) -> str:
    return f"ratio_{name}"


def tau_key(lag: str) -> str:
    return f"tau_lag_{lag}"


def _signed(spec) -> bool:
    """Whether the coefficient may take either sign (the term table's ParamSpec: not positive/nonnegative)."""
    c = spec.coef
    return not (getattr(c, "positive", False) or getattr(c, "nonnegative", False))


def shared_field(spec) -> str | None:
    """The Params field term ``spec`` shares with its equation (``TermSpec.shares``), or None."""
    return getattr(spec, "shares", None)


def constant_unit(lag: str) -> str:
    """Unit of the constant of lag ``lag`` (``fmu_src.terms.LAGS``; "s" for a lag the table does not know)."""
    from fmu_src.terms import LAGS
    g = LAGS.get(lag)
    return getattr(g, "constant_unit", "s") if g is not None else "s"


class TermLibrary(Library):
    """The library of a term table {name: TermSpec} (default: ``fmu_src.terms.TERMS``, :func:`default_library`)."""

    def __init__(self, table: dict, lag_ranges: dict | None = None):
        self.table = dict(table)
        self.lag_ranges = dict(lag_ranges or {})
        self._params = {n: self._make(n, s) for n, s in self.table.items()}
        self._by_key = {d.key: (n, d) for n, ds in self._params.items() for d in ds}

    @property
    def names(self) -> tuple:
        return tuple(self.table)

    def spec(self, name: str):
        return self.table[name]

    def _make(self, name: str, spec) -> tuple:
        share = shared_field(spec)
        if share:
            out = [TermParam(ratio_key(name), name, "1", False, 0.0, SHARE_BOUND, 1e-5, 0.0,
                             f"share c_{name}*tau_{spec.lag}/({share} + c_{name}*tau_{spec.lag}) of the slow {share} "
                             f"carried by the lag ({spec.basis}; {spec.equation} equation; shared: one rig)")]
        else:
            lo = -RATIO_BOUND if _signed(spec) else 0.0
            out = [TermParam(ratio_key(name), name, "1", False, lo, RATIO_BOUND, 1e-5, 0.0,
                             f"c_{name} / its natural scale ({spec.basis}; {spec.equation} equation; shared: one rig)")]
        if spec.lag:
            unit = constant_unit(spec.lag)
            lo_s, hi_s, t0 = self.lag_ranges.get(spec.lag, CONSTANT_RANGES[unit][0])
            what = "time constant" if unit == "s" else f"constant [{unit}]"
            out.append(TermParam(tau_key(spec.lag), name, unit, True, math.log(lo_s), math.log(hi_s), 1e-4,
                                 math.log(t0), f"{what} tau_{spec.lag} of the lag state of {spec.lag} "
                                               f"(shared: one rig)"))
        return tuple(out)

    def params(self, name: str) -> tuple:
        return self._params[name]

    def starts(self, name: str, fitted: dict) -> list:
        spec = self.table[name]
        if not spec.lag or tau_key(spec.lag) in fitted:
            return [{}]
        unit = constant_unit(spec.lag)
        lo, hi, _ = self.lag_ranges.get(spec.lag, CONSTANT_RANGES[unit][0])
        return [{tau_key(spec.lag): math.log(min(max(t, lo), hi))} for t in CONSTANT_RANGES[unit][1]]

    def at_resolution(self, dt_s: float) -> "TermLibrary":
        """This library with every time constant of a lag (unit s) fitted from ``LAG_RESOLUTION * dt_s`` up
        (dt_s [s]: the shortest sample period of the data the fits see; never below ``TAU_RANGE_S[0]``, its start
        raised to the bound if below it). A non-positive or non-finite dt_s leaves the ranges as they are."""
        if not (math.isfinite(float(dt_s)) and float(dt_s) > 0):
            return self
        ranges = dict(self.lag_ranges)
        for spec in self.table.values():
            if spec.lag and constant_unit(spec.lag) == "s":
                lo, hi, t0 = ranges.get(spec.lag, CONSTANT_RANGES["s"][0])
                lo = min(max(lo, LAG_RESOLUTION * float(dt_s)), hi)
                ranges[spec.lag] = (lo, hi, min(max(t0, lo), hi))
        return TermLibrary(self.table, ranges)

    def is_term(self, name: str) -> bool:
        return name in self.table

    def natural_scale(self, p, name: str) -> float:
        """d c_<name> / d ratio_<name> [its unit] at sample parameters ``p``: the term's natural scale, or for a term
        sharing a parameter (``TermSpec.shares``) the slow value over the time constant, (L + c tau)/tau (``p``
        must then have its time constant > 0)."""
        spec = self.table[name]
        share = shared_field(spec)
        if not share:
            return super().natural_scale(p, name)
        tau = float(getattr(p, f"tau_{spec.lag}"))
        if not tau > 0.0:
            raise ValueError(f"term {name}: tau_{spec.lag} must be > 0 to scale its share, got {tau!r}")
        return (float(getattr(p, share)) + float(getattr(p, spec.coef.name)) * tau) / tau

    def coefficient(self, p, name: str, ratio: float) -> float:
        """c_<name> [its unit] of the fitted ratio for sample parameters ``p`` (the scale is evaluated on ``p``)."""
        return float(ratio) * self.natural_scale(p, name) if float(ratio) != 0.0 else 0.0

    def apply(self, p, fitted: dict):
        """Time constants first, then the coefficients (a shared parameter's share needs its time constant);
        a term sharing a parameter moves the share s of its slow value P + c tau to the lag: c = s (P + c tau)/tau,
        P = (1 - s)(P + c tau) (its slow value unchanged)."""
        taus, ratios = {}, {}
        for key, v in fitted.items():
            hit = self._by_key.get(key)
            if hit is None:
                continue
            name, d = hit
            if d.log:
                taus[f"tau_{self.table[name].lag}"] = math.exp(float(v))
            else:
                ratios[name] = max(float(v), 0.0) if d.lo >= 0 else float(v)
        if not taus and not ratios:
            return p
        q = p.with_(**taus) if taus else p
        kw = {}
        for name, r in ratios.items():
            spec = self.table[name]
            c = self.coefficient(q, name, r)
            share = shared_field(spec)
            if share:
                tau = float(getattr(q, f"tau_{spec.lag}"))
                slow = float(getattr(q, share)) + float(getattr(q, spec.coef.name)) * tau
                kw[share] = slow - c * tau
            kw[spec.coef.name] = c
        return q.with_(**kw) if kw else q


_DEFAULT = None


def default_library() -> TermLibrary:
    """The library of ``fmu_src.terms.TERMS`` (built once)."""
    global _DEFAULT
    if _DEFAULT is None:
        from fmu_src.terms import TERMS
        _DEFAULT = TermLibrary(TERMS)
    return _DEFAULT
