"""Results of the identification: per-sample result types and their JSON / CSV form.

:class:`SampleIdentification` (one sample: parameters, uncertainties, Pareto front, Eq. 6 choice),
:func:`identification_to_json` (``mpc-actuator-identification/1``, units in every key) and
:func:`write_identification` (``identification.json`` and ``pareto/<sample>.csv``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fmu_src.specs import SPEC_BY_NAME, Params
from harness.analysis.identification.objectives import OBJECTIVE_NAMES
from harness.data import paramsjson

__all__ = ["PARAM_KEYS", "PARAM_UNITS", "ParetoFront", "SampleIdentification", "sample_to_json",
           "identification_to_json", "write_identification"]

# The identified parameters (the paper's, without the per-test gap r0): JSON key with unit, unit.
PARAM_KEYS = {n: paramsjson.KEYS[n] for n in paramsjson.PAPER}
PARAM_UNITS = {n: SPEC_BY_NAME[n].unit for n in PARAM_KEYS}


# ============================================================================ results
@dataclass
class ParetoFront:
    """Non-dominated models: C [N.s/m], m [kg], objectives (n, 4) in OBJECTIVE_NAMES order."""
    C: np.ndarray
    m: np.ndarray
    objectives: np.ndarray

    def __len__(self):
        return int(self.C.size)


@dataclass
class SampleIdentification:
    """Identification result of one sample.

    ``params``: the identified model handed downstream (r0 is a per-test setting and left at its default,
    blocked False): C and m by ``choice`` ("least_squares" by default, or "paper": the Eq. 6 choice).
    ``values``: {name: (value, unit)}. ``uncertainty``: standard
    uncertainty of R, L, Em, K1, K2 from the measurement noise (same units).
    ``steady``: steady-state values used. ``pareto``: the whole front; ``chosen``: its
    index picked by Eq. 6; ``chosen_objectives``: {objective name: value} plus "J".
    ``timing_s``: wall times of the analytic part and of the optimization. ``settings``: the
    :class:`harness.analysis.identification.settings.IdentifySettings` used; ``evaluations``: candidates simulated.
    ``residual_check``: the chosen model's residual deviance against the front's least-squares model
    (:func:`harness.analysis.identification.identify.residual_check`). ``least_squares``: the profile-likelihood estimate of
    (C, m) with standard deviations and 95 % intervals (:meth:`harness.analysis.identification.cm_profile.CMProfile.to_json`;
    {"error": ...} if the residuals do not determine it). ``choice``: where the identified C, m came from
    ("least_squares" or "paper"); ``paper_choice``: the Eq. 6 model's C, m and its deviation from the
    least-squares estimate (sd and %); ``covariance_7``: joint covariance of R, L, Em, K1, K2, C, m
    ({"parameters": keys with units, "matrix": SI}, :mod:`harness.analysis.identification.cm_joint`); ``interval_95``:
    {key: [lo, hi]} normal 95 % intervals about the least-squares model (both None when it failed).
    ``analytic_notes``: what the analytic identification changed (e.g. a negative K1 within its noise set to
    0); ``settling_band``: {test: band [-]} of the records whose settling test needed a band wider than the
    settings' (the noise leaves the 2 % band undecidable: ``metrics.resolvable_band``). Both empty normally.
    """
    sample: str
    wt_pct: float
    diameter_mm: float
    params: Params
    values: dict
    uncertainty: dict
    steady: dict
    pareto: ParetoFront
    chosen: int
    chosen_objectives: dict
    J: np.ndarray
    weights: tuple
    bounds: dict
    timing_s: dict
    settings: Any = None
    evaluations: int = 0
    residual_check: dict | None = None
    least_squares: dict | None = None
    analytic_notes: tuple = ()
    settling_band: dict = field(default_factory=dict)
    choice: str = "paper"
    paper_choice: dict | None = None
    covariance_7: dict | None = None
    interval_95: dict | None = None


# ============================================================================ JSON
def _f(x):
    x = float(x)
    return x if math.isfinite(x) else None


def sample_to_json(r: SampleIdentification) -> dict:
    """One sample's result as JSON-ready dict; every quantity's key carries its unit."""
    params = paramsjson.params_to_json(r.params, effects=False)
    unc = {PARAM_KEYS[n] + "_std": _f(v) for n, v in r.uncertainty.items()}
    front = []
    for i in range(len(r.pareto)):
        row = {PARAM_KEYS["C"]: _f(r.pareto.C[i]), PARAM_KEYS["m"]: _f(r.pareto.m[i])}
        row.update({n: _f(v) for n, v in zip(OBJECTIVE_NAMES, r.pareto.objectives[i])})
        row["J"] = _f(r.J[i])
        front.append(row)
    steady = {k: (_f(v) if not isinstance(v, str) else v) for k, v in r.steady.items()}
    out = {
        "wt_pct": r.wt_pct, "diameter_mm": r.diameter_mm,
        "parameters": params,
        "parameter_std": unc,
        "steady_state": steady,
        "search_bounds": r.bounds,
        "weights": {n: w for n, w in zip(OBJECTIVE_NAMES, r.weights)},
        "chosen_index": int(r.chosen),
        "chosen_objectives": {k: _f(v) for k, v in r.chosen_objectives.items()},
        "pareto_front": front,
        "evaluations": int(r.evaluations),
        "timing": {k: _f(v) for k, v in r.timing_s.items()},
    }
    if r.residual_check is not None:
        out["residual_check"] = r.residual_check
    if r.least_squares is not None:
        out["least_squares"] = {k: (_f(v) if isinstance(v, float) else [_f(x) for x in v] if isinstance(v, list)
                                    else v) for k, v in r.least_squares.items()}
    out["identified_choice"] = r.choice
    if r.paper_choice is not None:
        out["paper_choice"] = {k: (_f(v) if isinstance(v, float) else v) for k, v in r.paper_choice.items()}
    if r.covariance_7 is not None:
        out["covariance_7"] = r.covariance_7
        out["interval_95"] = {k: [_f(a), _f(b)] for k, (a, b) in r.interval_95.items()}
    if r.analytic_notes:                 # only when the analytic part changed something
        out["analytic_notes"] = list(r.analytic_notes)
    if r.settling_band:                  # only records whose noise needed a band wider than the settings'
        out["settling_band_pct"] = {n: 100.0 * float(b) for n, b in r.settling_band.items()}
    return out


def identification_to_json(results, settings: Any = None, synthetic: bool | None = None,
                           wall_time_s: float | None = None, selection: dict | None = None,
                           conventions: dict | None = None) -> dict:
    """All results ({id: SampleIdentification} or a list) as one JSON-ready dict.

    settings: the :class:`harness.analysis.identification.settings.IdentifySettings` (default: the first result's).
    selection: {"unseen": [ids declared unseen], "skipped": {id: reason}} (samples skipped for
    incomplete data); written as "unseen_samples" and "skipped_samples". conventions: the rig
    conventions inferred from the data (``harness.analysis.identification.conventions.Conventions.as_dict``),
    written as "conventions".

    Layout: {"format", "synthetic", "settings", "objectives", "samples": {id: {...,
    "parameters": {"R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m",
    "C_N_s_per_m", "m_kg", "a_m", "D_m", "kB_T_per_A"}, "pareto_front": [...], ...}}}.
    """
    if isinstance(results, SampleIdentification):
        results = [results]
    if not isinstance(results, dict):
        results = {r.sample: r for r in results}
    if settings is None and results:
        settings = next(iter(results.values())).settings
    out = {
        "format": "mpc-actuator-identification/1",
        "synthetic": synthetic,
        "settings": settings.to_json() if settings is not None else None,
        "objectives": {"T3_ste_s": "|2 % settling time (sim) - (meas)| of T3 [s]",
                       "T3_rmse_mm": "RMSE of the T3 displacement [mm]",
                       "T5_ste_s": "|2 % settling time (sim) - (meas)| of T5 [s]",
                       "T5_rmse_mm": "RMSE of the T5 displacement [mm]",
                       "J": "Eq. 6: sum of weight * min-max normalized objective over the front [-]"},
        "samples": {sid: sample_to_json(r) for sid, r in results.items()},
    }
    if selection is not None:
        out["unseen_samples"] = list(selection.get("unseen", []))
        out["skipped_samples"] = dict(selection.get("skipped", {}))
    if wall_time_s is not None:
        out["wall_time_s"] = float(wall_time_s)
    if conventions is not None:
        out["conventions"] = conventions
    return out


def write_identification(results, out_dir, settings: Any = None, synthetic: bool | None = None,
                         wall_time_s: float | None = None, selection: dict | None = None,
                         conventions: dict | None = None) -> list[Path]:
    """Write ``identification.json`` and ``pareto/<sample>.csv`` (one row per front model) to out_dir."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = identification_to_json(results, settings, synthetic, wall_time_s, selection, conventions)
    p = out_dir / "identification.json"
    p.write_text(json.dumps(data, indent=2) + "\n")
    written = [p]
    pdir = out_dir / "pareto"
    pdir.mkdir(exist_ok=True)
    for sid, s in data["samples"].items():
        cols = [PARAM_KEYS["C"], PARAM_KEYS["m"], *OBJECTIVE_NAMES, "J"]
        lines = [",".join(cols + ["chosen"])]
        for i, row in enumerate(s["pareto_front"]):
            lines.append(",".join(f"{row[c]:.10g}" if row[c] is not None else "nan" for c in cols)
                         + f",{int(i == s['chosen_index'])}")
        q = pdir / f"{sid}.csv"
        q.write_text("\n".join(lines) + "\n")
        written.append(q)
    return written
