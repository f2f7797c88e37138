"""Frozen, validated settings of the vectorized simulator (``harness.sim``) and its typed error.

* :class:`MechParams` -- the fixed parameters of one test of the identification's population runs
  (everything but C and m);
* :class:`PopulationSettings` -- tolerances of :func:`harness.sim.population.integrate`;
* :class:`Schedule` -- output grid and step schedule of :func:`harness.sim.simulator.simulate`.

Units: SI throughout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["SimInputError", "MechParams", "PopulationSettings", "Schedule"]


class SimInputError(ValueError):
    """Invalid input of the simulator (time grid, parameters, shapes)."""


def _check(name: str, val, positive: bool) -> None:
    if not math.isfinite(val) or (val <= 0 if positive else val < 0):
        raise SimInputError(f"parameter {name} must be {'> 0' if positive else '>= 0'} and finite, got {val!r}")


@dataclass(frozen=True)
class MechParams:
    """Parameters of one test that do not change with the candidate's (C, m).

    Attributes
    ----------
    R : coil resistance [Ohm];  L : inductance [H];  r0 : gap [m];  Em : magnetic coefficient [N.m/T^2];
    K1 : cubic spring coefficient [N/m^3];  K2 : linear spring coefficient [N/m];
    a : coil radius [m];  D : diaphragm diameter [m];  kB : field per ampere at the coil face [T/A].
    """

    R: float
    L: float
    r0: float
    Em: float
    K1: float
    K2: float
    a: float
    D: float
    kB: float

    def __post_init__(self):
        for name in ("R", "L", "r0", "K2", "a", "D", "kB"):
            _check(name, float(getattr(self, name)), True)
        for name in ("Em", "K1"):
            _check(name, float(getattr(self, name)), False)

    @classmethod
    def of(cls, p, r0: float | None = None) -> "MechParams":
        """From a ``fmu_src.params.Params`` p, optionally with another gap r0 [m]."""
        return cls(R=p.R, L=p.L, r0=p.r0 if r0 is None else float(r0), Em=p.Em, K1=p.K1, K2=p.K2, a=p.a,
                   D=p.D, kB=p.kB)


@dataclass(frozen=True)
class PopulationSettings:
    """Tolerances of the population integration (:func:`harness.sim.population.integrate`).

    Attributes
    ----------
    settle_rtol : float
        Relative energy distance from the equilibrium at which a candidate counts as settled (its
        record is then filled with the equilibrium); 0: integrate every candidate to the end.
    check_every : int
        Samples between settle checks (at absolute sample indices: a candidate's result does not
        depend on the rest of the batch).
    max_substeps : int
        Upper bound of the RK4 sub-steps per sample interval.
    rk_tol : float
        Tolerated phase error of the oscillation relative to its amplitude (sets the sub-steps).
    linear_tail : bool or float
        Leave the integration once the motion is linear to this relative tolerance (True:
        settle_rtol; False: never) and write the exact linearized solution (in the compiled core).
    substeps : int or None
        Overrides the per-candidate sub-step count.
    """

    settle_rtol: float = 1e-5
    check_every: int = 10
    max_substeps: int = 64
    rk_tol: float = 1e-4
    linear_tail: bool | float = True
    substeps: int | None = None

    def __post_init__(self):
        if not (self.settle_rtol >= 0 and self.rk_tol > 0 and self.check_every >= 1 and self.max_substeps >= 1):
            raise SimInputError(f"invalid population settings {self!r}")

    @property
    def linear_tol(self) -> float:
        """Relative tolerance of the linear tail (0.0: off)."""
        if self.linear_tail is True:
            return float(self.settle_rtol)
        return float(self.linear_tail) if self.linear_tail else 0.0


@dataclass(frozen=True)
class Schedule:
    """Output grid and step schedule of :func:`harness.sim.simulator.simulate`.

    Attributes
    ----------
    t_end : float
        Duration [s] of the runs with a constant input (local time from the input onset).
    fine_s : float or None
        With a constant input, outputs every sample period up to fine_s [s], then every
        ``coarse_out`` samples (quasi-static remainder, larger steps); None: fine to t_end.
    coarse_out : int
        Output spacing [samples] of the coarse part.
    tol_I : float
        Current change [A] below which (over 50 ms, with the reading's change below the run's tol_y)
        a run without slow states counts as settled and is frozen.
    """

    t_end: float = 2.8
    fine_s: float | None = 0.5
    coarse_out: int = 4
    tol_I: float = 1e-7

    def __post_init__(self):
        if not (self.t_end > 0 and self.coarse_out >= 1 and self.tol_I >= 0):
            raise SimInputError(f"invalid schedule {self!r}")
        if self.fine_s is not None and not self.fine_s >= 0:
            raise SimInputError(f"fine_s [s] must be >= 0, got {self.fine_s!r}")
