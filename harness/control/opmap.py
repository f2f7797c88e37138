"""Operating map and static inverse of the actuator (steady states of ``fmu_src.statics``).

    m = operating_map(Params(), gaps_m=[0.005, 0.007, 0.009])   # steady x against V per gap, pull-in
    V = static_inverse(Params(), 1e-3)                            # volts that hold x = 1 mm

Units: SI (V, m).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmu_src.specs import Params
from fmu_src.statics import Statics


@dataclass(frozen=True)
class GapCurve:
    """Stable static curve at one gap: x [m] on [0, x_pull_in] and the voltage V [V] that holds it."""
    r0_m: float
    x_m: np.ndarray
    V_V: np.ndarray
    x_pull_in_m: float
    V_pull_in_V: float

    def displacement(self, V) -> np.ndarray:
        """Steady displacement [m] under V [V]: on the stable branch, r0 (contact) above pull-in."""
        V = np.abs(np.asarray(V, dtype=float))
        return np.where(V >= self.V_pull_in_V, self.r0_m, np.interp(V, self.V_V, self.x_m))


@dataclass(frozen=True)
class OperatingMap:
    """Static curves over gaps (see ``GapCurve``)."""
    params: Params
    curves: tuple

    def grid(self, V_V) -> np.ndarray:
        """Steady displacement [m], shape (gaps, len(V_V)), contact (x = r0) beyond pull-in."""
        return np.array([c.displacement(V_V) for c in self.curves])


def gap_curve(p: Params, n: int = 121) -> GapCurve:
    """The stable static curve of p at its gap p.r0."""
    s = Statics(p)
    x, V = s.table(n)
    return GapCurve(p.r0, x, V, s.x_holdable, s.v_pull_in)


def operating_map(p: Params, gaps_m, n: int = 121) -> OperatingMap:
    """Static curves of p at each gap in gaps_m [m] (every other parameter as in p)."""
    gaps = [float(g) for g in gaps_m]
    if not gaps or min(gaps) <= 0.0:
        raise ValueError(f"gaps_m must be positive gaps [m], got {gaps_m!r}")
    return OperatingMap(p, tuple(gap_curve(p.with_(r0=g), n) for g in gaps))


def static_inverse(p: Params, x_m: float) -> float:
    """Steady voltage [V] that holds the displacement x_m [m] (stable only up to ``holdable_limit``)."""
    return Statics(p).voltage_for(float(x_m))


def holdable_limit(p: Params) -> tuple[float, float]:
    """(x_holdable [m], V_pull_in [V]): the displacements [0, x_holdable] can be held open loop (x_holdable =
    the pull-in displacement unless coil heating runs away first)."""
    s = Statics(p)
    return s.x_holdable, s.v_pull_in
