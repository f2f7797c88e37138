"""Targets and design space of ``mpc-actuator design``.

A design is (filler fraction wt% [wt%], diameter D [mm], gap r0 [mm], voltage V [V]); the space is a
grid over ranges (or fixed values) of the four. Targets are bounds on the metrics of
:mod:`harness.analysis.design.evaluate`; a design meets the spec when every given bound holds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DesignError", "Targets", "Axis", "DesignSpace"]


class DesignError(ValueError):
    """Targets or a design space that cannot be used (the message names the option)."""


def _opt(name: str, v, positive: bool = True):
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise DesignError(f"{name} must be a number, got {v!r}") from None
    if not math.isfinite(f) or (positive and f <= 0):
        raise DesignError(f"{name} must be a finite number > 0, got {v!r}")
    return f


@dataclass(frozen=True)
class Targets:
    """The spec a design must meet (at least one target; None: no target).

    Parameters
    ----------
    stroke_mm : float or None
        Minimum stroke [mm] (displacement after the step).
    blocked_force_N : float or None
        Minimum blocked force at the gap [N].
    settling_ms : float or None
        Maximum 2 % settling time [ms].
    max_current_A : float or None
        Maximum steady coil current [A].
    max_power_W : float or None
        Maximum steady coil power [W].
    allow_contact : bool
        Reaching the coil face counts as meeting a stroke (default no: the stroke must be a controlled
        equilibrium).
    min_bandwidth_Hz : float or None
        Minimum bandwidth [Hz].

    Examples
    --------
    >>> Targets(stroke_mm=1.0, max_power_W=10.0).met({"stroke_m": 1.2e-3, "current_A": 0.8, "power_W": 9.6,
    ...                                                "contact": False}).item()
    True
    """
    stroke_mm: float | None = None
    blocked_force_N: float | None = None
    settling_ms: float | None = None
    max_current_A: float | None = None
    max_power_W: float | None = None
    allow_contact: bool = False
    min_bandwidth_Hz: float | None = None

    def __post_init__(self):
        for n in ("stroke_mm", "blocked_force_N", "settling_ms", "max_current_A", "max_power_W", "min_bandwidth_Hz"):
            object.__setattr__(self, n, _opt(f"--{n.replace('_', '-')}", getattr(self, n)))
        if all(getattr(self, n) is None for n in ("stroke_mm", "blocked_force_N", "settling_ms", "max_current_A",
                                                   "max_power_W", "min_bandwidth_Hz")):
            raise DesignError("no target given: name at least one of --stroke-mm, --blocked-force-N, "
                              "--settling-ms, --max-current-A, --max-power-W, --min-bandwidth-Hz")

    def bound_margins(self, m: dict) -> list:
        """Relative margins (>= 0: met) of the given blocked-force, current, power and bandwidth targets on the
        metrics ``m`` (arrays or scalars), in that order; the stroke and settling margins are the callers' (they
        read different stroke metrics and treat contact differently).

        Parameters
        ----------
        m : dict
            Metrics: ``blocked_force_N`` [N], ``current_A`` [A], ``power_W`` [W], ``bandwidth_Hz`` [Hz].
        """
        r = []
        if self.blocked_force_N is not None:
            r.append(m["blocked_force_N"] / self.blocked_force_N - 1)
        if self.max_current_A is not None:
            r.append(1 - m["current_A"] / self.max_current_A)
        if self.max_power_W is not None:
            r.append(1 - m["power_W"] / self.max_power_W)
        if self.min_bandwidth_Hz is not None:
            r.append(m["bandwidth_Hz"] / self.min_bandwidth_Hz - 1)
        return r

    def met(self, m: dict) -> np.ndarray:
        """Boolean array: designs whose metrics ``m`` (:data:`harness.analysis.design.evaluate.METRICS`) meet the spec.

        Parameters
        ----------
        m : dict
            Metrics (arrays of one shape, or scalars): ``stroke_m`` [m], ``current_A`` [A], ``contact``, and those
            of the targets given.
        """
        ok = np.ones(np.shape(m["current_A"]), dtype=bool)
        if self.stroke_mm is not None:
            ok &= m["stroke_m"] * 1e3 >= self.stroke_mm
        if self.blocked_force_N is not None:
            ok &= m["blocked_force_N"] >= self.blocked_force_N
        if self.settling_ms is not None:
            ok &= m["settling_s"] * 1e3 <= self.settling_ms
        if self.max_current_A is not None:
            ok &= m["current_A"] <= self.max_current_A
        if self.max_power_W is not None:
            ok &= m["power_W"] <= self.max_power_W
        if self.min_bandwidth_Hz is not None:
            ok &= m["bandwidth_Hz"] >= self.min_bandwidth_Hz
        if not self.allow_contact:
            ok &= ~np.asarray(m["contact"], dtype=bool)
        return ok

    def to_json(self) -> dict:
        """The targets as a JSON object (units in the keys)."""
        return {k: getattr(self, k) for k in ("stroke_mm", "blocked_force_N", "settling_ms", "max_current_A",
                                              "max_power_W", "min_bandwidth_Hz", "allow_contact")}


@dataclass(frozen=True)
class Axis:
    """One design variable: a fixed value (lo == hi, n = 1) or n points from lo to hi."""
    name: str
    lo: float
    hi: float
    n: int = 1

    @classmethod
    def parse(cls, name: str, values, n: int) -> "Axis":
        """From 1 value (fixed) or 2 values (a range of n points); the option name in errors."""
        vals = [_opt(f"--{name.replace('_', '-')}", v) for v in (values or [])]
        if len(vals) == 1:
            return cls(name, vals[0], vals[0], 1)
        if len(vals) != 2:
            raise DesignError(f"--{name.replace('_', '-')}: give one value (fixed) or two (a range), got {values!r}")
        lo, hi = vals
        if lo > hi:
            opt = f"--{name.replace('_', '-')}"
            raise DesignError(f"{opt} {lo:g} {hi:g}: a range is given low then high (did you mean {opt} {hi:g} "
                              f"{lo:g}?)")
        if not (isinstance(n, int) and n >= 2):
            raise DesignError(f"--points must be a whole number >= 2, got {n!r}")
        return cls(name, lo, hi, n if hi > lo else 1)

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.lo, self.hi, self.n) if self.n > 1 else np.array([self.lo])


@dataclass(frozen=True)
class DesignSpace:
    """The grid: wt_pct [wt%], diameter_mm [mm], gap_mm [mm], voltage_V [V] axes."""
    wt_pct: Axis
    diameter_mm: Axis
    gap_mm: Axis
    voltage_V: Axis

    @property
    def axes(self) -> tuple:
        return (self.wt_pct, self.diameter_mm, self.gap_mm, self.voltage_V)

    @property
    def shape(self) -> tuple:
        return tuple(a.n for a in self.axes)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def to_json(self) -> dict:
        return {a.name: {"min": a.lo, "max": a.hi, "points": a.n} for a in self.axes}
