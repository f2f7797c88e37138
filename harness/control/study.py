"""The closed-loop study: the controller FMU (PI + feed-forward) and the MPC on the actuator FMU, on a clean
plant and on a plant with effects (a hidden one, or a diagnosed sample's own), with controllers built on the
paper's model or on the model the diagnosis extended (the paper's plus the effect's parameters), all of one sample
(``StudySettings.base``: the default sample or one of a parameter file). Setpoints beyond a plant's holdable range
at the voltage limit are clipped to it and reported (``plan_study``).

    res = run_study(StudySettings(actuator_fmu=..., controller_fmu=...))
    res.rows     # one dict per run: plant, model, controller, profile, metrics
    res.runs     # the traces (harness.control.closedloop.run_loop) by (plant, model, controller, profile)
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from fmu_src.specs import EFFECT_FIELDS, EFFECTS, Params, active_effects
from fmu_src.statics import Statics

from .closedloop import (ControlLoopError, EstimatedMpcLoop, FmuPid, LoopSettings, MpcLoop, Profile, metrics,
                         run_loop, staircase_to_pull_in, start_values, stroke_profile)
from .estimator import Ekf, EkfSettings, NoiseLevels
from .mpc import Mpc, MpcSettings
from .opmap import holdable_limit
from .tuning import tune_pi


class TargetClippedWarning(UserWarning):
    """Setpoints of the study beyond a plant's holdable range were clipped to it (one warning per study)."""


@dataclass(frozen=True)
class StudySettings:
    """What the study runs (SI): the FMUs, the sample's paper parameters ``base`` (the paper model; effects off)
    and where they come from (``sample``, for the report), the plant's effects: either the sample's own
    (``sample_effects``: {parameter name: value} of its parameter file, e.g. a diagnosis's extended_params.json)
    or the hidden effect ``effect`` (name in ``fmu_src.specs.EFFECTS``, or None) with its parameters
    ``effect_params`` (None: the virtual rig's magnitude 1); the extended model (``extended_params``: None = the
    plant's model, i.e. a perfect diagnosis; a dict = those effect parameters on ``base``; a ``Params`` = that
    whole model, e.g. a diagnosis's sample), the stroke, the PI's period pi_dt_s, the MPC's settings (voltage
    limit, margin).

    Parameters
    ----------
    actuator_fmu : str
        The actuator FMU, the plant.
    controller_fmu : str
        The PI controller FMU.
    base : Params
        The sample's paper parameters (effects off): the paper model.
    effect : str or None
        The plant's hidden effect (a name of ``fmu_src.specs.EFFECTS``; None: none).
    effect_params : dict or None
        Its parameters (None: the virtual rig's magnitude 1).
    extended_params : dict, Params or None
        The extended model: None, the plant's model; a dict, those effect parameters on ``base``; a Params, that
        whole model.
    stroke_m : float
        Stroke of the tracking task [m].
    freq_Hz : float
        Frequency of the tracking task's sine [Hz].
    pi_dt_s : float
        The PI controller's period [s].
    mpc : MpcSettings
        The MPC's settings (horizon, period, voltage limits, margin).
    sample_effects : dict or None
        The sample's own effect parameters (e.g. from extended_params.json), instead of ``effect``.
    sample : str
        Where ``base`` comes from, for the report.
    paper_model : Params or None
        The model the "paper" controllers are built on (None: ``base``).
    estimator : str
        The MPC's state: "none" (the plant's exact I, x, v) or "ekf" (an EKF on the MPC's model from the plant's x
        and I readings plus white noise at the rig's noise floors times ``noise_factor``).
    offset_free : bool
        With "ekf": the EKF's input disturbances, predicted by the MPC.
    noise_factor : float
        The readings' noise over the rig's noise floors.
    seed : int
        Seed of the readings' noise.
    """
    actuator_fmu: str
    controller_fmu: str
    base: Params = field(default_factory=Params)
    effect: str | None = "filler_saturation"
    effect_params: dict | None = None
    extended_params: dict | Params | None = None
    stroke_m: float = 1e-3
    freq_Hz: float = 2.0
    pi_dt_s: float = 1e-3
    mpc: MpcSettings = MpcSettings()
    sample_effects: dict | None = None
    sample: str = "the default sample (20 wt%, 45 mm)"
    #: the model the "paper" controllers are built on (None: ``base``, the plant's own paper parameters); e.g. the
    #: paper model a blind diagnosis refitted to the plant's data, so that neither controller sees true values
    paper_model: Params | None = None
    estimator: str = "none"
    offset_free: bool = False
    noise_factor: float = 1.0
    seed: int = 0

    def __post_init__(self):
        if self.estimator not in ("none", "ekf"):
            raise ControlLoopError(f"estimator must be 'none' or 'ekf', got {self.estimator!r}")
        if self.offset_free and self.estimator != "ekf":
            raise ControlLoopError("offset-free MPC needs the estimator (estimator='ekf'): its disturbances are "
                                   "estimated with the states")
        if not (isinstance(self.noise_factor, (int, float)) and 0 < self.noise_factor < float("inf")):
            raise ControlLoopError(f"noise_factor must be a positive finite number, got {self.noise_factor!r}")
        if self.sample_effects is not None:
            unknown = sorted(set(self.sample_effects) - set(EFFECT_FIELDS))
            if unknown:
                raise ControlLoopError(f"sample_effects: unknown effect parameters {unknown}")
            if not active_effects(self.base.with_(**self.sample_effects)):
                raise ControlLoopError("sample_effects: no effect is on (use sample_effects=None)")
            if self.effect is not None:
                raise ControlLoopError(f"the plant is {self.sample} with its own effects "
                                       f"({', '.join(self.plant_name.split('+'))}); a hidden effect "
                                       f"{self.effect!r} cannot be added (leave it out)")
        if self.effect is not None and self.effect not in EFFECTS:
            raise ControlLoopError(f"unknown effect {self.effect!r} (known: {', '.join(EFFECTS)})")
        if not 0 < self.stroke_m < self.base.r0:
            raise ControlLoopError(f"stroke [m] must be in (0, r0 = {self.base.r0}), got {self.stroke_m!r}")
        if not self.mpc.margin_m + self.stroke_m < self.base.r0:
            raise ControlLoopError(f"MPC margin_m {self.mpc.margin_m!r} plus stroke_m {self.stroke_m!r} [m] must be below "
                                   f"r0 = {self.base.r0!r} (the MPC keeps x <= r0 - margin_m)")

    @property
    def has_effect_plant(self) -> bool:
        """True if the study has a plant with effects (the sample's own or a hidden one)."""
        return self.sample_effects is not None or self.effect is not None

    @property
    def plant_name(self) -> str:
        """The effect plant's name: the hidden effect, or the sample's own effects joined by "+"."""
        if self.sample_effects is not None:
            return "+".join(active_effects(self.base.with_(**self.sample_effects)))
        return str(self.effect)

    @property
    def mpc_name(self) -> str:
        """The MPC's name in the rows: MPC (exact state), MPC+EKF, MPC+EKF offset-free."""
        if self.estimator == "none":
            return "MPC"
        return "MPC+EKF offset-free" if self.offset_free else "MPC+EKF"

    def mpc_controller(self, model: Params):
        """The loop's MPC controller on ``model``: ``MpcLoop`` or ``EstimatedMpcLoop`` (see the fields).

        Parameters
        ----------
        model : Params
            The model the MPC (and its EKF) predicts with.
        """
        mpc = Mpc(model, self.mpc)
        if self.estimator == "none":
            return MpcLoop(mpc)
        noise = NoiseLevels.from_rig().scaled(self.noise_factor)
        ekf = Ekf(model, noise, EkfSettings(dt_s=self.mpc.dt_s, offset_free=self.offset_free))
        return EstimatedMpcLoop(mpc, ekf, noise, self.seed)

    def plant_with_effect(self) -> Params:
        """The plant's parameters: ``base`` with the sample's own effects, or with the hidden ``effect``."""
        if self.sample_effects is not None:
            return self.base.with_(**self.sample_effects).validated()
        e = EFFECTS[self.effect]
        vals = self.effect_params if self.effect_params is not None else e.rig_magnitude_1(self.base)
        return self.base.with_(**vals).validated()

    def extended_model(self) -> Params:
        """The extended model the controllers may use: ``extended_params`` (None: the plant's own model)."""
        if self.extended_params is None:
            return self.plant_with_effect()
        if isinstance(self.extended_params, Params):
            return self.extended_params.validated()
        return self.base.with_(**self.extended_params).validated()


@dataclass
class StudyResult:
    """rows: one dict per run (plant, model, controller, profile, metrics, gains/solve times); runs: traces;
    gains: the PI gains by (model, profile); solve_s: the MPC's solve times [s] per control step after its
    first call; first_call_s: the first MPC call of the study [s] (numba compilation or cache loading: warm-up);
    clipped: one sentence per profile whose setpoints were clipped to a plant's holdable range; holdable:
    {plant name: (x_holdable [m], V there [V], what limits the range)} at the voltage limit."""
    rows: list
    runs: dict
    gains: dict
    solve_s: list
    x_pull_in_m: float
    V_pull_in_V: float
    first_call_s: float | None = None
    clipped: list = field(default_factory=list)
    holdable: dict = field(default_factory=dict)


def _profiles(s: StudySettings, x_pi: float) -> dict:
    return {"stroke": stroke_profile(s.stroke_m, s.freq_Hz), "staircase": staircase_to_pull_in(x_pi)}


def clip_profile(prof: Profile, x_max_m: float) -> Profile:
    """``prof`` with its setpoints clipped to [0, x_max_m] [m]."""
    if prof.kind == "trapezoid":
        return prof if prof.stroke_m <= x_max_m else replace(prof, stroke_m=x_max_m)
    return replace(prof, levels_m=tuple(min(v, x_max_m) for v in prof.levels_m))


def _operating_points(profile: Profile, x_max_m: float) -> list:
    """Operating points [m] of the PI tuning: the profile's setpoints, at most 95 % of the holdable range x_max_m
    of the model the PI is built on (the linearization at the range's end, a fold, has no stiffness left)."""
    ops = [0.1 * profile.stroke_m, profile.stroke_m] if profile.kind == "trapezoid" else list(profile.levels_m)
    return [min(x, 0.95 * x_max_m) for x in ops]


def _mm(x: float) -> str:
    return f"{1e3 * x:.3g} mm"


def _clip_note(plant_name: str, prof_name: str, prof: Profile, clipped: Profile, hold) -> str | None:
    if clipped == prof:
        return None
    x, V, limit = hold
    was = (_mm(prof.stroke_m) if prof.kind == "trapezoid" else
           ", ".join(_mm(a) for a, b in zip(prof.levels_m, clipped.levels_m) if a != b))
    return (f"{plant_name} plant, {prof_name}: setpoint {was} clipped to {_mm(x)}, the end of its holdable range "
            f"at V <= {V:.3g} V ({limit})")


@dataclass(frozen=True)
class StudyPlan:
    """What ``run_study`` runs: cases (plant name, plant, model name, model), the profiles per (plant name,
    profile name) after clipping, the unclipped profiles, the holdable ranges {plant or "<model> model": (x [m],
    V [V], limit)} at the voltage limit, and the clipping notes."""
    cases: list
    profiles: dict
    unclipped: dict
    ranges: dict
    clipped: list
    x_pull_in_m: float
    V_pull_in_V: float


def plan_study(s: StudySettings) -> StudyPlan:
    """The study's cases and setpoints: setpoints beyond a plant's holdable range at the voltage limit are clipped
    to it (one ``TargetClippedWarning`` for the study, and ``StudyPlan.clipped``)."""
    paper = s.base.validated()
    model = s.paper_model.validated() if s.paper_model is not None else paper
    x_pi, v_pi = holdable_limit(paper)
    profiles = _profiles(s, x_pi)
    cases = [("clean", paper, "paper", model)]
    if s.has_effect_plant:
        plant = s.plant_with_effect()
        cases += [(s.plant_name, plant, "paper", model), (s.plant_name, plant, "extended", s.extended_model())]
    V_max = s.mpc.V_max_V
    ranges = {}
    for plant_name, plant, model_name, model in cases:
        for name, p in ((plant_name, plant), (f"{model_name} model", model)):
            if name not in ranges:
                st = Statics(p, V_max)
                ranges[name] = (st.x_holdable, min(st.v_pull_in, V_max), st.limit)
    plans, clipped = {}, []
    for plant_name in dict.fromkeys(c[0] for c in cases):
        for prof_name, prof in profiles.items():
            c = clip_profile(prof, ranges[plant_name][0])
            plans[(plant_name, prof_name)] = c
            note = _clip_note(plant_name, prof_name, prof, c, ranges[plant_name])
            if note:
                clipped.append(note)
    if clipped:
        warnings.warn("; ".join(clipped), TargetClippedWarning, stacklevel=3)
    return StudyPlan(cases, plans, profiles, ranges, clipped, x_pi, v_pi)


def run_study(s: StudySettings, progress=None) -> StudyResult:
    """Run every case (see the module docstring); ``progress(text)`` is called before each run. Setpoints beyond
    a plant's holdable range at the voltage limit are clipped to it (``plan_study``)."""
    plan = plan_study(s)
    cases, plans, profiles, ranges, clipped = plan.cases, plan.profiles, plan.unclipped, plan.ranges, plan.clipped
    holdable = {c[0]: ranges[c[0]] for c in cases}
    V_max = s.mpc.V_max_V
    rows, runs, gains, solve_s = [], {}, {}, []
    first_call = None
    for plant_name, plant, model_name, model in cases:
        for prof_name in profiles:
            prof = plans[(plant_name, prof_name)]
            g = gains.get((model_name, prof_name)) or tune_pi(
                model, _operating_points(profiles[prof_name], ranges[f"{model_name} model"][0]), step_s=s.pi_dt_s,
                best_effort=True)
            gains[(model_name, prof_name)] = g
            for ctl_name in ("PI", s.mpc_name):
                if progress:
                    progress(f"{plant_name} plant, {model_name} model, {ctl_name}, {prof_name}")
                if ctl_name == "PI":
                    ctl = FmuPid(s.controller_fmu, {**start_values(model), **g.fmu_parameters(),
                                                    "V_min": s.mpc.V_min_V, "V_max": V_max})
                    loop = LoopSettings(dt_s=s.pi_dt_s)
                else:
                    ctl = s.mpc_controller(model)
                    every = int(round(s.mpc.dt_s / s.pi_dt_s))
                    loop = LoopSettings(dt_s=s.pi_dt_s, every=every, horizon_points=s.mpc.horizon + 1)
                run = run_loop(s.actuator_fmu, plant, ctl, prof, loop)
                if ctl_name != "PI":
                    times = list(ctl.solve_s)
                    if first_call is None and times:   # the study's first call: compilation / cache loading
                        first_call = times.pop(0)
                    solve_s += times
                runs[(plant_name, model_name, ctl_name, prof_name)] = run
                m = metrics(run)
                m["max_x_m"] = float(np.max(run["x_m"]))
                rows.append({"plant": plant_name, "model": model_name, "controller": ctl_name,
                             "profile": prof_name, **m})
    return StudyResult(rows, runs, gains, solve_s, plan.x_pull_in_m, plan.V_pull_in_V, first_call, clipped,
                       holdable)
