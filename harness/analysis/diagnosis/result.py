"""The diagnosis result: :class:`Diagnosis`, its gain blocks and metric records, and its JSON documents.

diagnosis.json (:func:`diagnosis_to_json`) and extended_params.json (:func:`extended_params_json`): layouts
in the package docstring (``harness.analysis.diagnosis``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from fmu_src.specs import EFFECT_SPEC_BY_NAME, EFFECTS
from harness.analysis.core import metrics
from harness.data.paramsjson import params_to_json, unit_key

from harness.analysis.discovery import default_library, discovered_term, term_json

from .candidates import shared_defs
from .decision import Comparison, Selection
from .evidence import pointing_to
from .fitting import ModelFit
from .heldout import RULE as HELDOUT_RULE
from .prepare import PreparedDataset
from .settings import DiagnoseSettings

FORMAT = "mpc-actuator-diagnosis/1"
_CHANNEL = {"y": "reading", "I": "current"}
ROLE_SHARED, ROLE_HELDOUT = "shared fit", "held-out sample"


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`harness.analysis.diagnosis.diagnose` (see :func:`diagnosis_to_json` for the JSON layout).

    ``traces``: {sample id: {"before" | "after": {test: Trace}}} (figures); ``records_before``/``records_after``:
    per-sample, per-test metric records (``harness.report.tables`` layout) of the paper and the final model.
    """
    cause: str
    causes: list
    candidates: dict
    rounds: list
    effect_parameters: dict
    gain: dict
    evidence: dict
    decision: dict
    synthetic: bool
    samples: list                       # [{"id", "wt_pct", "diameter_mm", "role"}]
    extended_params: dict               # sample id -> Params (final model)
    baseline_params: dict               # sample id -> Params (paper identification)
    refit_params: dict                  # sample id -> Params (paper model, least squares on the fit tests)
    effects: tuple
    timing_s: dict
    traces: dict = field(default_factory=dict, repr=False)
    records_before: list = field(default_factory=list, repr=False)
    records_after: list = field(default_factory=list, repr=False)
    settings: DiagnoseSettings | None = None
    conventions: dict = field(default_factory=dict)   # rig conventions inferred from the data (prepare)
    verdict: str = ""                   # the whole answer (``decision.verdict``): e.g. "A + unexplained remainder"
    remainder: dict = field(default_factory=dict)   # where structure beyond the noise is left (JSON block)
    fits_cut_short: list = field(default_factory=list)   # fits stopped on a limit, not at a minimum (fits_cut_short)
    discovered: list = field(default_factory=list)    # discovered terms (``discovery.result.DiscoveredTerm``)
    discovery: dict = field(default_factory=dict)     # the discovery stage (JSON block; empty when it did not run)


@dataclass(frozen=True, eq=False)
class Outcome:
    """Everything :func:`assemble` turns into a :class:`Diagnosis`.

    ``paper``/``refit``: the paper identification and the paper model refitted (both with held-out
    chi-square); ``selection``: the decision (its ``final`` model is the extended one); ``uncertainty``
    {shared key: std, natural units}; ``traces`` {"paper" | "refit" | "final": {sample index: {test: Trace}}};
    ``features`` the evidence features; ``notes`` {sample index: [str]} of the paper identification;
    ``timing`` {step: s} and the start time ``t0`` (``time.perf_counter``).
    """
    prepared: PreparedDataset
    settings: DiagnoseSettings
    shared_idx: tuple
    paper: ModelFit
    refit: ModelFit
    selection: Selection
    uncertainty: dict
    traces: dict
    features: dict
    notes: dict
    timing: dict
    t0: float


def finite_or_none(x):
    """float(x) when finite, else None (JSON has no NaN)."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


_f = finite_or_none


def _rmse_parts(sd, traces: dict, names) -> dict:
    """{test: {"y": RMSE [mm or N], "I": RMSE [A], "y_norm": RMSE / sensor floor, "I_norm": ...}}."""
    out = {}
    for name in names:
        if name not in traces:
            continue
        tr = traces[name]
        test = sd.tests[name]
        ry = float(np.sqrt(np.mean((tr.y_meas - tr.y_sim) ** 2)))
        rI = float(np.sqrt(np.mean((tr.I_meas - tr.I_sim) ** 2)))
        fy = test.floor_y if tr.kind == "sweep" else test.sig_y
        fI = test.floor_I if tr.kind == "sweep" else test.sig_I
        scale = 1.0 if tr.blocked else 1e3
        out[name] = {"y": ry * scale, "I": rI, "y_norm": ry / fy, "I_norm": rI / fI,
                     "y_unit": "N" if tr.blocked else "mm"}
    return out


def gain_block(samples, traces_by_model: dict, names, idx) -> dict:
    """RMSE per test (pooled over the samples ``idx``) for each model {model: {sample index: {test: Trace}}},
    and the overall normalized RMSE (RMS over samples, tests and signals of RMSE / noise floor)."""
    out = {"per_test": {}, "overall_normalized_rmse": {}}
    norms = {m: [] for m in traces_by_model}
    for name in names:
        entry = {}
        have = False
        for m, tr in traces_by_model.items():
            vals = [_rmse_parts(samples[i], tr[i], [name]).get(name) for i in idx]
            vals = [v for v in vals if v]
            if not vals:
                continue
            have = True
            unit = vals[0]["y_unit"]
            sig = "blocked_force" if unit == "N" else "displacement"
            ky, kI = f"{sig}_rmse_{unit}", "current_rmse_A"
            entry.setdefault(ky, {})[m] = math.sqrt(float(np.mean([v["y"] ** 2 for v in vals])))
            entry.setdefault(kI, {})[m] = math.sqrt(float(np.mean([v["I"] ** 2 for v in vals])))
            entry.setdefault(f"{sig}_rmse_per_noise_floor", {})[m] = math.sqrt(
                float(np.mean([v["y_norm"] ** 2 for v in vals])))
            entry.setdefault("current_rmse_per_noise_floor", {})[m] = math.sqrt(
                float(np.mean([v["I_norm"] ** 2 for v in vals])))
            norms[m] += [v["y_norm"] ** 2 for v in vals] + [v["I_norm"] ** 2 for v in vals]
        if have:
            out["per_test"][name] = entry
    for m, v in norms.items():
        out["overall_normalized_rmse"][m] = math.sqrt(float(np.mean(v))) if v else None
    b, a = out["overall_normalized_rmse"].get("before"), out["overall_normalized_rmse"].get("after")
    out["overall_normalized_rmse"]["after_over_before"] = (a / b) if a is not None and b else None
    return out


def _rmse(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _record(sd, name: str, tr) -> dict:
    test = sd.tests[name]
    rec = {"sample": sd.sid, "wt_pct": sd.wt_pct, "diameter_mm": sd.diameter_mm, "test": name}
    unit = "N" if tr.blocked else "mm"
    scale = 1.0 if tr.blocked else 1e3
    ym, ys = tr.y_meas * scale, tr.y_sim * scale
    if tr.kind == "sweep":
        rec[f"rmse_{unit}"] = _rmse(ym, ys)
    elif test.frequency_hz:
        try:
            rec.update(metrics.sine_metrics(test.t, ym, ys, float(test.frequency_hz), unit=unit))
        except ValueError:
            rec[f"rmse_{unit}"] = _rmse(ym, ys)
    else:
        try:
            rec.update(metrics.step_metrics(test.t, ym, ys, t_step=test.t_step_s,
                                            noise_sigma=test.sig_y * scale, unit=unit))
        except ValueError:
            rec[f"rmse_{unit}"] = _rmse(ym, ys)
    rec["current_rmse_A"] = _rmse(tr.I_meas, tr.I_sim)
    return rec


def records(samples, traces: dict) -> list:
    """Per-sample, per-test metric records (harness.report.tables layout) from full traces."""
    return [_record(sd, name, tr) for i, sd in enumerate(samples) for name, tr in sorted(traces[i].items())]


def _signal_name(sd, test: str, ch: str) -> str:
    t = sd.tests.get(test)
    if ch == "I":
        return "current"
    return "blocked force" if getattr(t, "blocked", False) else "displacement"


def comparison_json(c: Comparison, sd0) -> dict:
    """A candidate's JSON entry (``sd0``: a prepared sample, to name the signals)."""
    return {"effects": list(c.effects), "extra_parameters": c.k, "delta_chi2_fit": _f(c.d_fit),
            "delta_bic": _f(c.d_bic), "delta_chi2_heldout": _f(c.d_heldout), "score": _f(c.score),
            "accepted": bool(c.accepted), "reason": c.reason,
            "shared_parameters": {unit_key(d.key, d.unit): _f(c.shared.get(d.key)) for d in shared_defs(c.effects)},
            "shows_in": [{"test": t, "signal": _signal_name(sd0, t, ch), "delta_chi2": _f(v)}
                         for t, ch, v in c.shows_in[:6]],
            "fits_cut_short": list(c.cut_short)}


def _effect_parameters(o: Outcome) -> dict:
    """Shared effect parameters with uncertainty; per-sample FMU effect parameters."""
    final = o.selection.final
    eff = {}
    for d in shared_defs(final.effects):
        eff[unit_key(d.key, d.unit)] = {"value": _f(d.natural(final.shared[d.key])),
                                        "std": _f(o.uncertainty.get(d.key)),
                                        "effect": d.effect, "description": d.description}
    per_sample = {}
    terms = [e for e in final.effects if e not in EFFECTS]
    lib = default_library() if terms else None
    for i, sd in enumerate(o.prepared.samples):
        p = final.params[i]
        per_sample[sd.sid] = {unit_key(k, EFFECT_SPEC_BY_NAME[k].unit): float(getattr(p, k))
                              for e in final.effects if e in EFFECTS for k in EFFECTS[e].params}
        for e in terms:
            if lib.is_term(e):
                spec = lib.spec(e)
                per_sample[sd.sid][unit_key(spec.coef.name, spec.coef.unit)] = float(getattr(p, spec.coef.name))
                if spec.lag:
                    per_sample[sd.sid][unit_key(f"tau_{spec.lag}", "s")] = float(getattr(p, f"tau_{spec.lag}"))
    if eff:
        eff["per_sample"] = per_sample
    return eff


def _roles(o: Outcome) -> dict:
    S = set(o.shared_idx)
    return {i: (ROLE_SHARED if i in S else ROLE_HELDOUT) for i in range(len(o.prepared.samples))}


def _tests_present(samples, names) -> list:
    return [nm for nm in names if any(nm in sd.tests for sd in samples)]


def _gain(o: Outcome) -> dict:
    samples, st, n = o.prepared.samples, o.settings, len(o.prepared.samples)
    roles = _roles(o)
    tb = {"before": o.traces["paper"], "refit": o.traces["refit"], "after": o.traces["final"]}
    if "catalogue" in o.traces:       # discovery added terms: the catalogue stage's model, before them
        tb = {"before": tb["before"], "refit": tb["refit"], "catalogue": o.traces["catalogue"], "after": tb["after"]}
    held, fitn = _tests_present(samples, st.heldout_tests), _tests_present(samples, st.fit_tests)
    final = o.selection.final
    gain = gain_block(samples, tb, held, list(range(n)))
    gain["heldout_tests"] = held
    gain["models"] = {"before": "paper model, identified as in the paper (analytic R, L, Em, K1, K2 from T3, T5, "
                                "T8; C, m by least squares on T3/T5)",
                      "refit": "paper model re-fitted by least squares on the fit tests",
                      "after": "extended model " + ("+".join(final.effects) if final.effects else
                                                    "(no effect selected: the refitted paper model)")}
    hs = [i for i in range(n) if roles[i] == ROLE_HELDOUT]
    if hs:
        gain["heldout_samples"] = dict(gain_block(samples, tb, held + fitn, hs),
                                       samples=[samples[i].sid for i in hs])
    du = [i for i in range(n) if samples[i].unseen]
    if du:
        gain["declared_unseen_samples"] = dict(gain_block(samples, tb, held + fitn, du),
                                               samples=[samples[i].sid for i in du])
    gain["fit_tests"] = gain_block(samples, tb, fitn, list(range(n)))
    gain["noise_floors"] = o.prepared.floors.as_dict()
    gain["per_sample"] = {samples[i].sid: dict(role=roles[i],
                                               **gain_block(samples, tb, held, [i])["overall_normalized_rmse"])
                          for i in range(n)}
    return gain


def _evidence(o: Outcome) -> dict:
    zb = {f"{t}_{_CHANNEL[ch]}": _f(v) for (t, ch), v in sorted(o.refit.structure().items())}
    zf = {f"{t}_{_CHANNEL[ch]}": _f(v) for (t, ch), v in sorted(o.selection.final.structure().items())}
    remaining = [k for k, v in zf.items() if v is not None and v > o.settings.z_struct]
    sids = [sd.sid for sd in o.prepared.samples]
    return {"features": o.features, "baseline_structure_z": zb, "final_structure_z": zf,
            "remaining_structure": remaining,
            "uncertainty_allowance": {f"{t}_{_CHANNEL[ch]}": {"mean_chi2": _f(mu), "sd_chi2": _f(math.sqrt(var))}
                                      for (t, ch), (mu, var) in sorted(o.refit.allowance.items())},
            "uncertainty_allowance_note": (
                "computed only when a test of the refitted paper model shows structure: the chi-square the fitted "
                "parameters' own uncertainty (linearized, from the fit tests) adds to each held-out test, and the "
                "step instants' own uncertainty (estimated from each test's current) to each step test, held-out or "
                "fit (the part the fitted parameters cannot take up); z subtracts its mean and adds its variance, so "
                "what the data cannot pin down is not taken for structure the model misses"),
            "structure_note": "z = (chi2 - n)/sqrt(2 n) of the refitted model's residuals per test and signal, "
                              "summed over samples (about N(0,1) for pure noise)",
            "baseline_notes": {sid: o.notes[i] for i, sid in enumerate(sids) if o.notes[i]}}


def _decision(o: Outcome) -> dict:
    st, samples = o.settings, o.prepared.samples
    roles = _roles(o)
    return {
        "rule": ("Each candidate is fitted (shared effect parameters + every sample's base parameters) on the fit "
                 "tests and accepted when its BIC on the fit data is lower than the refitted paper model's by more "
                 f"than {st.bic_min:g} AND its chi-square on the held-out tests (never fitted) is lower by more than "
                 f"{st.heldout_min:g}; the accepted candidate with the largest score = held-out chi-square "
                 "decrease - BIC change is taken, then each remaining candidate is added to it in turn (greedy "
                 "forward selection) while the selected model's residuals still show structure "
                 f"(z > {st.z_struct:g}). No candidate accepted: 'none' if the refitted paper model's residuals "
                 f"are noise (every z <= {st.z_struct:g}), else 'unexplained'. Causes accepted but the extended "
                 f"model still shows structure (some z > {st.z_struct:g}): the verdict is the causes + 'unexplained "
                 "remainder' (harness.analysis.diagnosis.decision.verdict)."),
        "thresholds": {"bic_min": st.bic_min, "heldout_chi2_min": st.heldout_min, "structure_z": st.z_struct,
                       "max_effects": st.max_effects},
        "fit_tests": _tests_present(samples, st.fit_tests), "heldout_tests": _tests_present(samples, st.heldout_tests),
        "shared_fit_samples": [samples[i].sid for i in sorted(set(o.shared_idx))],
        "heldout_samples": [samples[i].sid for i in range(len(samples)) if roles[i] == ROLE_HELDOUT],
        "heldout_sample_choice": {
            "declared_unseen": ([sd.sid for sd in samples if sd.unseen] if st.unseen is not None else None),
            "source": "declared by the user (--unseen) and the rule" if st.unseen else "the rule (none declared)",
            "rule": HELDOUT_RULE, "max_shared_samples": st.max_shared_samples,
            "min_samples_holdout": st.min_samples_holdout},
        "n_fit_residuals": o.refit.n("fit"),
        "noise_model": ("time series: white noise at the sensor noise floor; sweep readings (T1/T7, means over "
                        f"the last averaging window of each hold): floor/sqrt(n) but at least {st.sweep_sigma_floor:g} "
                        f"x floor, residuals passed through c*asinh(z/c), c = {st.sweep_robust_c:g} (a pull-in "
                        "mismatch at one gap must not outweigh everything else)"),
        "rounds": [{"reference": list(r.reference),
                    "candidates": {c.name: comparison_json(c, samples[0]) for c in r.comparisons}}
                   for r in o.selection.rounds],
    }


def _per_sample_structure(mf: ModelFit, keys, samples) -> dict:
    """{sample id: {"<test>_<signal>": z}} of the (test, channel) ``keys`` for each sample (fit + held-out)."""
    out = {}
    for i, sd in enumerate(samples):
        row = {}
        for d in (mf.fit_chi2, mf.heldout or {}):
            for k, (c, m) in d.get(i, {}).items():
                if k in keys and m > 0:
                    row[f"{k[0]}_{_CHANNEL[k[1]]}"] = _f((c - m) / math.sqrt(2.0 * m))
        out[sd.sid] = row
    return out


def _sample_drop(ref: ModelFit, mf: ModelFit, samples) -> dict:
    """{sample id: chi-square decrease (fit + held-out tests) from ``ref`` to ``mf``}."""
    out = {}
    for i, sd in enumerate(samples):
        a = sum(c for d in (ref.fit_chi2, ref.heldout or {}) for c, _ in d.get(i, {}).values())
        b = sum(c for d in (mf.fit_chi2, mf.heldout or {}) for c, _ in d.get(i, {}).values())
        out[sd.sid] = a - b
    return out


def _discovery(o: Outcome) -> tuple:
    """([DiscoveredTerm], the discovery's JSON block) of the outcome (([], {}) when it did not run)."""
    sel = o.selection
    path = sel.discovery
    if path is None:
        return [], {}
    samples = o.prepared.samples
    lib = default_library()
    sids = [sd.sid for sd in samples]
    params = {sids[i]: sel.final.params[i] for i in range(len(samples))}
    terms, ref = [], sel.catalogue_final
    fits = {c.name: f for r in path.rounds for c, f in zip(r.comparisons, r.fits)}
    for c in path.chosen:
        mf = fits.get(c.name, sel.final)
        terms.append(discovered_term(lib, c.name, c, params, o.uncertainty, _sample_drop(ref, mf, samples)))
        ref = mf
    block = {"ran_because": sel.catalogue_verdict.reason if sel.catalogue_verdict else "",
             "catalogue_verdict": sel.catalogue_verdict.label if sel.catalogue_verdict else "",
             "stop": path.stop, "max_terms": o.settings.max_terms, "library": list(lib.names),
             "rule": "each candidate term (fmu_src.terms.TERMS) is added to the catalogue stage's model, fitted on "
                     "whole trajectories as the catalogue candidates are, and accepted by the same rule (BIC on the "
                     "fit tests AND held-out chi-square); greedy forward selection while structure is left",
             "rounds": [{"reference": list(r.reference),
                         "candidates": {c.name: comparison_json(c, samples[0]) for c in r.comparisons}}
                        for r in path.rounds]}
    return terms, block


def _remainder(o: Outcome) -> dict:
    """The unexplained remainder (``verdict.remainder``) with its evidence: where, how large, which samples."""
    v = o.selection.verdict
    mf = o.selection.final if (v.causes or v.terms) else o.refit
    keys = {(t, ch) for t, ch, _ in v.remainder}
    return {"present": bool(v.remainder), "of_model": "extended" if (v.causes or v.terms) else "paper_refit",
            "reason": v.reason, "structure_z_threshold": o.settings.z_struct,
            # candidates the fit budget left undecided (decision.budget_bound): supported by the fit data, cut
            "undecided_within_budget": [{"candidate": n, "iterations": k} for n, k in v.undecided],
            "where": [{"test": t, "signal": _signal_name(o.prepared.samples[0], t, ch), "z": _f(z)}
                      for t, ch, z in v.remainder],
            "per_sample_z": _per_sample_structure(mf, keys, o.prepared.samples) if keys else {},
            "note": "z = (chi2 - n)/sqrt(2 n) per test and signal (about N(0,1) for noise; z also allows for "
                    "evidence.uncertainty_allowance when one was computed); per_sample_z: the same for each sample "
                    "alone, to show which samples carry the remainder"}


def fits_cut_short(o: Outcome) -> list:
    """Every fit of the diagnosis that stopped on its iteration limit or its time budget rather than at a minimum
    (``DiagnoseSettings.max_iter``, ``fit_budget_s``): [{"model", "fit", "stop", "iterations", "why"}]. Its model's
    numbers are then those of the last iterate: the report says so instead of running on."""
    why = {"max_iter": "the Levenberg-Marquardt iteration limit (max_iter) was reached before the cost stopped "
                       "falling",
           "time_budget": "the diagnosis's fit time budget (fit_budget_s, CPU seconds) ran out: its simulations are slow "
                          "(stiff parameter points need many sub-steps, long or fast records) or the fits "
                          "converge slowly"}
    models = [("paper model (refit)", o.refit.cut_short)]
    rounds = list(o.selection.rounds) + (list(o.selection.discovery.rounds) if o.selection.discovery else [])
    models += [("+".join(c.effects), c.cut_short) for r in rounds for c in r.comparisons]
    return [dict(model=name, why=why[c["stop"]], **c) for name, cs in models for c in cs]


def assemble(o: Outcome) -> Diagnosis:
    """The :class:`Diagnosis` of an :class:`Outcome` (JSON-ready blocks, parameters, traces, records)."""
    samples = o.prepared.samples
    n = len(samples)
    sel = o.selection
    roles = _roles(o)
    candidates = {c.name: comparison_json(c, samples[0]) for c in sel.first_round}
    causes = []
    for r, c in enumerate(sel.chosen, 1):
        cj = comparison_json(c, samples[0])
        causes.append({"name": c.name, "rank": r, "score": cj["score"], "delta_bic": cj["delta_bic"],
                       "delta_chi2_heldout": cj["delta_chi2_heldout"], "reason": c.reason,
                       "shows_in": cj["shows_in"], "evidence_features": pointing_to(o.features, c.name)})
    eff, gain, evidence, decision = _effect_parameters(o), _gain(o), _evidence(o), _decision(o)
    discovered, discovery = _discovery(o)
    sids = [sd.sid for sd in samples]
    o.timing["total"] = round(time.perf_counter() - o.t0, 3)
    diag = Diagnosis(
        cause=sel.cause, causes=causes, candidates=candidates, rounds=list(sel.rounds), effect_parameters=eff,
        gain=gain, evidence=evidence, decision=decision, synthetic=o.prepared.synthetic,
        samples=[{"id": sd.sid, "wt_pct": sd.wt_pct, "diameter_mm": sd.diameter_mm, "role": roles[i],
                  "declared_unseen": bool(sd.unseen)} for i, sd in enumerate(samples)],
        extended_params={sids[i]: sel.final.params[i] for i in range(n)},
        baseline_params={sids[i]: o.paper.params[i] for i in range(n)},
        refit_params={sids[i]: o.refit.params[i] for i in range(n)},
        effects=tuple(sel.final.effects), timing_s=o.timing,
        conventions=o.prepared.conventions.as_dict() if o.prepared.conventions is not None else {},
        traces={sids[i]: {"before": o.traces["paper"][i], "after": o.traces["final"][i]} for i in range(n)},
        records_before=records(samples, o.traces["paper"]), records_after=records(samples, o.traces["final"]),
        settings=o.settings, verdict=sel.verdict.label, remainder=_remainder(o), fits_cut_short=fits_cut_short(o),
        discovered=discovered, discovery=discovery)
    return diag


# ============================================================================ JSON documents
def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return _f(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return [_jsonable(v) for v in o.tolist()]
    return o


def _namer(diag: Diagnosis):
    """A signal namer (test, channel) -> "current" | "displacement" | "blocked force" from the traces."""
    def name(test: str, ch: str) -> str:
        if ch == "I":
            return "current"
        for tr in diag.traces.values():
            t = tr.get("after", {}).get(test)
            if t is not None:
                return "blocked force" if t.blocked else "displacement"
        return "reading"
    return name


def diagnosis_to_json(diag: Diagnosis) -> dict:
    """diagnosis.json as a dict (layout: see the package docstring)."""
    st = diag.settings or DiagnoseSettings()
    return _jsonable({
        "format": FORMAT,
        "synthetic": diag.synthetic,
        "cause": diag.cause,
        "verdict": diag.verdict,
        "unexplained_remainder": diag.remainder,
        "causes": diag.causes,
        "discovered_terms": [term_json(t, _namer(diag)) for t in diag.discovered],
        "discovery": diag.discovery,
        "effects": list(diag.effects),
        "effect_parameters": diag.effect_parameters,
        "gain": diag.gain,
        "candidates": diag.candidates,
        "evidence": diag.evidence,
        "decision": diag.decision,
        "samples": diag.samples,
        "parameters": {
            "extended": {sid: params_to_json(p) for sid, p in diag.extended_params.items()},
            "paper_identification": {sid: params_to_json(p) for sid, p in diag.baseline_params.items()},
            "paper_refit": {sid: params_to_json(p) for sid, p in diag.refit_params.items()},
        },
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in st.__dict__.items()},
        "timing_s": diag.timing_s,
        "fits_cut_short": diag.fits_cut_short,
        "conventions": diag.conventions,
    })


def extended_params_json(diag: Diagnosis) -> dict:
    """extended_params.json: every sample's parameters (paper + effect parameters, unit keys)."""
    std = {k: v.get("std") for k, v in diag.effect_parameters.items() if k != "per_sample"}
    return _jsonable({
        "format": "mpc-actuator-params/1",
        "synthetic": diag.synthetic,
        "source": "harness.analysis.diagnosis",
        "cause": diag.cause,
        "effects": list(diag.effects),
        "discovered_terms": [t.name for t in diag.discovered],
        "note": ("SI parameters per sample with the unit in every key; the gap r0 is a per-test setting and "
                 "not stored; effect parameters are 0 when the effect is off. fmu_src.specs names: the key "
                 "up to the first underscore-unit suffix (harness.data.rig.params_from_json reads this layout)."),
        "shared_effect_parameters": {k: v for k, v in diag.effect_parameters.items() if k != "per_sample"},
        "samples": {sid: {"wt_pct": s["wt_pct"], "diameter_mm": s["diameter_mm"], "role": s["role"],
                          "parameters": params_to_json(diag.extended_params[sid])}
                    for sid, s in ((s["id"], s) for s in diag.samples)},
        "shared_effect_parameter_std": std,
    })
