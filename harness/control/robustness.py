"""Robustness of the MPC on an estimator (issue 26): the offset-free MPC on an EKF fed noisy displacement and
current readings, on plants that differ from its model (the paper's), against the full-state MPC on a perfect
model (the plant's exact I, x, v; the plant's own parameters).

Cases (``robustness_cases``): the clean plant; each catalogue effect unmodelled (on in the plant at the virtual
rig's magnitude 1, not in the model); each of the parameters R, L, Em, K1, K2, C, m of the plant off by +-20 %;
measurement noise 1x, 2x, 5x the rig's noise floors; a measurement delay of 1 and 2 ms (the readings the
controller gets are that old). Profiles: the 2 Hz 0 -> 1 mm stroke and the staircase toward the paper model's
pull-in (clipped to the plant's holdable range at the voltage limit). Metrics per run: tracking RMSE, peak voltage,
contact events, closest approach to the coil, the worst error at the end of a staircase hold (the offset), and
the controller's time per control step (estimator + MPC: median
and 95th percentile, first step left out).

    rows = run_robustness("mpc_actuator.fmu")
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmu_src.specs import EFFECTS, Params
from fmu_src.statics import Statics

from .closedloop import (EstimatedMpcLoop, LoopSettings, MpcLoop, hold_end_errors, metrics, run_loop,
                         staircase_to_pull_in, stroke_profile)
from .estimator import Ekf, EkfSettings, NoiseLevels
from .mpc import Mpc, MpcSettings
from .opmap import holdable_limit
from .study import clip_profile

PARAMS_OFF = ("R", "L", "Em", "K1", "K2", "C", "m")


@dataclass(frozen=True)
class Case:
    """One plant/measurement case: name, the plant's parameters, the noise factor, the delay [base steps of 1 ms]."""
    name: str
    plant: Params
    noise_factor: float = 1.0
    delay_steps: int = 0


def robustness_cases(base: Params = Params(), effect_params=None) -> list:
    """The cases of the study on the model ``base`` (see the module docstring); ``effect_params``: {effect: its
    parameters} (None: the virtual rig's magnitude 1, ``EffectSpec.rig_magnitude_1``)."""
    cases = [Case("clean plant", base)]
    for name, e in EFFECTS.items():
        vals = (effect_params or {}).get(name) or e.rig_magnitude_1(base)
        cases.append(Case(f"unmodelled {name}", base.with_(**vals).validated()))
    for k in PARAMS_OFF:
        for f in (0.8, 1.2):
            cases.append(Case(f"{k} {'+' if f > 1 else '-'}20 %", base.with_(**{k: getattr(base, k) * f})))
    cases += [Case(f"noise {f:g}x", base, noise_factor=f) for f in (2.0, 5.0)]
    cases += [Case(f"delay {d} ms", base, delay_steps=d) for d in (1, 2)]
    return cases


def _row(case, profile_name, run, ctl, controller, prof, preview_s):
    m = metrics(run)
    s = np.asarray(ctl.solve_s[1:], dtype=float)
    c = np.asarray(ctl.solve_cpu_s[1:], dtype=float)
    hold = (float(np.max(np.abs(hold_end_errors(run, prof, preview_s)))) if prof.kind == "staircase"
            else float("nan"))
    return {"case": case, "controller": controller, "profile": profile_name, "rmse_m": m["rmse_m"],
            "hold_end_error_m": hold,
            "peak_V": m["peak_V"], "contact_events": m["contact_events"], "min_gap_m": m["min_gap_m"],
            "step_median_s": float(np.median(s)) if s.size else float("nan"),
            "step_p95_s": float(np.percentile(s, 95)) if s.size else float("nan"),
            "step_cpu_median_s": float(np.median(c)) if c.size else float("nan"),
            "step_cpu_p95_s": float(np.percentile(c, 95)) if c.size else float("nan")}


def run_robustness(actuator_fmu, base: Params = Params(), settings: MpcSettings = MpcSettings(), cases=None,
                   offset_free: bool = True, progress=None, seed: int = 0) -> list:
    """Rows (dicts: case, controller, profile, rmse_m, hold_end_error_m (staircase: the largest |x - x_ref| at the
    end of a hold, one MPC horizon before the next setpoint; NaN for the stroke), peak_V, contact_events, min_gap_m,
    step_median_s, step_p95_s (wall clock), step_cpu_median_s, step_cpu_p95_s (the controller thread's CPU time)) of the reference (full-state MPC, perfect model, clean plant) and of the MPC on the EKF (on the
    model ``base``; ``offset_free``) for every case."""
    cases = robustness_cases(base) if cases is None else cases
    x_pi = holdable_limit(base)[0]
    every = int(round(settings.dt_s / 1e-3))
    name = "MPC+EKF offset-free" if offset_free else "MPC+EKF"
    preview = settings.horizon * settings.dt_s
    rows = []

    def profiles(plant):
        stair = clip_profile(staircase_to_pull_in(x_pi), Statics(plant, settings.V_max_V).x_holdable)
        return {"stroke": stroke_profile(1e-3, 2.0), "staircase": stair}

    for prof_name, prof in profiles(base).items():
        if progress:
            progress(f"reference: full-state MPC, perfect model, {prof_name}")
        ctl = MpcLoop(Mpc(base, settings))
        run = run_loop(actuator_fmu, base, ctl, prof,
                       LoopSettings(dt_s=1e-3, every=every, horizon_points=settings.horizon + 1))
        rows.append(_row("perfect model, exact state", prof_name, run, ctl, "MPC", prof, preview))
    for case in cases:
        for prof_name, prof in profiles(case.plant).items():
            if progress:
                progress(f"{case.name}, {prof_name}")
            noise = NoiseLevels.from_rig().scaled(case.noise_factor)
            ekf = Ekf(base, noise, EkfSettings(dt_s=settings.dt_s, offset_free=offset_free))
            ctl = EstimatedMpcLoop(Mpc(base, settings), ekf, noise, seed)
            loop = LoopSettings(dt_s=1e-3, every=every, horizon_points=settings.horizon + 1,
                                delay_steps=case.delay_steps)
            run = run_loop(actuator_fmu, case.plant, ctl, prof, loop)
            rows.append(_row(case.name, prof_name, run, ctl, name, prof, preview))
    return rows


def markdown_table(rows) -> str:
    """The rows as a Markdown table (um, V, ms; the step times are the controller thread's CPU time: on a shared
    machine the wall clock adds other processes' time)."""
    out = ["| case | controller | profile | RMSE [um] | worst hold end [um] | peak V [V] | contacts | min gap [mm] "
           "| step CPU median [ms] | step CPU p95 [ms] |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        hold = "" if r["hold_end_error_m"] != r["hold_end_error_m"] else f"{1e6 * r['hold_end_error_m']:.1f}"
        out.append(f"| {r['case']} | {r['controller']} | {r['profile']} | {1e6 * r['rmse_m']:.1f} | {hold} | "
                   f"{r['peak_V']:.1f} | {r['contact_events']} | {1e3 * r['min_gap_m']:.2f} | "
                   f"{1e3 * r['step_cpu_median_s']:.2f} | {1e3 * r['step_cpu_p95_s']:.2f} |")
    return "\n".join(out)
