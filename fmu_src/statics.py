"""Steady states of the actuator: equilibria, the static inverse (voltage that holds a displacement) and
the pull-in (contact) limit, for the paper's model and every effect that is on.

Above ``model`` in the layers of ``fmu_src`` (it uses ``Dynamics.rhs``, the compiled right-hand side the
FMU integrates): no second copy of the equations. A steady state has v = 0 and every rate zero:

* the current: I' = 0, i.e. V = R(T)*I (the coil's right-hand side is affine in V);
* every effect state by the steady-state rule its ``fmu_src.specs.StateSpec`` declares: its rate zero
  (affine in it: solved from two evaluations; e.g. the winding temperature rise), equal to x (the creep
  branch relaxed, the laser reading) or to the magnetic force (the force reading). No effect is named here;
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

from .model import FREE, dynamics_class, state_names
from .specs import EFFECTS, Params

#: every effect state's spec by name (its steady-state rule)
_STATE_SPECS = {st.name: st for e in EFFECTS.values() for st in e.state_specs}
N_TABLE = 241   # points of the static-inverse table on [0, x_holdable]


class Statics:
    """Steady states of one parameter set (``Params``; not blocked)."""

    def __init__(self, p: Params):
        if p.blocked:
            raise ValueError("Statics: blocked mode has no displacement to hold")
        self.p = p
        self.dyn = dynamics_class(p)(p)
        self.names = state_names(self.dyn.on)
        self.n = len(self.names)
        self._x_pi = None

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
                if st.steady != rule or not (electrical or st.mechanical):
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
    def current_for(self, x: float) -> float:
        """Current [A] (>= 0) whose magnetic force holds the diaphragm at x [m] (0 <= x < r0);
        ``ValueError`` if no current can (filler saturation caps the force)."""
        if not 0.0 <= x < self.p.r0:
            raise ValueError(f"target displacement x = {x!r} m outside [0, r0 = {self.p.r0!r} m)")
        if x == 0.0:
            return 0.0
        hi = 1.0
        while self.acceleration(hi, x) <= 0.0:
            hi *= 2.0
            if hi > 1e4:
                raise ValueError(f"no current holds x = {x!r} m (the magnetic force saturates below the "
                                 "restoring force)")
        return brentq(lambda i: self.acceleration(i, x), 0.0, hi, xtol=1e-14, rtol=1e-13)

    def stiffness(self, x: float) -> float:
        """Net stiffness -m*d x''/dx [N/m] at the equilibrium x [m] at fixed current (> 0: stable)."""
        I = self.current_for(x)
        h = 1e-7 * max(self.p.r0, 1e-3)
        return -self.p.m * (self.acceleration(I, x + h) - self.acceleration(I, x - h)) / (2 * h)

    @property
    def x_pull_in(self) -> float:
        """Largest displacement [m] held by a stable open-loop equilibrium (the fold of the static curve);
        r0 if the equilibrium stays stable up to the coil face."""
        if self._x_pi is None:
            r0 = self.p.r0
            xs = np.linspace(0.0, r0, 401)[1:-1]
            k = [self.stiffness(x) for x in xs]
            bad = next((i for i, ki in enumerate(k) if ki <= 0.0), None)
            if bad is None:
                self._x_pi = r0
            elif bad == 0:
                self._x_pi = 0.0
            else:
                self._x_pi = brentq(self.stiffness, xs[bad - 1], xs[bad], xtol=1e-12)
        return self._x_pi

    @property
    def x_holdable(self) -> float:
        """Largest displacement [m] with a stable steady state: ``x_pull_in``, or less where the winding has no
        thermal steady state (coil_heating: the current that holds x would run away thermally)."""
        x = min(self.x_pull_in, self.p.r0 * (1 - 1e-9))
        if self._steady(x):
            return x
        lo, hi = 0.0, x
        while hi - lo > 1e-9 * self.p.r0:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self._steady(mid) else (lo, mid)
        return lo

    def _steady(self, x: float) -> bool:
        try:
            self.voltage_for(x)
            return True
        except ValueError:
            return False

    @property
    def v_pull_in(self) -> float:
        """Pull-in voltage [V]: above it no equilibrium is left (the diaphragm goes into contact); the voltage at
        ``x_holdable``."""
        x = self.x_holdable
        return self.voltage(self.current_for(x), x)

    def voltage_for(self, x: float) -> float:
        """Static inverse: the steady voltage [V] that holds the displacement x [m] (any equilibrium,
        stable only for x <= ``x_pull_in``)."""
        return self.voltage(self.current_for(x), x)

    def table(self, n: int = N_TABLE) -> tuple[np.ndarray, np.ndarray]:
        """(x [m], V [V]) of the static inverse on n points of [0, x_holdable] (V increasing in x)."""
        xs = np.linspace(0.0, self.x_holdable * (1 - 1e-9), n)
        return xs, np.array([self.voltage_for(x) for x in xs])

    def displacement_for(self, V: float) -> float:
        """Stable steady displacement [m] under the voltage V [V]; r0 (contact) above the pull-in voltage."""
        V = abs(float(V))
        if V >= self.v_pull_in:
            return self.p.r0
        if V == 0.0:
            return 0.0
        return brentq(lambda x: self.voltage_for(x) - V, 0.0, self.x_holdable * (1 - 1e-9), xtol=1e-13)


def feedforward_table(p: Params, n: int = N_TABLE) -> tuple[np.ndarray, np.ndarray]:
    """(x [m], V [V]) table of the static inverse of ``p`` on [0, x_holdable] (``Statics.table``)."""
    return Statics(p).table(n)
