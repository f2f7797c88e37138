"""Nonlinear MPC for stroke tracking, predicting with the FMU's own compiled integrator.

Prediction: the model's state is loaded into the FMU's integrator (``fmu_src.model.ActuatorModel``: DP5 with
contact events, numba-compiled in ``fmu_src.integrator``) and a batch of candidate voltage sequences is
shot through ``fmu_src.integrator.advance`` in one compiled loop (``rollouts``): no second copy of the
equations, every effect of the model's parameters included.

Decision variables: the voltage on ``blocks`` (move blocking: block j holds for blocks[j] control periods;
horizon = sum(blocks) periods), inside [V_min, V_max] (box, by projection), optimized as w = V*|V| (the force
goes with the current squared: at V = 0 the displacement's gradient in V vanishes, in w it does not). Cost
over the horizon:

    sum_k ((x_k - x_ref,k)/x_scale)^2 + w_dv * sum_j ((V_j - V_{j-1})/V_scale)^2
          + w_gap * sum_k (max(0, x_k - (r0 - margin))/x_scale)^2

minimized by projected Levenberg-Marquardt (Jacobian by forward differences: blocks + 1 rollouts per batch),
started from the better of the previous solution shifted by one block and the static inverse of the
reference. The reference is clipped to r0 - margin; the no-contact margin is a penalty: the closed loop
checks it (``harness.control.closedloop``).

State: the measured I, x, v (state feedback: the plant FMU's outputs); the model's other states (winding
temperature, creep, sensor lag) are not measured and are run alongside in the MPC's own model (open-loop
observer) driven by the voltages applied. Or the whole state estimated (``harness.control.estimator.Ekf``:
``measured`` then has every state of the model), with the estimator's input disturbances (``disturbance``:
a voltage offset dV [V] added to every candidate voltage, and parameter-block overrides, e.g. the force gain and
saturation the estimator fitted, ``Ekf.prediction``): offset-free, the prediction is the disturbed model's, so the
steady state the MPC drives the estimate to is the measured one's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from fmu_src import integrator as J
from fmu_src.model import ActuatorModel
from fmu_src.specs import Params
from fmu_src.statics import Statics

# rollouts (compiled, cached) calls the integrator: its cache keyed to the physics' sources too (numba keys it to
# this file alone, and kept rollouts compiled against an older integrator, block layout included)
J.register_compiled_module(__name__, __file__)
W_VIEW = J.W_VIEW


@numba.njit(cache=True)
def rollouts(S0, W0, coef, t0, dt, Vseq, xout):
    """Shoot every row of Vseq (candidates x periods, V [V] held over each period dt [s]) from the integrator
    state (S0, W0) at t0 [s]; the displacement [m] at the end of each period into xout (NaN after a failed
    step). Returns the number of failed rollouts."""
    n_c, n_k = Vseq.shape
    S = np.empty_like(S0)
    W = np.empty_like(W0)
    failed = 0
    for c in range(n_c):
        S[:] = S0
        W[:, :] = W0
        for k in range(n_k):
            status = J.advance(S, W, coef, t0 + (k + 1) * dt, Vseq[c, k])
            if status != 0:
                failed += 1
                for kk in range(k, n_k):
                    xout[c, kk] = np.nan
                break
            xout[c, k] = W[W_VIEW, 1]
    return failed


def _w(V):
    """Decision variable w = V*|V| [V^2] of the voltage V [V]."""
    return np.asarray(V) * np.abs(V)


def _v(w):
    """Voltage [V] of the decision variable w [V^2]."""
    return np.sign(w) * np.sqrt(np.abs(w))


@dataclass(frozen=True)
class MpcSettings:
    """Settings of the MPC (SI): control period dt_s [s], move blocks (periods per decision variable),
    voltage limits V_min_V, V_max_V [V], no-contact margin_m [m] (x <= r0 - margin), weights, LM iterations,
    the prediction's relative tolerance rtol."""
    dt_s: float = 0.01
    blocks: tuple = (1, 1, 2, 4)
    V_min_V: float = 0.0
    V_max_V: float = 30.0
    margin_m: float = 0.5e-3
    w_dv: float = 1e-4
    w_gap: float = 1e3
    iterations: int = 3
    rtol: float = 1e-5

    def __post_init__(self):
        if not (self.dt_s > 0 and math.isfinite(self.dt_s)):
            raise ValueError(f"MpcSettings.dt_s [s] must be > 0, got {self.dt_s!r}")
        if not self.blocks or min(self.blocks) < 1:
            raise ValueError(f"MpcSettings.blocks must be positive period counts, got {self.blocks!r}")
        if not self.V_max_V > self.V_min_V:
            raise ValueError(f"MpcSettings: V_max_V {self.V_max_V!r} must be > V_min_V {self.V_min_V!r}")
        if not self.margin_m >= 0:
            raise ValueError(f"MpcSettings.margin_m [m] must be >= 0, got {self.margin_m!r}")

    @property
    def horizon(self) -> int:
        """Prediction horizon [control periods]."""
        return int(sum(self.blocks))


class Mpc:
    """Nonlinear MPC on the model p (``Params``; the paper's or an extended one). See the module docstring.

    ``command(t, x_ref_horizon, measured)`` returns the voltage for the coming period; ``applied(V)`` must
    follow with the voltage actually applied (advances the observer of the unmeasured states).
    """

    def __init__(self, p: Params, settings: MpcSettings = MpcSettings()):
        self.p = p
        self.s = settings
        self.model = ActuatorModel(p, rtol=settings.rtol)
        self.model.reset(0.0)
        st = Statics(p, settings.V_max_V)   # holdable range at the voltage limit (never raises for a model)
        self.x_max = p.r0 - settings.margin_m
        self.x_holdable = st.x_holdable
        xs, vs = st.table(121)
        self._ff = (xs, vs)
        self._expand = np.repeat(np.arange(len(settings.blocks)), settings.blocks)
        self.z = None
        self.x_scale = max(p.r0, 1e-3) * 0.1
        self.V_scale = max(settings.V_max_V - settings.V_min_V, 1.0)
        self.last_predicted = None

    def reset(self) -> None:
        self.model.reset(0.0)
        self.z = None

    def feedforward(self, x_ref) -> np.ndarray:
        """Static-inverse voltage [V] for the references x_ref [m] (clipped to the holdable range at V_max_V)."""
        xs, vs = self._ff
        return np.interp(np.clip(x_ref, 0.0, xs[-1]), xs, vs)

    def _load_state(self, t: float, measured) -> None:
        """Put the measured I [A], x [m], v [m/s] into the prediction model (other states: the observer's), or the
        whole state when ``measured`` has every state of the model."""
        y = list(self.model.integ.y)
        m = [float(v) for v in measured]
        if len(m) not in (3, len(y)):
            raise ValueError(f"Mpc: measured must be (I, x, v) or the model's whole state ({len(y)} entries)")
        y[:len(m)] = m
        y[1] = min(y[1], self.p.r0)
        if y[1] >= self.p.r0:
            y[2] = 0.0
        self.model.integ.reset(t, y)

    def _cost(self, X, Z, ref) -> np.ndarray:
        """Residual vectors (rows: candidates) of X (predicted x), Z (block voltages)."""
        s = self.s
        track = (X - ref) / self.x_scale
        gap = np.sqrt(s.w_gap) * np.maximum(X - self.x_max, 0.0) / self.x_scale
        prev = self._prev_V
        dv = np.diff(np.concatenate([np.full((Z.shape[0], 1), prev), Z], axis=1), axis=1)
        move = np.sqrt(s.w_dv) * dv / self.V_scale
        r = np.concatenate([track, gap, move], axis=1)
        return np.where(np.isfinite(r), r, 1e6)

    def command(self, t: float, x_ref, measured, disturbance=(0.0, ())) -> float:
        """Voltage [V] for the period starting at t [s].

        Parameters
        ----------
        t : float
            Time [s].
        x_ref : array
            Reference displacement [m] at the ends of the next ``horizon`` periods.
        measured : sequence
            Measured (I [A], x [m], v [m/s]), or the model's whole estimated state.
        disturbance : (float, sequence of (int, float))
            The estimator's input disturbances (``Ekf.prediction``): voltage offset dV [V] and (index, value)
            overrides of the prediction's parameter block (``fmu_src.integrator``; see the module docstring).
        """
        s = self.s
        ref = np.minimum(np.asarray(x_ref, dtype=float)[: s.horizon], self.x_max)
        if ref.size < s.horizon:
            ref = np.concatenate([ref, np.full(s.horizon - ref.size, ref[-1] if ref.size else 0.0)])
        self._load_state(t, measured)
        integ = self.model.integ
        S0, W0, coef = integ.S.copy(), integ.W.copy(), integ.coef
        dV, overrides = float(disturbance[0]), disturbance[1]
        for i, v in overrides:
            S0[int(i)] = float(v)
        nb = len(s.blocks)
        ends = np.cumsum(s.blocks) - 1
        ff = np.clip(self.feedforward(ref[ends]) - dV, s.V_min_V, s.V_max_V)
        if self.z is None:
            self._prev_V = float(ff[0])
            starts = ff[None, :]
        else:   # previous solution shifted by one block, and the feed-forward
            starts = np.stack([np.concatenate([self.z[1:], self.z[-1:]]), ff])
        wlo, whi = _w(s.V_min_V), _w(s.V_max_V)
        mu = 1e-3
        h = 1e-3 * max(abs(wlo), abs(whi))
        X = np.empty((nb + 1, s.horizon))
        best_r, best_w, w = None, None, None
        for it in range(s.iterations + 1):
            if it == 0:
                W = _w(starts)
            else:
                W = np.repeat(w[None, :], nb + 1, axis=0)
                for j in range(nb):   # forward differences, stepping inward from the upper limit
                    W[j + 1, j] += h if w[j] + h <= whi else -h
            Z = _v(W)
            Xb = X[: len(W)]
            rollouts(S0, W0, coef, t, s.dt_s, np.ascontiguousarray(Z[:, self._expand] + dV), Xb)
            R = self._cost(Xb, Z, ref)
            if it == 0:
                i0 = int(np.argmin(np.einsum("ij,ij->i", R, R)))
                best_r, best_w, self.last_predicted = R[i0], W[i0].copy(), Xb[i0].copy()
                w = best_w.copy()
                continue
            r0 = R[0]
            if r0 @ r0 > best_r @ best_r:   # the last step made it worse: back, more damping
                w, mu = best_w.copy(), mu * 10.0
                continue
            best_r, best_w, self.last_predicted = r0, w.copy(), Xb[0].copy()
            if it == s.iterations:
                break
            Jac = ((R[1:] - r0) / (W[1:, :].diagonal() - w)[:, None]).T
            H = Jac.T @ Jac
            step = np.linalg.solve(H + mu * (np.trace(H) / nb + 1e-30) * np.eye(nb), Jac.T @ r0)
            w = np.clip(w - step, wlo, whi)
            mu = max(mu / 3.0, 1e-6)
        self.z = _v(best_w)
        return float(self.z[0])

    def applied(self, t_end: float, V: float) -> None:
        """The voltage V [V] was applied until t_end [s]: advance the observer of the unmeasured states."""
        self.model.advance(float(t_end), float(V))
        self._prev_V = float(V)
