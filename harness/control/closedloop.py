"""Closed-loop co-simulation: the actuator FMU (plant) in an fmpy master loop (``FMU2Slave``, explicit
communication steps) with the controller FMU (``mpc_controller.fmu``) or the MPC (``harness.control.mpc``).

The plant steps with the base step ``dt_s``; the controller acts every ``every`` base steps (its control
period) and holds its voltage in between (zero-order hold). Per control period the master reads the plant's
outputs (x_sensor as the measured displacement; I, v for the MPC's state feedback), gives the controller
the setpoint and the measurement, reads the voltage, sets it on the plant and steps both.

Profiles (``Profile``): the drug-pump stroke (a trapezoid, e.g. 2 Hz from 0 to 1 mm) and a setpoint staircase
toward pull-in. Metrics (``metrics``): tracking RMSE, overshoot, settling time, peak voltage, coil energy,
contact events, closest approach to the coil face. SI units.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fmu_src.specs import EFFECT_FIELDS, Params, param_names
from harness import scratch


class ControlLoopError(ValueError):
    """A closed-loop run cannot be set up (bad FMU, parameters, profile); the message names what."""


# ------------------------------------------------------------------------------------------ profiles
@dataclass(frozen=True)
class Profile:
    """A setpoint x_ref(t) [m]: ``kind`` "trapezoid" (stroke_m, freq_Hz, rise_frac: fraction of the period
    in each ramp, the rest split between the top and bottom holds) or "staircase" (levels_m held for
    hold_s each, starting at 0)."""
    kind: str
    stroke_m: float = 1e-3
    freq_Hz: float = 2.0
    rise_frac: float = 0.2
    levels_m: tuple = ()
    hold_s: float = 0.3

    def __post_init__(self):
        if self.kind not in ("trapezoid", "staircase"):
            raise ControlLoopError(f"profile kind must be 'trapezoid' or 'staircase', got {self.kind!r}")
        if self.kind == "trapezoid" and not (self.stroke_m > 0 and self.freq_Hz > 0 and 0 < self.rise_frac < 0.5):
            raise ControlLoopError("trapezoid: stroke_m > 0, freq_Hz > 0 and 0 < rise_frac < 0.5 required")
        if self.kind == "staircase" and (not self.levels_m or self.hold_s <= 0 or min(self.levels_m) < 0):
            raise ControlLoopError("staircase: levels_m (>= 0) and hold_s > 0 required")

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if self.kind == "trapezoid":
            T = 1.0 / self.freq_Hz
            ph = np.mod(t, T) / T
            r, top = self.rise_frac, 0.5 - self.rise_frac   # ramp up, top hold, ramp down, bottom hold
            up = np.clip(ph / r, 0, 1)
            down = np.clip((ph - r - top) / r, 0, 1)
            return self.stroke_m * np.where(ph < r + top, up, 1.0 - down)
        k = np.floor(t / self.hold_s).astype(int)
        levels = np.concatenate([[0.0], np.asarray(self.levels_m, dtype=float)])
        return levels[np.clip(k, 0, len(levels) - 1)]

    @property
    def duration_s(self) -> float:
        """A natural run length [s]: two periods, or every level held once (after the initial 0)."""
        return 2.0 / self.freq_Hz if self.kind == "trapezoid" else self.hold_s * (len(self.levels_m) + 1)


def stroke_profile(stroke_m: float = 1e-3, freq_Hz: float = 2.0) -> Profile:
    """Drug-pump stroke: trapezoid 0 -> stroke_m at freq_Hz."""
    return Profile("trapezoid", stroke_m=stroke_m, freq_Hz=freq_Hz)


def staircase_to_pull_in(x_pull_in_m: float, fractions=(0.25, 0.5, 0.7, 0.85, 0.95), hold_s: float = 0.3) -> Profile:
    """Setpoint staircase approaching the open-loop pull-in displacement x_pull_in_m [m]."""
    return Profile("staircase", levels_m=tuple(f * x_pull_in_m for f in fractions), hold_s=hold_s)


# ------------------------------------------------------------------------------------------ FMUs
def start_values(p: Params) -> dict:
    """FMU parameter values of p (names as in both FMUs' modelDescriptions; effects only when on)."""
    sv = {k: float(getattr(p, k)) for k in param_names()}
    sv.update({k: float(getattr(p, k)) for k in EFFECT_FIELDS if getattr(p, k) != 0.0})
    return sv


class FmuInstance:
    """One FMU instantiated with fmpy's low-level ``FMU2Slave`` (extracted into a temp dir, removed on close)."""

    def __init__(self, path, name: str, values: dict, t0: float = 0.0, t_end: float | None = None):
        import fmpy
        from fmpy.fmi2 import FMU2Slave
        path = Path(path)
        if not path.is_file():
            raise ControlLoopError(f"FMU not found: {path} (build it with `python build_fmu.py"
                                   f"{' --controller' if 'controller' in path.name else ''}`)")
        self.md = fmpy.read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        unknown = [k for k in values if k not in self.vr]
        if unknown:
            raise ControlLoopError(f"{path.name}: no variables {unknown}")
        self.dir = fmpy.extract(str(path), unzipdir=scratch.new_dir("fmu-"))    # removed however the run ends
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=t0, stopTime=t_end)
        self.fmu.enterInitializationMode()
        for k, v in values.items():
            if self.types[k] == "Boolean":
                self.fmu.setBoolean([self.vr[k]], [bool(v)])
            else:
                self.fmu.setReal([self.vr[k]], [float(v)])
        self.fmu.exitInitializationMode()

    def get(self, names) -> list:
        return self.fmu.getReal([self.vr[n] for n in names])

    def set(self, names, values) -> None:
        self.fmu.setReal([self.vr[n] for n in names], [float(v) for v in values])

    def close(self) -> None:
        try:
            self.fmu.terminate()
            self.fmu.freeInstance()
        finally:
            shutil.rmtree(self.dir, ignore_errors=True)


# ------------------------------------------------------------------------------------------ controllers
class FmuPid:
    """The controller FMU as the loop's controller (its gains and feed-forward model as FMU parameters)."""

    def __init__(self, path, values: dict):
        self.path, self.values = path, dict(values)
        self.inst = None

    def start(self, t0, t_end):
        self.inst = FmuInstance(self.path, "controller", self.values, t0, t_end)

    def command(self, t, x_ref_horizon, measured) -> float:
        self.inst.set(["x_ref", "x_meas"], [x_ref_horizon[0], measured[1]])
        return self.inst.get(["V"])[0]

    def applied(self, t, h, V):
        self.inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def close(self):
        if self.inst is not None:
            self.inst.close()


class MpcLoop:
    """The MPC (``harness.control.mpc.Mpc``) as the loop's controller; records its solve times [s]: wall clock
    (``solve_s``) and this thread's CPU time (``solve_cpu_s``: without the time other processes take the CPU)."""

    def __init__(self, mpc):
        self.mpc = mpc
        self.solve_s = []
        self.solve_cpu_s = []

    def start(self, t0, t_end):
        self.mpc.reset()
        self.mpc.model.reset(t0)

    def command(self, t, x_ref_horizon, measured) -> float:
        import time
        t1, c1 = time.perf_counter(), time.thread_time()
        V = self.mpc.command(t, x_ref_horizon[1:], measured)
        self.solve_s.append(time.perf_counter() - t1)
        self.solve_cpu_s.append(time.thread_time() - c1)
        return V

    def applied(self, t, h, V):
        self.mpc.applied(t + h, V)

    def close(self):
        pass


class EstimatedMpcLoop(MpcLoop):
    """The MPC on the estimate of an EKF (``harness.control.estimator.Ekf``, same control period) fed the plant's
    displacement reading x_sensor and current I plus white Gaussian noise of ``noise`` (``NoiseLevels``; None: the
    readings as they are, e.g. already noisy). The velocity the plant outputs is not used. With an offset-free
    EKF the MPC predicts with its disturbances. Records the solve times (estimator update + MPC + estimator
    prediction) and the estimates (``estimates``: (t [s], state vector) per control step)."""

    def __init__(self, mpc, ekf, noise=None, seed: int = 0):
        super().__init__(mpc)
        if abs(ekf.s.dt_s - mpc.s.dt_s) > 1e-12:
            raise ControlLoopError(f"the estimator's period {ekf.s.dt_s} s differs from the MPC's {mpc.s.dt_s} s")
        self.ekf, self.noise = ekf, noise
        self.rng = np.random.default_rng(seed)
        self.estimates = []

    def start(self, t0, t_end):
        super().start(t0, t_end)
        self.ekf.reset(None, t0)

    def command(self, t, x_ref_horizon, measured) -> float:
        import time
        I, x_s, _ = measured
        if self.noise is not None:
            x_s += self.rng.normal(0.0, self.noise.sigma_x_m)
            I += self.rng.normal(0.0, self.noise.sigma_I_A)
        t1, c1 = time.perf_counter(), time.thread_time()
        self.ekf.update([x_s, I])
        V = self.mpc.command(t, x_ref_horizon[1:], self.ekf.model_state, self.ekf.prediction)
        self._spent = (time.perf_counter() - t1, time.thread_time() - c1)
        self.estimates.append((t, self.ekf.x.copy()))
        return V

    def applied(self, t, h, V):
        import time
        t1, c1 = time.perf_counter(), time.thread_time()
        self.ekf.predict(V, h)   # the estimator's prediction belongs to the step (the plant's steps in between not)
        self.solve_s.append(self._spent[0] + time.perf_counter() - t1)
        self.solve_cpu_s.append(self._spent[1] + time.thread_time() - c1)


# ------------------------------------------------------------------------------------------ the loop
@dataclass(frozen=True)
class LoopSettings:
    """Base step dt_s [s] of the plant, controller period = every*dt_s, run length t_end_s [s] (None: the
    profile's), horizon_points (setpoints passed ahead: the MPC's horizon + 1), delay_steps: the controller reads
    the plant's outputs of that many base steps before (a measurement delay of delay_steps*dt_s)."""
    dt_s: float = 1e-3
    every: int = 1
    t_end_s: float | None = None
    horizon_points: int = 1
    delay_steps: int = 0

    def __post_init__(self):
        if not (isinstance(self.delay_steps, int) and self.delay_steps >= 0):
            raise ControlLoopError(f"LoopSettings.delay_steps must be an integer >= 0, got {self.delay_steps!r}")


def run_loop(plant_fmu, plant: Params, controller, profile: Profile, settings: LoopSettings = LoopSettings()) -> dict:
    """Closed loop of the actuator FMU (parameters ``plant``) and ``controller`` (``FmuPid`` or ``MpcLoop``)
    following ``profile``. Returns arrays t_s, x_ref_m, x_m, V_V, I_A, contact (per base step; x, I, contact at
    the step's start, V held over it) and r0_m."""
    dt, every = float(settings.dt_s), int(settings.every)
    t_end = settings.t_end_s or profile.duration_s
    n = int(round(t_end / dt))
    Tc = dt * every
    out = {k: np.empty(n) for k in ("t_s", "x_ref_m", "x_m", "V_V", "I_A", "contact")}
    plant_fmu_inst = FmuInstance(plant_fmu, "plant", start_values(plant), 0.0, n * dt)
    try:
        controller.start(0.0, n * dt)
        V = 0.0
        past = []   # the readings of the last delay_steps base steps (measurement delay)
        for k in range(n):
            t = k * dt
            x_s, x, I, v = plant_fmu_inst.get(["x_sensor", "x", "I", "v"])
            contact = plant_fmu_inst.fmu.getBoolean([plant_fmu_inst.vr["contact"]])[0]
            past.append((I, x_s, v))
            if len(past) > settings.delay_steps + 1:
                past.pop(0)
            if k % every == 0:
                refs = profile(t + Tc * np.arange(settings.horizon_points))
                V = controller.command(t, refs, past[0])
                plant_fmu_inst.set(["V"], [V])
            out["t_s"][k], out["x_ref_m"][k], out["x_m"][k] = t, float(profile(t)), x
            out["V_V"][k], out["I_A"][k], out["contact"][k] = V, I, float(contact)
            plant_fmu_inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            if (k + 1) % every == 0:
                controller.applied(t + dt - Tc, Tc, V)
    finally:
        plant_fmu_inst.close()
        controller.close()
    out["r0_m"] = plant.r0
    return out


def metrics(run: dict, band_m: float = 20e-6) -> dict:
    """Tracking metrics of a ``run_loop`` result.

    rmse_m: RMS of x - x_ref; over the first half of every hold of the setpoint after a rise (the second
    half may hold the MPC's anticipation of the next change): overshoot_m, the largest x - x_ref (0 if never
    above), and settling_s, the longest time from the end of the rise until x stays within band_m [m] of the
    setpoint (the half hold's length if it never does); peak_V; energy_J = sum(V*I*dt) (the coil's
    electrical energy); contact_events (rising edges of contact); min_gap_m = min(r0 - x)."""
    t, xr, x = run["t_s"], run["x_ref_m"], run["x_m"]
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    e = x - xr
    settle, over = [], [0.0]
    for k in np.nonzero(np.diff(xr) > 1e-12)[0] + 1:   # a rise ends at k: the hold after it
        j = k
        while j + 1 < len(t) and abs(xr[j + 1] - xr[k]) < 1e-12:
            j += 1
        if j == k:
            continue   # still rising (a ramp)
        seg = e[k:k + max((j + 1 - k) // 2, 1)]   # first half: the MPC's preview of the next change is later
        outside = np.nonzero(np.abs(seg) > band_m)[0]
        settle.append(0.0 if outside.size == 0 else (outside[-1] + 1) * dt)
        over.append(float(np.max(seg)))
    contact = run["contact"] > 0.5
    return {"rmse_m": float(np.sqrt(np.mean(e ** 2))), "overshoot_m": max(0.0, max(over)),
            "settling_s": max(settle) if settle else float("nan"), "peak_V": float(np.max(np.abs(run["V_V"]))),
            "energy_J": float(np.sum(run["V_V"] * run["I_A"]) * dt),
            "contact_events": int(np.sum(contact[1:] & ~contact[:-1]) + contact[0]),
            "min_gap_m": float(np.min(run["r0_m"] - x)),
            "max_abs_error_m": float(np.max(np.abs(e)))}


def hold_end_errors(run: dict, profile: Profile, preview_s: float = 0.0) -> np.ndarray:
    """x - x_ref [m] at the end of every hold of a staircase ``profile`` (the initial 0 included), ``preview_s`` [s]
    before the next setpoint (an MPC previews the next setpoint over its horizon and leaves the hold that long
    before it ends: give its horizon [s] to read the end of the hold it keeps)."""
    if profile.kind != "staircase":
        raise ControlLoopError("hold_end_errors: a staircase profile is needed")
    t = run["t_s"]
    dt = float(t[1] - t[0])
    out = []
    for j in range(len(profile.levels_m) + 1):
        k = int(round(((j + 1) * profile.hold_s - preview_s) / dt)) - 1
        if 0 <= k < t.size:
            out.append(run["x_m"][k] - run["x_ref_m"][k])
    return np.array(out)
