"""Steady states of the actuator: equilibria, the static inverse (voltage that holds a displacement) and
the pull-in (contact) limit, for the paper's model and every effect that is on.

Above ``model`` in the layers of ``fmu_src`` (it uses ``Dynamics.rhs``, the compiled right-hand side the
FMU integrates): no second copy of the equations. A steady state has v = 0 and every rate zero:

* the current: I' = 0, i.e. V = R(T)*I (the coil's right-hand side is affine in V);
* every effect state by the steady-state rule its ``fmu_src.specs.StateSpec`` declares: its rate zero
  (affine in it: solved from two evaluations; e.g. the winding temperature rise), equal to x (the creep
  branch relaxed, the laser reading) or to the magnetic force (the force reading). No effect is named here;
* every lag state of the term set (``fmu_src.terms.LAGS``): its rate zero (z = its input u);
* the diaphragm: x'' = 0 at v = 0, i.e. magnetic force = restoring force.

For a target displacement x the current follows by ``scipy.optimize.brentq`` on x''(I) = 0 (the force grows
monotonically with |I|), then the voltage. A displacement can be held (open loop) where the equilibrium is
stable: d x''/dx < 0 at fixed current. Going up from x = 0 the equilibrium stays stable until the fold
x_pi (pull-in): above the pull-in voltage V(x_pi) no equilibrium is left and the diaphragm snaps onto the
coil face (contact). Used by the controller FMU's feed-forward (``fmu_src.mpc_controller``) and by
``harness.control.opmap``. SI units.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from .model import FREE, dynamics_class
from .specs import EFFECTS, Params, StateSpec
from .terms import LAGS, lags_in_use

#: every effect state's and lag state's spec by name (its steady-state rule)
_STATE_SPECS = {st.name: st for e in EFFECTS.values() for st in e.state_specs}
_STATE_SPECS.update({g.state: StateSpec(g.state, g.unit, g.description, mechanical=g.mechanical)
                     for g in LAGS.values()})
N_TABLE = 241   # points of the static-inverse table on [0, x_holdable]
I_CAP_A = 1e4   # the largest current [A] the search for a holding current admits


class Statics:
    """Steady states of one parameter set (``Params``; not blocked).

    ``V_max`` [V]: the largest admissible voltage (None: no voltage limit). Currents are searched up to
    ``I_CAP_A``; a displacement that no admissible current holds (filler saturation caps the force) is outside
    the holdable range, not an error of the range's computation (``x_holdable``, ``limit``)."""

    def __init__(self, p: Params, V_max: float | None = None):
        if p.blocked:
            raise ValueError("Statics: blocked mode has no displacement to hold")
        if V_max is not None and not math.isfinite(float(V_max)):
            raise ValueError(f"Statics: V_max [V] must be finite or None, got {V_max!r}")
        self.p = p
        self.V_max = None if V_max is None else float(V_max)
        self.dyn = dynamics_class(p)(p)
        self.names = self.dyn.state_names
        self.n = len(self.names)
        # a lag in use whose input reads the electrical states (the coil's power): the force balance needs them
        self._electrical_mech = any(LAGS[g].electrical_input and LAGS[g].mechanical for g in lags_in_use(p))
        self._x_pi = None
        self._x_hold = None
        self._limit = None

    # -- steady state of the non-mechanical states --------------------------------------------
    def state(self, I: float, x: float, electrical: bool = True) -> np.ndarray:
        """Steady state vector y [I, x, v = 0, effect states] at current I [A] and displacement x [m].

        Each effect state follows its ``StateSpec.steady`` rule (``fmu_src.specs``): "displacement" (x),
        "force" (the magnetic force at y), "rate_zero" (its rate, affine in it, vanishes: root from two
        evaluations of the right-hand side; it must be >= 0, else no steady state: e.g. thermal runaway).
        ``electrical`` False leaves the states that change only the electrical side (``mechanical``
        False, e.g. the winding temperature) at 0: the force balance does not depend on them."""
        y = np.zeros(self.n)
        y[0], y[1] = I, x
        idx = self.dyn.index
        specs = [(idx[n], _STATE_SPECS[n]) for n in self.names[3:]]
        for rule in ("displacement", "rate_zero", "force"):     # the force reading last: it reads the rest
            for i, st in specs:
                if st.steady != rule or not (electrical or st.mechanical or self._electrical_mech):
                    continue
                if rule == "displacement":
                    y[i] = x
                elif rule == "force":
                    y[i] = self.dyn.force(y, FREE)
                else:
                    y[i] = 0.0
                    r0 = self.dyn.rhs(y, 0.0, FREE)[i]
                    y[i] = 1.0
                    r1 = self.dyn.rhs(y, 0.0, FREE)[i]
                    y[i] = -r0 / (r1 - r0) if r1 != r0 else 0.0
                    if not (y[i] >= 0.0 and math.isfinite(y[i])):
                        raise ValueError(f"no steady state of {st.name} ({st.description}) at I = {I!r} A")
        return y

    def acceleration(self, I: float, x: float) -> float:
        """x'' [m/s^2] at rest (v = 0) in the steady state of current I [A] at displacement x [m]."""
        return self.dyn.rhs(self.state(I, x, electrical=False), 0.0, FREE)[2]

    def voltage(self, I: float, x: float) -> float:
        """Steady voltage [V] that drives the current I [A] at displacement x [m] (I' = 0)."""
        y = self.state(I, x)
        f0 = self.dyn.rhs(y, 0.0, FREE)[0]
        f1 = self.dyn.rhs(y, 1.0, FREE)[0]
        return -f0 / (f1 - f0)

    # -- equilibria ----------------------------------------------------------------------------
    def holds(self, x: float) -> bool:
        """True if a current up to ``I_CAP_A`` holds x [m] (0 <= x < r0) in a force balance (the magnetic
        force grows monotonically with |I|: the cap's force must reach the restoring force)."""
        return 0.0 <= x < self.p.r0 and (x == 0.0 or self.acceleration(I_CAP_A, x) >= 0.0)

    def current_for(self, x: float) -> float:
        """Current [A] (>= 0) whose magnetic force holds the diaphragm at x [m] (0 <= x < r0);
        ``ValueError`` if no current up to ``I_CAP_A`` can (filler saturation caps the force)."""
        if not 0.0 <= x < self.p.r0:
            raise ValueError(f"target displacement x = {x!r} m outside [0, r0 = {self.p.r0!r} m)")
        if x == 0.0:
            return 0.0
        if not self.holds(x):
            raise ValueError(f"no current up to {I_CAP_A:g} A holds x = {float(x)!r} m (the magnetic force "
                             "saturates below the restoring force)")
        hi = 1.0
        while self.acceleration(hi, x) < 0.0:
            hi = min(2.0 * hi, I_CAP_A)
        return brentq(lambda i: self.acceleration(i, x), 0.0, hi, xtol=1e-14, rtol=1e-13)

    def stiffness(self, x: float) -> float:
        """Net stiffness -m*d x''/dx [N/m] at the equilibrium x [m] at fixed current (> 0: stable)."""
        I = self.current_for(x)
        h = 1e-7 * max(self.p.r0, 1e-3)
        return -self.p.m * (self.acceleration(I, x + h) - self.acceleration(I, x - h)) / (2 * h)

    @property
    def x_pull_in(self) -> float:
        """End [m] of the stable open-loop branch from x = 0: the fold of the static curve (pull-in), or where no
        current up to ``I_CAP_A`` holds the diaphragm any more (the saturated force's limit), whichever comes
        first; r0 if the equilibrium stays stable and held up to the coil face."""
        if self._x_pi is None:
            r0 = self.p.r0
            xs = np.linspace(0.0, r0, 401)[1:-1]
            lo = 0.0                          # the last grid point on the stable branch
            for x in xs:
                if not self.holds(x):         # the saturated force's limit lies in (lo, x): bisect on "held"
                    a, b = lo, x
                    while b - a > 1e-9 * r0:
                        mid = 0.5 * (a + b)
                        a, b = (mid, b) if self.holds(mid) else (a, mid)
                    if a > lo and self.stiffness(a) <= 0.0:   # folds before it
                        self._x_pi = brentq(self.stiffness, lo, a, xtol=1e-12) if lo > 0.0 else 0.0
                        self._limit = "pull-in"
                    else:
                        self._x_pi, self._limit = a, "saturation"
                    break
                if self.stiffness(x) <= 0.0:
                    self._x_pi = brentq(self.stiffness, lo, x, xtol=1e-12) if lo > 0.0 else 0.0
                    self._limit = "pull-in"
                    break
                lo = x
            else:
                self._x_pi, self._limit = r0, "coil face"
        return self._x_pi

    @property
    def x_holdable(self) -> float:
        """Largest displacement [m] an admissible voltage holds in a stable steady state (the holdable range is
        [0, x_holdable]): ``x_pull_in``, or less where the winding has no thermal steady state (coil_heating: the
        current that holds x would run away thermally) or where the steady voltage exceeds ``V_max``.
        ``limit`` says which."""
        if self._x_hold is None:
            x = min(self.x_pull_in, self.p.r0 * (1 - 1e-9))
            if self._admissible(x):
                self._x_hold = x
            else:
                lo, hi = 0.0, x
                while hi - lo > 1e-9 * self.p.r0:
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if self._admissible(mid) else (lo, mid)
                self._x_hold = lo
                self._limit = "voltage limit" if self._steady(hi) else "thermal runaway"
        return self._x_hold

    @property
    def limit(self) -> str:
        """What ends the holdable range: "pull-in", "saturation", "thermal runaway", "voltage limit" or
        "coil face"."""
        _ = self.x_holdable
        return self._limit

    def _steady(self, x: float) -> bool:
        try:
            self.voltage_for(x)
            return True
        except ValueError:
            return False

    def _admissible(self, x: float) -> bool:
        try:
            V = self.voltage_for(x)
        except ValueError:
            return False
        return self.V_max is None or V <= self.V_max

    @property
    def v_pull_in(self) -> float:
        """The voltage [V] at ``x_holdable``: at the pull-in fold, above it no equilibrium is left (the diaphragm
        goes into contact)."""
        x = self.x_holdable
        return self.voltage(self.current_for(x), x)

    def voltage_for(self, x: float) -> float:
        """Static inverse: the steady voltage [V] that holds the displacement x [m] (any equilibrium,
        stable only for x <= ``x_pull_in``)."""
        return self.voltage(self.current_for(x), x)

    def table(self, n: int = N_TABLE) -> tuple[np.ndarray, np.ndarray]:
        """(x [m], V [V]) of the static inverse on n points of [0, x_holdable] (V increasing in x; a single
        point x = 0 when nothing above 0 is holdable)."""
        if self.x_holdable <= 0.0:
            return np.zeros(1), np.zeros(1)
        xs = np.linspace(0.0, self.x_holdable * (1 - 1e-9), n)
        return xs, np.array([self.voltage_for(x) for x in xs])

    def clip(self, x: float) -> float:
        """The target x [m] clipped to the holdable range [0, x_holdable]."""
        return min(max(float(x), 0.0), self.x_holdable)

    def displacement_for(self, V: float) -> float:
        """Stable steady displacement [m] under the voltage V [V]; r0 (contact) above the pull-in voltage. Only
        for voltages up to ``v_pull_in`` when the range ends otherwise than at the pull-in fold (ValueError)."""
        V = abs(float(V))
        if V >= self.v_pull_in:
            contact = self.limit in ("pull-in", "coil face")
            if not contact and V > self.v_pull_in:
                raise ValueError(f"V = {V!r} V is above the holdable range's voltage {self.v_pull_in!r} V "
                                 f"(limited by {self.limit})")
            return self.p.r0 if contact else self.x_holdable
        if V == 0.0:
            return 0.0
        return brentq(lambda x: self.voltage_for(x) - V, 0.0, self.x_holdable * (1 - 1e-9), xtol=1e-13)


def feedforward_table(p: Params, n: int = N_TABLE, V_max: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(x [m], V [V]) table of the static inverse of ``p`` on [0, x_holdable] at the voltage limit V_max [V]
    (``Statics.table``)."""
    return Statics(p, V_max).table(n)
