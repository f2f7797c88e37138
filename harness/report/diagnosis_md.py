"""Markdown report and residual figures of a diagnosis (``harness.analysis.diagnosis``), and the writer of
its output folder: diagnosis.json, extended_params.json, paper-style tables, figures, diagnosis.md."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from harness.analysis.diagnosis import DiagnoseSettings, Diagnosis, diagnosis_to_json, extended_params_json
from harness.report import figures, tables


def _fmt(v, digits=4):
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float, np.floating)):
        if not math.isfinite(v):
            return "–"
        return f"{v:.{digits}g}"
    return str(v)


def _md_table(header, rows) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(_fmt(c) if not isinstance(c, str) else c for c in r) + " |" for r in rows]
    return "\n".join(out)


def _residual_figure(path, sid, tr: dict, effects) -> Path:
    """Residuals (measured - simulated) of one sample before (paper model) and after (final model)."""
    before, after = tr["before"], tr["after"]
    res_b, res_a, units = {}, {}, {}
    for name in sorted(before):
        b, a = before[name], after[name]
        scale = 1.0 if b.blocked else 1e3
        res_b[name] = (b.x, (b.y_meas - b.y_sim) * scale)
        res_a[name] = (a.x, (a.y_meas - a.y_sim) * scale)
        units[name] = "N" if b.blocked else "mm"
    for name in ("T5", "T8"):
        if name in before and before[name].kind == "series":
            b, a = before[name], after[name]
            key = f"{name} current"
            res_b[key] = (b.x, (b.I_meas - b.I_sim) * 1e3)
            res_a[key] = (a.x, (a.I_meas - a.I_sim) * 1e3)
            units[key] = "mA"
    after = f"paper model + {figures.effect_text(effects)}" if effects else "refitted paper model"
    return figures.plot_residuals(path, res_b, res_a, units=units, labels=("paper model", after),
                                  title=f"Sample {sid}: residuals measured − simulated, paper model and {after}")


def write_diagnosis(diag: Diagnosis, out_dir, max_figures: int | None = None) -> list:
    """Write diagnosis.json, diagnosis.md (with residual figures), extended_params.json and the
    paper-style tables of the baseline and the extended model to ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    data = diagnosis_to_json(diag)
    p = out / "diagnosis.json"
    p.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    written.append(p)
    p = out / "extended_params.json"
    p.write_text(json.dumps(extended_params_json(diag), indent=2, allow_nan=False) + "\n")
    written.append(p)
    tdir = out / "tables"
    written += tables.write_tables(diag.records_after, tdir, "extended")
    written += tables.write_tables(diag.records_before, tdir, "paper_model")
    fdir = out / "figures"
    fdir.mkdir(exist_ok=True)
    figs = []
    order = [s["id"] for s in diag.samples if s["role"] == "shared fit"] + \
            [s["id"] for s in diag.samples if s["role"] != "shared fit"]
    for sid in order[: (len(order) if max_figures is None else max_figures)]:
        f = _residual_figure(fdir / f"residuals_{sid}.png", sid, diag.traces[sid], diag.effects)
        figs.append((sid, f))
        written.append(f)
    p = out / "diagnosis.md"
    p.write_text(markdown(diag, data, figs, out))
    written.append(p)
    return written


def _verdict(diag: Diagnosis, data: dict, z_struct: float) -> list:
    L = ["# Model-error diagnosis", ""]
    if diag.synthetic:
        L.append("> Dataset: **SYNTHETIC** (virtual rig). The diagnosis ran blind: it did not read the hidden "
                 "effects or true parameters stored in the manifest.")
        L.append("")
    if diag.cause == "none":
        verdict = ("**none**: no candidate effect improves on the paper's model beyond the noise; the paper's "
                   "model explains the data.")
    elif diag.cause == "unexplained":
        verdict = ("**unexplained**: the paper's model leaves significant structure in the residuals "
                   f"({', '.join(k for k, v in data['evidence']['baseline_structure_z'].items() if v and v > z_struct)}) "
                   "and no candidate of the catalogue explains it.")
    else:
        named = [c["name"] for c in diag.causes] + [f"discovered term {t.name}" for t in diag.discovered]
        verdict = "**" + " + ".join(named) + "**" + (
            " (ranked, strongest first)" if len(diag.causes) > 1 else "")
        rem = diag.remainder or {}
        if rem.get("present"):
            verdict += (" + **unexplained remainder**: the named cause improves the fit and the held-out tests, but "
                        "the extended model still leaves structure beyond the noise in "
                        + ", ".join(f"{q['test']} {q['signal']} (z {_fmt(q['z'])})" for q in rem["where"][:6])
                        + " (an effect of another form or one outside the catalogue; per sample in diagnosis.json, "
                          "unexplained_remainder.per_sample_z).")
    undecided = (diag.remainder or {}).get("undecided_within_budget") or []
    if undecided:
        verdict += (" Not decided within the fit budget: " + ", ".join(
            f"{q['candidate']} (its fit cut after {q['iterations']} iteration(s))" for q in undecided)
            + ": the fit data supported it, but the time budget (fit_budget_s) cut its fit before convergence and "
              "the held-out tests judged the unconverged fit (see 'Fits cut short'); a larger fit_budget_s may "
              "decide.")
    L += [f"Cause: {verdict}", ""]
    if diag.causes:
        L += ["## Ranked causes", ""]
        L.append(_md_table(["rank", "effect", "BIC change (fit data)", "held-out chi² decrease", "score", "shows in"],
                           [[str(c["rank"]), c["name"], c["delta_bic"], c["delta_chi2_heldout"], c["score"],
                             ", ".join(f"{q['test']} {q['signal']}" for q in c["shows_in"][:5]) or "–"]
                            for c in diag.causes]))
        L.append("")
    return L + _discovered(diag, data)


def _discovered(diag: Diagnosis, data: dict) -> list:
    """The discovery stage: the terms found (equation, values +- std, reading, where they matter) or why none."""
    disc = data.get("discovery") or {}
    if not disc:
        return []
    L = ["## Discovery beyond the catalogue", "",
         f"The catalogue stage said *{disc['catalogue_verdict']}* ({disc['ran_because']}), so the "
         f"{len(disc['library'])} terms of the term library (`fmu_src.terms.TERMS`) were tried: {disc['rule']}. "
         f"Stopped: {disc['stop']}.", ""]
    for t in data.get("discovered_terms", []):
        c = t["coefficient"]
        L += [f"### {t['name']} ({t['kind']})", "", f"- equation: `{t['equation']}`",
              f"- physical reading: {t['physical_reading']}",
              f"- {c['name']} [{c['unit']}] per sample: "
              + ", ".join(f"{sid} {_fmt(v['value'])} ± {_fmt(v['std'])}" for sid, v in c["per_sample"].items())]
        lag = t.get("lag_time_constant_s")
        if lag:
            L.append(f"- {lag['name']}: {_fmt(lag['value'])} ± {_fmt(lag['std'])} {lag.get('unit', 's')}")
        L += [f"- accepted: {t['reason']}",
              "- shows in: " + (", ".join(f"{q['test']} {q['signal']} (chi² -{_fmt(q['delta_chi2'])})"
                                          for q in t["shows_in"]) or "–"),
              "- samples (chi² decrease): " + ", ".join(f"{q['id']} {_fmt(q['delta_chi2'])}" for q in t["samples"]),
              ""]
    if not data.get("discovered_terms"):
        L += ["No term passed the acceptance rule.", ""]
    g = diag.gain.get("overall_normalized_rmse", {})
    if "catalogue" in g:
        L += [f"Held-out RMSE / noise floor: paper model {_fmt(g.get('before'))}, catalogue stage "
              f"{_fmt(g.get('catalogue'))}, with the discovered terms {_fmt(g.get('after'))}.", ""]
    for r in disc["rounds"]:
        L += [f"Terms added to {' + '.join(r['reference']) or 'the catalogue stage model'}:", ""]
        L.append(_md_table(["term", "BIC change", "held-out chi² decrease", "accepted", "reason"],
                           [[n, c["delta_bic"], c["delta_chi2_heldout"], c["accepted"], c["reason"]]
                            for n, c in r["candidates"].items()]))
        L.append("")
    return L


def _effect_parameters(diag: Diagnosis) -> list:
    L = ["## Effect parameters", ""]
    if diag.effect_parameters:
        rows = [[k, v["value"], v["std"], v["effect"]] for k, v in diag.effect_parameters.items() if k != "per_sample"]
        L.append(_md_table(["parameter (unit in the name)", "value", "std (from the Jacobian)", "effect"], rows))
        ps = diag.effect_parameters.get("per_sample", {})
        if ps:
            keys = sorted({k for v in ps.values() for k in v})
            L += ["", "Per sample (FMU parameters):", ""]
            L.append(_md_table(["sample"] + keys, [[sid] + [v.get(k) for k in keys] for sid, v in ps.items()]))
    else:
        L.append("None (no effect selected).")
    L.append("")
    return L


def _gain(g: dict) -> list:
    L = ["## Gain on held-out data", ""]
    L.append(f"Held-out tests (never used by a fit): {', '.join(g['heldout_tests'])}. "
             "*before*: paper model identified as in the paper; *refit*: paper model re-fitted by least squares "
             "on the fit tests; *after*: the extended model. RMSE pooled over the samples.")
    L.append("")
    rows = []
    cat = any("catalogue" in v for e in g["per_test"].values() for v in e.values())
    for t, e in g["per_test"].items():
        for k, v in e.items():
            rows.append([t, k, v.get("before"), v.get("refit")] + ([v.get("catalogue")] if cat else []) + [v.get("after")])
    L.append(_md_table(["test", "quantity", "before", "refit"] + (["catalogue stage"] if cat else []) + ["after"],
                       rows))
    o = g["overall_normalized_rmse"]
    L.append("")
    L.append(f"Overall held-out RMSE in units of the sensor noise floor (RMS over samples, tests and signals): "
             f"before {_fmt(o.get('before'))}, refit {_fmt(o.get('refit'))}, after {_fmt(o.get('after'))} "
             f"(after/before {_fmt(o.get('after_over_before'))}).")
    if "heldout_samples" in g:
        h = g["heldout_samples"]["overall_normalized_rmse"]
        L.append(f"Held-out samples {', '.join(g['heldout_samples']['samples'])} (effect parameters fitted on the "
                 f"other samples; every test): before {_fmt(h.get('before'))}, after {_fmt(h.get('after'))}.")
    if "declared_unseen_samples" in g:
        h = g["declared_unseen_samples"]["overall_normalized_rmse"]
        L.append(f"Samples declared unseen {', '.join(g['declared_unseen_samples']['samples'])} (every test): "
                 f"before {_fmt(h.get('before'))}, after {_fmt(h.get('after'))}.")
    L.append("")
    return L


def _candidates(diag: Diagnosis) -> list:
    L = ["## Candidates", ""]
    rows = [[n, c["delta_bic"], c["delta_chi2_heldout"], c["score"], c["accepted"],
             ", ".join(f"{k} = {_fmt(v)}" for k, v in c["shared_parameters"].items()), c["reason"]]
            for n, c in diag.candidates.items()]
    L.append(_md_table(["candidate", "BIC change", "held-out chi² decrease", "score", "accepted",
                        "fitted shared parameters", "reason"], rows))
    for r in diag.decision["rounds"][1:]:
        L += ["", f"Greedy step: candidates added to {' + '.join(r['reference'])}:", ""]
        L.append(_md_table(["added", "BIC change", "held-out chi² decrease", "accepted", "reason"],
                           [[n, c["delta_bic"], c["delta_chi2_heldout"], c["accepted"], c["reason"]]
                            for n, c in r["candidates"].items()]))
    L.append("")
    return L


def _evidence(ev: dict) -> list:
    L = ["## Evidence in the residuals of the paper model", ""]
    rows = [[k, v.get("z"), v["points_to"], ", ".join(v["tests"]), v["description"]]
            for k, v in ev["features"].items()]
    L.append(_md_table(["feature", "z (noise units)", "points to", "tests", "what it measures"], rows))
    L.append("")
    zb, zf = ev["baseline_structure_z"], ev["final_structure_z"]
    L.append("Structure left in the residuals, z = (chi² - n)/sqrt(2n) per test and signal (about N(0,1) for "
             "noise; refitted paper model vs final model):")
    L.append("")
    L.append(_md_table(["test/signal", "paper model (refit)", "final model"], [[k, zb[k], zf.get(k)] for k in zb]))
    L.append("")
    return L


def _decision(d: dict) -> list:
    L = ["## Decision rule", "", d["rule"], ""]
    L.append(f"Fit tests: {', '.join(d['fit_tests'])}; held-out tests: {', '.join(d['heldout_tests'])}. "
             f"Shared effect parameters fitted on {', '.join(d['shared_fit_samples'])}"
             + (f"; held-out samples (base parameters re-fitted on their own fit tests with the effect parameters "
                f"fixed): {', '.join(d['heldout_samples'])}" if d["heldout_samples"] else "") + ".")
    ch = d.get("heldout_sample_choice")
    if ch:
        du = ch.get("declared_unseen")
        L += ["", f"Held-out samples chosen by {ch['source']}: "
              + (f"declared unseen {', '.join(du)}; " if du else "")
              + f"rule: {ch['rule']} (max_shared_samples {ch['max_shared_samples']})."]
    L += ["", d["noise_model"] + ".", ""]
    return L


def _figures_and_files(diag: Diagnosis, figs, out: Path) -> list:
    L = ["## Figures", ""]
    for sid, f in figs:
        L += [f"![{sid} residuals]({Path(f).relative_to(out).as_posix()})", ""]
    L += ["## Files", ""]
    L.append("- `diagnosis.json`: everything above, machine-readable (keys carry units).")
    L.append("- `extended_params.json`: every sample's parameters, paper + effect parameters (unit keys), for "
             "`mpc-actuator build --params extended_params.json`.")
    L.append("- `tables/extended_*`, `tables/paper_model_*`: paper-style Tables 3, 4, 5 and a long table of the "
             "extended model and of the paper model (CSV and Markdown).")
    L.append("")
    L.append(f"Wall time: {_fmt(diag.timing_s.get('total'))} s.")
    L.append("")
    return L


def _cut_short(diag: Diagnosis) -> list:
    """The fits that stopped on their iteration limit or time budget (``diagnosis.json`` -> ``fits_cut_short``)."""
    cs = diag.fits_cut_short
    if not cs:
        return []
    L = ["## Fits cut short", "",
         f"{len(cs)} fit(s) stopped on a limit, not at a minimum; their numbers are those of the last iterate:", ""]
    L += [f"- {c['model']}: {c['fit']}, after {c['iterations']} iterations: {c['why']}." for c in cs]
    return L + [""]


def _conventions(diag: Diagnosis) -> list:
    """The rig conventions inferred from the data (harness.analysis.identification.conventions; details in diagnosis.json)."""
    c = diag.conventions or {}
    if not c:
        return []
    from harness.analysis.identification.conventions import conventions_summary_lines
    return ["## Rig conventions inferred from the data", ""] + conventions_summary_lines(c) + [
        "", "Every test's sample period, clock start and step instant: `diagnosis.json` -> `conventions`.", ""]


def markdown(diag: Diagnosis, data: dict, figs, out: Path) -> str:
    """diagnosis.md: verdict, causes, effect parameters, gain, candidates, evidence, decision rule, figures.

    ``data``: :func:`diagnosis_to_json` of ``diag``; ``figs`` [(sample id, figure path)] under ``out``.
    """
    st = diag.settings or DiagnoseSettings()
    L = (_verdict(diag, data, st.z_struct) + _effect_parameters(diag) + _gain(diag.gain) + _candidates(diag)
         + _evidence(diag.evidence) + _decision(diag.decision) + _conventions(diag) + _cut_short(diag)
         + _figures_and_files(diag, figs, out))
    return "\n".join(L)
