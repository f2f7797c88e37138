"""The closed-loop study: the controller FMU (PI + feed-forward) and the MPC on the actuator FMU, on a clean
plant and on a plant with a hidden effect, with controllers built on the paper's model or on the model the
diagnosis extended (the paper's plus the effect's parameters).

    res = run_study(StudySettings(actuator_fmu=..., controller_fmu=...))
    res.rows     # one dict per run: plant, model, controller, profile, metrics
    res.runs     # the traces (harness.control.closedloop.run_loop) by (plant, model, controller, profile)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fmu_src.specs import EFFECTS, Params

from .closedloop import (ControlLoopError, FmuPid, LoopSettings, MpcLoop, Profile, metrics, run_loop,
                         staircase_to_pull_in, start_values, stroke_profile)
from .mpc import Mpc, MpcSettings
from .opmap import holdable_limit
from .tuning import tune_pi


@dataclass(frozen=True)
class StudySettings:
    """What the study runs (SI): the FMUs, the plant's base parameters, the hidden effect (name in
    ``fmu_src.specs.EFFECTS``, or None) and its parameters (None: the virtual rig's magnitude 1), the extended
    model's parameters for that effect (None: the plant's, i.e. a perfect diagnosis), the stroke, the PI's
    period pi_dt_s, the MPC's settings, the voltage limit."""
    actuator_fmu: str
    controller_fmu: str
    base: Params = field(default_factory=Params)
    effect: str | None = "filler_saturation"
    effect_params: dict | None = None
    extended_params: dict | None = None
    stroke_m: float = 1e-3
    freq_Hz: float = 2.0
    pi_dt_s: float = 1e-3
    mpc: MpcSettings = MpcSettings()

    def __post_init__(self):
        if self.effect is not None and self.effect not in EFFECTS:
            raise ControlLoopError(f"unknown effect {self.effect!r} (known: {', '.join(EFFECTS)})")
        if not 0 < self.stroke_m < self.base.r0:
            raise ControlLoopError(f"stroke [m] must be in (0, r0 = {self.base.r0}), got {self.stroke_m!r}")
        if not self.mpc.margin_m + self.stroke_m < self.base.r0:
            raise ControlLoopError(f"MPC margin_m {self.mpc.margin_m!r} plus stroke_m {self.stroke_m!r} [m] must be below "
                                   f"r0 = {self.base.r0!r} (the MPC keeps x <= r0 - margin_m)")

    def plant_with_effect(self) -> Params:
        e = EFFECTS[self.effect]
        vals = self.effect_params if self.effect_params is not None else e.rig_magnitude_1(self.base)
        return self.base.with_(**vals).validated()

    def extended_model(self) -> Params:
        if self.extended_params is None:
            return self.plant_with_effect()
        return self.base.with_(**self.extended_params).validated()


@dataclass
class StudyResult:
    """rows: one dict per run (plant, model, controller, profile, metrics, gains/solve times); runs: traces;
    gains: the PI gains by (model, profile); solve_s: the MPC's solve times [s] per control step."""
    rows: list
    runs: dict
    gains: dict
    solve_s: list
    x_pull_in_m: float
    V_pull_in_V: float


def _profiles(s: StudySettings, x_pi: float) -> dict:
    return {"stroke": stroke_profile(s.stroke_m, s.freq_Hz), "staircase": staircase_to_pull_in(x_pi)}


def _operating_points(profile: Profile) -> list:
    if profile.kind == "trapezoid":
        return [0.1 * profile.stroke_m, profile.stroke_m]
    return list(profile.levels_m)


def run_study(s: StudySettings, progress=None) -> StudyResult:
    """Run every case (see the module docstring); ``progress(text)`` is called before each run."""
    paper = s.base.validated()
    x_pi, v_pi = holdable_limit(paper)
    profiles = _profiles(s, x_pi)
    cases = [("clean", paper, "paper", paper)]
    if s.effect is not None:
        plant = s.plant_with_effect()
        cases += [(s.effect, plant, "paper", paper), (s.effect, plant, "extended", s.extended_model())]
    rows, runs, gains, solve_s = [], {}, {}, []
    V_max = s.mpc.V_max_V
    for plant_name, plant, model_name, model in cases:
        for prof_name, prof in profiles.items():
            g = gains.get((model_name, prof_name)) or tune_pi(model, _operating_points(prof), step_s=s.pi_dt_s)
            gains[(model_name, prof_name)] = g
            for ctl_name in ("PI", "MPC"):
                if progress:
                    progress(f"{plant_name} plant, {model_name} model, {ctl_name}, {prof_name}")
                if ctl_name == "PI":
                    ctl = FmuPid(s.controller_fmu, {**start_values(model), **g.fmu_parameters(),
                                                    "V_min": s.mpc.V_min_V, "V_max": V_max})
                    loop = LoopSettings(dt_s=s.pi_dt_s)
                else:
                    ctl = MpcLoop(Mpc(model, s.mpc))
                    every = int(round(s.mpc.dt_s / s.pi_dt_s))
                    loop = LoopSettings(dt_s=s.pi_dt_s, every=every, horizon_points=s.mpc.horizon + 1)
                run = run_loop(s.actuator_fmu, plant, ctl, prof, loop)
                if ctl_name == "MPC":
                    solve_s += ctl.solve_s
                runs[(plant_name, model_name, ctl_name, prof_name)] = run
                m = metrics(run)
                m["max_x_m"] = float(np.max(run["x_m"]))
                rows.append({"plant": plant_name, "model": model_name, "controller": ctl_name,
                             "profile": prof_name, **m})
    return StudyResult(rows, runs, gains, solve_s, x_pi, v_pi)
