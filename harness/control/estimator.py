"""State estimation on the FMU's own compiled model: a discrete extended Kalman filter (EKF) from the measured
displacement and current (and force, where the rig measures it).

No second copy of the equations: the prediction of one sample period is the FMU's compiled integrator
(``fmu_src.integrator.advance``, DP5 with contact events) started from the estimate, and its Jacobian F is
the forward difference of that same step map (one more integration per state, all in one compiled call,
``step_columns``); the measurement function is the FMU's compiled output function (``fmu_src.integrator.outputs``:
the sensor readings x_sensor, F_sensor, and I), its Jacobian H by forward differences too. The state is the
model's whole state y = [I, x, v, effect states] (winding temperature rise, creep dashpot position, sensor
readings: whatever the model in use carries, ``fmu_src.model.state_names``), so velocity and every unmeasured
state are estimated.

Offset-free (``EkfSettings.offset_free``): three input disturbances are appended to the state, random walks the
filter estimates with the rest: an additive voltage offset ``dV`` [V] (the model is driven by V + dV: a wrong
resistance, a heating coil, a supply offset), a force gain ``force_gain`` [-] multiplying the coupling factor Em
and a saturation offset ``dksat`` [1/T^2] added to the model's ksat (the model's force is
g*Em*I^2*G/(1 + (ksat + dksat)*(kB*I)^2), the filler_saturation term switched on in the filter's own parameter
block: a wrong Em or gap, a saturating filler; a force gain alone fits a saturating plant at one current but
overstates dF/dI by 1/(1 + ksat*B^2) and the loop rings near pull-in). The disturbances' Kalman gain has full
column rank 2 for the two measured outputs (x, I), so at a steady state of the filter its innovations vanish, and
a controller that brings the model's x to the setpoint brings the measured x there too
(``harness.control.mpc.Mpc.command`` predicts with the same disturbances: ``Ekf.prediction``).

Noise: the measurement noise standard deviations are the dataset's noise floors (``NoiseLevels.from_rig``: the
manifest's sensor models, ``harness.data.protocol.noise_floor``, or an estimate from the data,
``harness.data.protocol.estimate_noise_floor``); the process noise is a white-noise density per state
(``EkfSettings``: a voltage noise driving the current, a force noise driving the velocity, a rate noise per
effect state, relative to its scale). SI units.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from fmu_src import integrator as J
from fmu_src.model import ActuatorModel
from fmu_src.specs import BLOCK, Params

J.register_compiled_module(__name__, __file__)

P_EM, P_KSAT, SW_SAT = BLOCK.param["Em"], BLOCK.param["ksat"], BLOCK.switch["filler_saturation"]
DIST_NAMES = ("dV", "force_gain", "dksat")
KSAT_MIN = -0.5   # [1/T^2] smallest ksat + dksat (a force growing at most 2x faster than I^2 at 1 T)
#: units of the state names (columns of the estimate's CSV)
STATE_UNITS = {"I": "A", "x": "m", "v": "m/s", "dT": "K", "xc": "m", "x_sensor": "m", "F_sensor": "N",
               "dV": "V", "force_gain": "1", "dksat": "1/T2"}


FD_REL_STEP = 1e-4
#: typical magnitude of a state per unit, for the process noise, the initial covariance and the difference steps
_UNIT_SCALE = {"K": 10.0, "N": 1.0}


def state_scales(p: Params, names) -> np.ndarray:
    """Typical magnitudes of the model's states ``names``: 1 A, r0 [m], 10*r0 per second [m/s], r0 for every
    displacement-like effect state, 10 K for a temperature rise, 1 N for a force reading."""
    from fmu_src.specs import EFFECTS
    units = {st.name: st.unit for e in EFFECTS.values() for st in e.state_specs}
    r0 = max(p.r0, 1e-3)
    base = {"I": 1.0, "x": r0, "v": 10.0 * r0}
    return np.array([base[n] if n in base else (r0 if units[n] == "m" else _UNIT_SCALE[units[n]]) for n in names])


class EstimatorError(ValueError):
    """The estimator cannot be set up or run (bad noise levels, measurements, settings); the message names what."""


@numba.njit(cache=True)
def _reset(S, W, t, y, mode):
    """Put the integrator (S, W) at time t [s] in the state y and mode (the bookkeeping of
    ``fmu_src.model.Integrator.reset``, compiled)."""
    n = int(S[J.P_N])
    for i in range(J.NP, J.NS):
        S[i] = 0.0
    S[J.S_T] = t
    S[J.S_TF] = t
    S[J.S_MODE] = mode
    S[J.S_VMODE] = mode
    S[J.S_V] = np.nan
    S[J.S_CHANGED] = 1.0
    S[J.S_H] = 1e-4
    for i in range(n):
        W[J.W_Y, i] = y[i]
        W[J.W_VIEW, i] = y[i]


@numba.njit(cache=True)
def _mode_of(S, y):
    """The mode of the state y: blocked for a blocked model (its integrator was reset to BLOCKED), contact at the
    coil face, else free."""
    if S[J.S_MODE] == J.BLOCKED:
        return J.BLOCKED
    return J.CONTACT if y[1] >= S[J.P_R0] else J.FREE


@numba.njit(cache=True)
def step_columns(S0, W0, coef, span, V, Y, over, out):
    """Advance every column of Y (states x columns) over [t0, t0 + dt] [s] (span = (t0, dt)) with the voltage V[c]
    [V] held and the parameter-block entries over[0] (indices) set to over[1][:, c]; the end states into out (same
    shape). Returns the number of failed integrations (their columns NaN)."""
    t0, dt = span[0], span[1]
    idx, vals = over
    blocked = S0[J.S_MODE] == J.BLOCKED
    n, n_c = Y.shape
    S = S0.copy()
    W = W0.copy()
    y = np.empty(n)
    failed = 0
    for c in range(n_c):
        for i in range(n):
            y[i] = Y[i, c]
        if not blocked and y[1] > S[J.P_R0]:
            y[1] = S[J.P_R0]
        if not blocked and y[1] >= S[J.P_R0]:
            y[2] = 0.0
        for j in range(idx.size):
            S[idx[j]] = vals[j, c]
        _reset(S, W, t0, y, J.BLOCKED if blocked else _mode_of(S0, y))
        status = J.advance(S, W, coef, t0 + dt, V[c])
        for i in range(n):
            out[i, c] = W[J.W_VIEW, i] if status == 0 else np.nan
        if status != 0:
            failed += 1
    return failed


@numba.njit(cache=True)
def measure_columns(S0, coef, Y, over, rows, out):
    """Sensor readings of every column of Y (states x columns): out[j, c] = output rows[j] of
    ``fmu_src.integrator.outputs`` (0: I, 6: x_sensor, 7: F_sensor) with the parameter-block entries over[0] set to
    over[1][:, c]."""
    idx, vals = over
    S = S0.copy()
    o = np.empty(8)
    for c in range(Y.shape[1]):
        y = Y[:, c].copy()
        for j in range(idx.size):
            S[idx[j]] = vals[j, c]
        J.outputs(S, coef, y, _mode_of(S0, y), o)
        for j in range(rows.size):
            out[j, c] = o[rows[j]]


@dataclass(frozen=True)
class NoiseLevels:
    """Measurement noise standard deviations (SI): displacement sigma_x_m [m], current sigma_I_A [A], force
    sigma_F_N [N] (None: the force is not measured)."""
    sigma_x_m: float
    sigma_I_A: float
    sigma_F_N: float | None = None

    def __post_init__(self):
        for name in ("sigma_x_m", "sigma_I_A", "sigma_F_N"):
            v = getattr(self, name)
            if v is None and name == "sigma_F_N":
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise EstimatorError(f"noise level {name} must be a positive finite number, got {v!r}")

    @classmethod
    def from_rig(cls, rig=None, data=None, force: bool = False) -> "NoiseLevels":
        """The noise floors of a dataset: its manifest's sensor models (``rig``: the manifest's rig entry or a
        dataset; ``harness.data.protocol.noise_floor``), else estimated from its records (``data``,
        ``harness.data.protocol.estimate_noise_floor``), else the virtual rig's sensors (``harness.data.rig``).
        Displacement converted from mm to m."""
        from harness.data.protocol import estimate_noise_floor, noise_floor
        from harness.data.rig import SENSORS

        def level(col):
            v = noise_floor(rig, col) if rig is not None else None
            if v is None and data is not None:
                try:
                    v = estimate_noise_floor(data, col)
                except ValueError:
                    v = None
            return SENSORS[col].noise_floor if v is None else v
        return cls(level("displacement_mm") * 1e-3, level("current_A"), level("force_N") if force else None)

    def scaled(self, factor: float) -> "NoiseLevels":
        """Every level times factor."""
        return NoiseLevels(self.sigma_x_m * factor, self.sigma_I_A * factor,
                           None if self.sigma_F_N is None else self.sigma_F_N * factor)


@dataclass(frozen=True)
class EkfSettings:
    """Sample period dt_s [s]; process-noise densities: q_V [V^2/s] (voltage noise driving the current),
    q_F [N^2/s] (force noise driving the velocity), q_x_rel [1/s] (every other state: (q_x_rel*scale)^2 per
    second, scale its integrator scale); offset_free: append the disturbances dV [V], force_gain [-] and dksat
    [1/T^2] with random-walk densities q_dV [V^2/s], q_gain [1/s], q_ksat [1/(T^4.s)]; the integrator's rtol; the
    initial standard deviations of the disturbances."""
    dt_s: float = 0.01
    q_V: float = 1e-3
    q_F: float = 1e-8
    q_x_rel: float = 1e-3
    offset_free: bool = False
    q_dV: float = 0.1
    q_gain: float = 1e-3
    q_ksat: float = 0.1
    sigma0_dV_V: float = 1.0
    sigma0_gain: float = 0.2
    sigma0_ksat: float = 1.0
    rtol: float = 1e-8

    def __post_init__(self):
        for name in ("dt_s", "q_V", "q_F", "q_x_rel", "q_dV", "q_gain", "q_ksat", "sigma0_dV_V", "sigma0_gain",
                     "sigma0_ksat", "rtol"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise EstimatorError(f"EkfSettings.{name} must be a positive finite number, got {v!r}")


class Ekf:
    """Extended Kalman filter on the model p (``Params``: the paper's or an extended one). See the module docstring.

    ``update(z)`` with the readings z = (x_sensor [m], I [A]) (plus F_sensor [N] when noise.sigma_F_N is set),
    then ``predict(V)`` over one sample period with the voltage V [V] held. ``x``: the estimate (``names``),
    ``P``: its covariance. ``model_state`` / ``prediction``: its model part and what the MPC predicts with
    (voltage offset [V], parameter-block overrides).
    """

    def __init__(self, p: Params, noise: NoiseLevels, settings: EkfSettings = EkfSettings(), y0=None):
        self.p = p.validated()
        self.noise, self.s = noise, settings
        self.model = ActuatorModel(self.p, rtol=settings.rtol)
        self.model.reset(0.0)
        dyn = self.model.dyn
        self.n_y = dyn.n_states
        self.names = tuple(dyn.state_names) + (DIST_NAMES if settings.offset_free else ())
        self.n = len(self.names)
        self.scales = state_scales(self.p, dyn.state_names)
        self.blocked = bool(self.p.blocked)
        self._idx = np.array([P_EM, P_KSAT], dtype=np.int64) if settings.offset_free else np.zeros(0, np.int64)
        if settings.offset_free:   # the saturation term on in the filter's own parameter block (ksat + dksat)
            self.model.integ.S[SW_SAT] = 1.0
        self._rows = np.array([6, 0] + ([7] if noise.sigma_F_N is not None else []), dtype=np.int64)
        sig = [noise.sigma_x_m, noise.sigma_I_A] + ([noise.sigma_F_N] if noise.sigma_F_N is not None else [])
        self.R = np.diag(np.square(sig))
        self.Qc = self._process_noise()
        self.t = 0.0
        self.reset(y0)

    def _process_noise(self) -> np.ndarray:
        """Continuous white-noise densities (diagonal) per state."""
        s, p = self.s, self.p
        q = (s.q_x_rel * self.scales) ** 2
        q = np.concatenate([q, [s.q_dV, s.q_gain, s.q_ksat]]) if s.offset_free else q
        q[0] = s.q_V / p.L ** 2
        q[1] = (s.q_x_rel * self.scales[1]) ** 2
        q[2] = s.q_F / p.m ** 2
        return np.diag(q)

    def reset(self, y0=None, t0: float = 0.0) -> None:
        """Start at t0 [s] from y0 (model state; None: at rest, zero current) with an initial covariance of a few
        noise levels on I and x, the velocity's scale and each effect state's."""
        y = np.zeros(self.n_y) if y0 is None else np.asarray(y0, dtype=float)
        if y.shape != (self.n_y,):
            raise EstimatorError(f"initial state must have {self.n_y} entries {self.names[:self.n_y]}")
        self.x = np.concatenate([y, [0.0, 1.0, 0.0]]) if self.s.offset_free else y.copy()
        sd = np.concatenate([[3 * self.noise.sigma_I_A, 3 * self.noise.sigma_x_m], 1e-2 * self.scales[2:]])
        if self.s.offset_free:
            sd = np.concatenate([sd, [self.s.sigma0_dV_V, self.s.sigma0_gain, self.s.sigma0_ksat]])
        self.P = np.diag(sd ** 2)
        self.t = float(t0)

    # -- the model's maps ---------------------------------------------------------------------------
    def _overrides(self, D):
        """Parameter-block values (rows: Em [N.m/T^2], ksat [1/T^2]) of the disturbances D (rows: dV, force_gain,
        dksat; columns)."""
        return np.vstack([self.p.Em * D[1], np.maximum(self.p.ksat + D[2], KSAT_MIN)])

    def _split(self, X):
        """Model states, voltage offsets and parameter-block overrides of the columns of X (n x columns)."""
        if not self.s.offset_free:
            return np.ascontiguousarray(X), np.zeros(X.shape[1]), np.zeros((0, X.shape[1]))
        D = X[self.n_y:]
        return np.ascontiguousarray(X[:self.n_y]), np.ascontiguousarray(D[0]), np.ascontiguousarray(self._overrides(D))

    def _step(self, X, V: float, dt: float) -> np.ndarray:
        Y, dV, vals = self._split(X)
        out = np.empty_like(Y)
        integ = self.model.integ
        bad = step_columns(integ.S, integ.W, integ.coef, np.array([self.t, dt]), V + dV, Y, (self._idx, vals), out)
        if bad:
            raise EstimatorError(f"the model's integration failed from the estimate at t = {self.t:.6g} s")
        return np.vstack([out, X[self.n_y:]]) if self.s.offset_free else out

    def _measure(self, X) -> np.ndarray:
        Y, _, vals = self._split(X)
        out = np.empty((self._rows.size, X.shape[1]))
        measure_columns(self.model.integ.S, self.model.integ.coef, Y, (self._idx, vals), self._rows, out)
        return out

    def _steps(self) -> np.ndarray:
        """Forward-difference steps per state: 1e-4 of its scale (far above the integrator's tolerance, far below
        where the model bends)."""
        sc = np.concatenate([self.scales, [1.0, 1.0, 1.0]]) if self.s.offset_free else self.scales
        return FD_REL_STEP * sc

    # -- the filter ---------------------------------------------------------------------------------
    def predict(self, V: float, dt: float | None = None) -> None:
        """Propagate the estimate and its covariance over dt [s] (the sample period) with V [V] held."""
        dt = self.s.dt_s if dt is None else float(dt)
        h = self._steps()
        X = np.repeat(self.x[:, None], self.n + 1, axis=1)
        X[np.arange(self.n), np.arange(1, self.n + 1)] += h
        Xn = self._step(X, float(V), dt)
        F = (Xn[:, 1:] - Xn[:, :1]) / h[None, :]
        self.x = Xn[:, 0]
        Qd = self.Qc * dt   # white noise over the period (first order)
        self.P = F @ self.P @ F.T + Qd
        self.P = 0.5 * (self.P + self.P.T)
        self.t += dt

    def update(self, z) -> np.ndarray:
        """Correct the estimate with the readings z (x_sensor [m], I [A][, F_sensor [N]]); returns the
        innovation."""
        z = np.asarray(z, dtype=float)
        if z.shape != (self._rows.size,) or not np.all(np.isfinite(z)):
            raise EstimatorError(f"measurement must be {self._rows.size} finite readings (x_sensor [m], I [A]"
                                 f"{', F_sensor [N]' if self._rows.size == 3 else ''}), got {z!r}")
        h = self._steps()
        X = np.repeat(self.x[:, None], self.n + 1, axis=1)
        X[np.arange(self.n), np.arange(1, self.n + 1)] += h
        Z = self._measure(X)
        H = (Z[:, 1:] - Z[:, :1]) / h[None, :]
        e = z - Z[:, 0]
        Sinn = H @ self.P @ H.T + self.R
        K = np.linalg.solve(Sinn, H @ self.P).T
        self.x = self.x + K @ e
        IKH = np.eye(self.n) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ self.R @ K.T   # Joseph form: stays symmetric positive
        if not self.blocked and self.x[1] > self.p.r0:
            self.x[1] = self.p.r0
        return e

    @property
    def model_state(self) -> np.ndarray:
        """The estimated model state y [I, x, v, effect states]."""
        return self.x[:self.n_y].copy()

    @property
    def disturbance(self) -> np.ndarray:
        """(dV [V], force gain [-], dksat [1/T^2]) of the offset-free filter; (0, 1, 0) without disturbances."""
        return self.x[self.n_y:].copy() if self.s.offset_free else np.array([0.0, 1.0, 0.0])

    @property
    def prediction(self) -> tuple:
        """What a predictor of the disturbed model uses: (voltage offset dV [V], ((parameter-block index, value),
        ...)): Em*force_gain, ksat + dksat and the saturation switch on; (0, ()) without disturbances."""
        if not self.s.offset_free:
            return 0.0, ()
        d = self.disturbance
        em, ksat = self._overrides(d[:, None])[:, 0]
        return float(d[0]), ((P_EM, float(em)), (P_KSAT, float(ksat)), (SW_SAT, 1.0))

    def std(self) -> np.ndarray:
        """Standard deviations of the estimate (units of ``names``)."""
        return np.sqrt(np.maximum(np.diag(self.P), 0.0))


def nees(err, P) -> float:
    """Normalized estimation error squared e^T P^-1 e of the error e with the filter's covariance P."""
    err = np.asarray(err, dtype=float)
    return float(err @ np.linalg.solve(P, err))


def filter_record(p: Params, t, V, z, noise: NoiseLevels, settings: EkfSettings | None = None, y0=None) -> dict:
    """Run the EKF over a record: times t [s] (uniform), the voltage V [V] held from each sample to the next, the
    readings z (rows: samples; columns x_sensor [m], I [A][, F_sensor [N]]). Returns {"t_s", "names", "x" (samples
    x states: estimate after each sample's update), "std" (same shape)}."""
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    z = np.asarray(z, dtype=float)
    if t.ndim != 1 or t.size < 2 or V.shape != t.shape or z.shape[0] != t.size:
        raise EstimatorError("filter_record: t, V and the readings must have one row per sample (>= 2 samples)")
    dts = np.diff(t)
    dt = float(np.median(dts))
    if not (dt > 0 and np.all(np.abs(dts - dt) <= 1e-6 * dt + 1e-12)):
        raise EstimatorError("filter_record: the time column must be uniform and increasing")
    s = settings or EkfSettings(dt_s=dt)
    ekf = Ekf(p, noise, s, y0)
    ekf.reset(y0, float(t[0]))
    xs = np.empty((t.size, ekf.n))
    sd = np.empty((t.size, ekf.n))
    for k in range(t.size):
        ekf.update(z[k])
        xs[k], sd[k] = ekf.x, ekf.std()
        if k + 1 < t.size:
            ekf.predict(V[k], dt)
    return {"t_s": t, "names": ekf.names, "x": xs, "std": sd}
