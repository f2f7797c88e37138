"""The whole chain on a user's dataset (``mpc-actuator run DATASET``): check -> identify (validate, generalize)
-> diagnose -> FMUs of every sample (paper and extended model, validated) -> uncertainty and bands -> a control
study on one sample -> design advice (when a spec is given) -> one report, ``report.md``.

Each step's settings come from a settings file (TOML, :func:`load_settings_file`; the keys are listed in
:data:`SETTINGS_KEYS`) and from options (an option wins); ``skip`` names steps not to run (a step whose input a
skipped step would have made is skipped too, and the report says why). Everything is written into one output
folder as a transaction (:func:`harness.outputs.output_transaction`).
"""
from __future__ import annotations

import json
import math
import sys
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from harness import jobs
from harness.analysis.design.run import DesignSettings, default_space, design as run_design
from harness.analysis.design.space import Targets as DesignTargets
from harness.analysis.diagnosis import DiagnoseSettings
from harness.analysis.identification.identify import SampleChoice
from harness.analysis.identification.settings import IdentifySettings
from harness.analysis.core.sweep import ClusterSettings
from harness.analysis.identification.parameter_uncertainty import read_uncertainty
from harness.analysis.uncertainty.run import UncertaintySettings, dataset_uncertainty
from harness.chain_control import control_step, middle_sample, sample_gap_mm
from harness.data.dataset import Dataset, dataset_summary, read_dataset
from harness.outputs import check_output_target, guard_not_inside, output_transaction
from harness.pipeline import JobSettings, PipelineError, fmu_path, identify_validate, run_diagnosis, summary_lines
from harness.report.run_md import StepRecord, write_run_report
from harness.report.uncertainty_report import write_design_outputs, write_uncertainty_outputs

__all__ = ["STEPS", "SETTINGS_KEYS", "ChainSettings", "SettingsFileError", "load_settings_file", "run_chain",
           "middle_sample", "samples_span_an_area"]

#: the steps of the chain, in order
STEPS = ("check", "identify", "diagnose", "fmus", "uncertainty", "control", "design")
#: the steps each step needs (skipping one skips those that need it)
NEEDS = {"identify": ("check",), "diagnose": ("check",), "fmus": ("identify",), "uncertainty": ("identify",),
         "control": ("identify",), "design": ("uncertainty",)}

#: steps whose failure on the user's model (a ValueError that is not a bad-input error) is reported in the report
#: instead of ending the chain: the studies built on the identified model
MAY_FAIL = ("uncertainty", "control", "design")

#: the settings file's sections and keys: {section: {key: (type, description)}}
SETTINGS_KEYS = {
    "run": {"skip": (list, "steps not to run: any of " + ", ".join(STEPS))},
    "identify": {"pop_size": (int, "NSGA-II population (default 60)"),
                 "generations": (int, "NSGA-II generations (default 40)"),
                 "choose": (str, "least_squares (default) or paper (Eq. 6)"),
                 "unseen": (list, "samples to predict from the surfaces instead of identifying, e.g. ['W15-D45']")},
    "diagnose": {"fit_budget_s": (float, "[s] CPU-time budget of all fits of the diagnosis (default 75)"),
                 "unseen": (list, "samples held out of the diagnosis's shared fit")},
    "uncertainty": {"bootstrap": (int, "bootstrap draws of the analytic part (default 500 here, >= 100)"),
                    "draws": (int, "Monte-Carlo draws per sample for the bands (default 16 here, >= 8)"),
                    "seed": (int, "random seed (default 0)"),
                    "bands": (bool, "compute prediction bands (default true)")},
    "control": {"sample": (str, "sample of the control study (default: the identified sample nearest the "
                                "middle of the data in filler fraction and diameter)"),
                "stroke_mm": (float, "[mm] stroke of the reference (default 1)"),
                "freq_hz": (float, "[Hz] frequency of the sine reference (default 2)"),
                "v_max": (float, "[V] voltage limit (default 30)"),
                "margin_mm": (float, "[mm] MPC's margin to the coil face (default 0.5)")},
    "design": {"stroke_mm": (float, "[mm] minimum stroke"), "blocked_force_N": (float, "[N] minimum blocked force"),
               "settling_ms": (float, "[ms] maximum settling time"), "max_current_A": (float, "[A] maximum current"),
               "max_power_W": (float, "[W] maximum steady power"),
               "min_bandwidth_Hz": (float, "[Hz] minimum small-signal bandwidth"),
               "minimise": (str, "what the ranking minimises: power (default), current, diameter or filler"),
               "min_probability": (float, "linearised probability of meeting the spec a recommended design must "
                                          "reach (default 0.95)"),
               "points": (int, "grid points per axis (default 8 here)"),
               "draws": (int, "Monte-Carlo draws per candidate (default 64 here)")},
}

Echo = Callable[[str], None]


class SettingsFileError(PipelineError):
    """The settings file cannot be read or holds an unknown or ill-typed key (the message names file, section
    and key)."""


@dataclass(frozen=True)
class ChainSettings:
    """What :func:`run_chain` runs. ``skip``: steps of :data:`STEPS` not to run; ``identify``,
    ``diagnose``, ``uncertainty``: the steps' settings (None: the chain's defaults); ``unseen``: samples
    identify predicts instead of identifying; ``diagnose_unseen``: samples held out of the diagnosis's shared
    fit; ``control``: the control study's options (keys of :data:`SETTINGS_KEYS` ``control``); ``design``: the
    design spec (keys of ``design``; None or empty: no design step); ``job``: workers and progress.

    Parameters
    ----------
    skip : tuple of str
        Steps of :data:`STEPS` not to run.
    identify : IdentifySettings or None
        The identification's settings (None: the chain's defaults).
    unseen : tuple of str or None
        Samples the identification predicts (generalization) instead of identifying.
    diagnose : DiagnoseSettings or None
        The diagnosis's settings (None: the defaults).
    diagnose_unseen : tuple of str or None
        Samples held out of the diagnosis's shared fit.
    uncertainty : UncertaintySettings or None
        The uncertainty step's settings (None: the defaults).
    control : dict
        The control study's options (keys of :data:`SETTINGS_KEYS` ``control``).
    design : dict or None
        The design spec (keys of ``design``; None or empty: no design step).
    job : JobSettings
        Workers and progress bars.
    """
    skip: tuple = ()
    identify: IdentifySettings | None = None
    unseen: tuple | None = None
    diagnose: DiagnoseSettings | None = None
    diagnose_unseen: tuple | None = None
    uncertainty: UncertaintySettings | None = None
    control: dict = field(default_factory=dict)
    design: dict | None = None
    job: JobSettings = JobSettings()

    def __post_init__(self):
        unknown = [s for s in self.skip if s not in STEPS]
        if unknown:
            raise PipelineError(f"--skip {' '.join(unknown)}: unknown step (steps: {', '.join(STEPS)})")
        object.__setattr__(self, "skip", tuple(self.skip))
        for sec, d in (("control", self.control), ("design", self.design or {})):
            bad = sorted(set(d) - set(SETTINGS_KEYS[sec]))
            if bad:
                raise PipelineError(f"{sec} setting(s) {', '.join(bad)} unknown (known: {', '.join(SETTINGS_KEYS[sec])})")

    def skipped(self) -> dict:
        """{step: why} of the steps that will not run: skipped by the user, needing a skipped step, or (design)
        without a spec."""
        out = {s: "skipped (--skip)" for s in self.skip}
        if not self.design and "design" not in out:
            out["design"] = "no design spec given (settings file [design] or --design-* options)"
        for s in STEPS:
            for n in NEEDS.get(s, ()):
                if n in out and s not in out:
                    out[s] = f"needs the {n} step, which did not run"
        return out


def _typed(path: Path, section: str, key: str, value, kind):
    where = f"{path}: [{section}] {key}"
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if kind is list:
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise SettingsFileError(f"{where}: expected a list of strings, got {value!r}")
        bad = [v for v in value if section == "run" and v not in STEPS]
        if bad:
            raise SettingsFileError(f"{where}: unknown step(s) {', '.join(bad)} (steps: {', '.join(STEPS)})")
        return tuple(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise SettingsFileError(f"{where}: expected {'a list of strings' if kind is list else kind.__name__}, "
                                f"got {value!r}")
    if kind is float and not math.isfinite(value):
        raise SettingsFileError(f"{where}: expected a finite number, got {value!r}")
    return value


def load_settings_file(path: str | Path) -> dict:
    """{section: {key: value}} of a TOML settings file, checked against :data:`SETTINGS_KEYS`.

    Parameters
    ----------
    path : str or Path
        The TOML file (``--settings run.toml``).

    Raises
    ------
    SettingsFileError
        Unreadable file, TOML syntax error (line and column), unknown section or key, ill-typed value.
    """
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise SettingsFileError(f"settings file {p}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise SettingsFileError(f"settings file {p}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as e:
        raise SettingsFileError(f"settings file {p}: {e}") from None
    out = {}
    for sec, body in data.items():
        if not isinstance(body, dict):
            home = next((s for s, keys in SETTINGS_KEYS.items() if sec in keys), None)
            raise SettingsFileError(f"{p}: key {sec!r} outside any section (put it under "
                                    f"{f'[{home}]' if home else 'its section'}; sections: {', '.join(SETTINGS_KEYS)})")
        if sec not in SETTINGS_KEYS:
            raise SettingsFileError(f"{p}: unknown section [{sec}] (sections: {', '.join(SETTINGS_KEYS)})")
        out[sec] = {}
        for key, value in body.items():
            if key not in SETTINGS_KEYS[sec]:
                raise SettingsFileError(f"{p}: [{sec}] unknown key {key!r} (keys: {', '.join(SETTINGS_KEYS[sec])})")
            out[sec][key] = _typed(p, sec, key, value, SETTINGS_KEYS[sec][key][0])
    return out


# --------------------------------------------------------------------------- steps
@dataclass
class _State:
    ds: Dataset
    out: Path
    fmu: Path
    settings: ChainSettings
    records: list = field(default_factory=list)
    results: dict = field(default_factory=dict)
    diagnosis: object = None
    params_files: dict = field(default_factory=dict)        # kind -> Path (in out)


def _step_check(st: _State) -> StepRecord:
    text = dataset_summary(st.ds)
    (st.out / "check.txt").write_text(text + "\n", encoding="utf-8")
    return StepRecord("check", files=[st.out / "check.txt"], summary=text)


def _step_identify(st: _State) -> StepRecord:
    idir = st.out / "identification"
    idir.mkdir(exist_ok=True)
    s = st.settings
    choice = SampleChoice(unseen=s.unseen, skip_incomplete=True)
    st.results, _, written = identify_validate(st.ds, idir, st.fmu, s.identify, s.job, choice)
    st.params_files["identified"] = idir / "identification.json"
    gen = idir / "generalization.json"
    if gen.is_file() and json.loads(gen.read_text(encoding="utf-8")).get("samples"):   # unseen samples predicted
        st.params_files["generalized"] = gen
    return StepRecord("identify", files=written, summary=f"{len(st.results)} samples identified")


def _step_diagnose(st: _State) -> StepRecord:
    ddir = st.out / "diagnosis"
    ddir.mkdir(exist_ok=True)
    s = st.settings
    dset = s.diagnose or DiagnoseSettings(workers=s.job.workers)
    if s.diagnose_unseen is not None:
        dset = replace(dset, unseen=tuple(s.diagnose_unseen))
    st.diagnosis, written = run_diagnosis(st.ds, ddir, dset, s.job)
    if (ddir / "extended_params.json").is_file():
        st.params_files["extended"] = ddir / "extended_params.json"
    return StepRecord("diagnose", files=written, summary="\n".join(summary_lines(st.diagnosis)))


def _step_fmus(st: _State) -> StepRecord:
    from fmpy.validation import validate_fmu
    fdir = st.out / "fmus"
    fdir.mkdir(exist_ok=True)
    rows, written = [], []
    for kind in ("identified", "generalized", "extended"):
        pf = st.params_files.get(kind)
        if pf is None:
            continue
        model = "extended" if kind == "extended" else "paper"
        for sid in sorted(jobs.load_params_file(pf)):
            path = fdir / f"{sid}_{model}.fmu"
            gap = sample_gap_mm(st.ds, sid)
            jobs.build(pf, path, jobs.BuildSettings(sample=sid, gap_mm=gap))
            problems = validate_fmu(str(path))
            rows.append({"sample": sid, "model": model, "parameters": kind, "gap_mm": gap,
                         "file": path.name, "fmpy_validate": "OK" if not problems else "; ".join(problems)})
            written.append(path)
    bad = [r for r in rows if r["fmpy_validate"] != "OK"]
    return StepRecord("fmus", files=written, rows=rows,
                      summary=f"{len(rows)} FMUs built, {len(rows) - len(bad)} pass fmpy validate")


def _step_uncertainty(st: _State) -> StepRecord:
    udir = st.out / "uncertainty"
    params = jobs.load_params_file(st.params_files["identified"])
    s = st.settings
    us = s.uncertainty or UncertaintySettings(n_boot=500, n_draws=16)
    res = dataset_uncertainty(st.ds, params, us, ClusterSettings(workers=s.job.workers, progress=s.job.progress))
    written = write_uncertainty_outputs(res, udir)
    return StepRecord("uncertainty", files=written,
                      summary=f"parameter uncertainty of {len(res.uncertainties)} samples, bands of {len(res.bands)}")


def _step_control(st: _State) -> StepRecord:
    return control_step(st)


def _step_design(st: _State) -> StepRecord:
    spec = dict(st.settings.design or {})
    points = int(spec.pop("points", 8))
    draws = int(spec.pop("draws", 64))
    kw = {"objective": spec.pop("minimise", "power"), "min_probability": float(spec.pop("min_probability", 0.95))}
    targets = DesignTargets(**spec)
    training = read_uncertainty(st.out / "uncertainty" / "uncertainty.json")
    if not samples_span_an_area(st.results):
        raise ValueError(f"the identified samples {sorted(st.results)} span no area in (wt%, D) (fewer than three, "
                         f"or all on one line): their convex hull is degenerate, and surfaces over both variables, "
                         f"which the design needs, cannot be fitted")
    space = default_space(training, {}, points)
    s = st.settings
    res = run_design(training, targets, space, DesignSettings(n_draws=draws, **kw),
                     ClusterSettings(workers=s.job.workers, progress=s.job.progress))
    written = write_design_outputs(res, st.out / "design")
    return StepRecord("design", files=written,
                      summary=f"{len(res.candidates)} of {res.evaluated} designs meet the spec")


def samples_span_an_area(results: dict) -> bool:
    """Whether the identified samples' (filler fraction [wt%], diameter [mm]) points span an area: at least three,
    not all on one line (the design's surfaces over both variables need it)."""
    wd = np.array([(r.wt_pct, r.diameter_mm) for r in results.values()], dtype=float)
    return len(wd) >= 3 and int(np.linalg.matrix_rank(wd - wd.mean(axis=0), tol=1e-9)) == 2


_STEP_FUNCS = {"check": _step_check, "identify": _step_identify, "diagnose": _step_diagnose, "fmus": _step_fmus,
               "uncertainty": _step_uncertainty, "control": _step_control, "design": _step_design}


def run_chain(dataset: str | Path, out: str | Path, settings: ChainSettings = ChainSettings(),
              fmu: str | Path | None = None, overwrite: bool = False, echo: Echo = lambda _line: None) -> Path:
    """Run the chain (module docstring) on ``dataset`` into the folder ``out``; returns ``out/report.md``.

    The dataset is read and every option checked before anything is written; the output folder is written as a
    transaction (on an error or Ctrl-C ``out`` is left as it was).

    Parameters
    ----------
    dataset : str or Path
        The dataset folder.
    out : str or Path
        Output folder (report.md, report.json and one folder per step).
    settings : ChainSettings
        Steps to skip, each step's settings, the control sample, the design spec.
    fmu : str, Path or None
        The actuator FMU (None: the one built in the repository).
    overwrite : bool
        Replace an earlier output of this tool in ``out``.
    echo : callable
        Called with one line per finished step (e.g. ``print``).

    Returns
    -------
    Path
        ``out/report.md``.

    Raises
    ------
    harness.data.format.DataFormatError, PipelineError, harness.outputs.OutputPathError
        Bad dataset, settings, FMU or output folder.
    """
    ds = read_dataset(dataset)
    target = check_output_target(out, overwrite)
    guard_not_inside(dataset, target)
    fmu = fmu_path(fmu)
    skipped = settings.skipped()
    if settings.design:
        DesignTargets(**{k: v for k, v in settings.design.items()
                         if k not in ("points", "draws", "minimise", "min_probability")})
    with output_transaction(target, overwrite, inputs=(dataset,)) as tmp:
        st = _State(ds=ds, out=tmp, fmu=fmu, settings=settings)
        for step in STEPS:
            if step in skipped:
                st.records.append(StepRecord(step, skipped=skipped[step]))
                echo(f"[run] {step}: {skipped[step]}")
                continue
            t0 = time.perf_counter()
            try:
                rec = _STEP_FUNCS[step](st)
            except ValueError as e:
                if step not in MAY_FAIL or isinstance(e, (PipelineError, SettingsFileError)):
                    raise
                # the model of the user's sample does not allow this study (e.g. no PI gains meet the margins):
                # reported, and the chain goes on (a step that needs this one is not run)
                rec = StepRecord(step, failed=f"{type(e).__name__}: {e}")
                skipped.update({s: f"needs the {step} step, which failed" for s in STEPS if step in NEEDS.get(s, ())})
                print(f"warning: step {step} failed: {e} (reported in report.md)", file=sys.stderr)
            rec.wall_s = time.perf_counter() - t0
            st.records.append(rec)
            echo(f"[run] {step}: {rec.summary.splitlines()[0] if rec.summary else 'done'} ({rec.wall_s:.1f} s)")
        report = write_run_report(tmp, Path(dataset), st.records, st.diagnosis, st.results)
    echo(f"report: {target / report.name}")
    return target / report.name


def options_to_settings(file_values: dict, options: dict, job: JobSettings) -> ChainSettings:
    """ChainSettings from a settings file's values (:func:`load_settings_file`) overridden by the options
    ``options`` ({section: {key: value or None}}: None = not given)."""
    merged = {sec: dict(file_values.get(sec, {})) for sec in SETTINGS_KEYS}
    for sec, d in options.items():
        for k, v in d.items():
            if v is not None and v != ():
                merged[sec][k] = v
    idf = merged["identify"]
    ident = None
    if idf.keys() & {"pop_size", "generations", "choose"}:
        kw = {}
        if "pop_size" in idf:
            kw["pop_size"] = idf["pop_size"]
        if "generations" in idf:
            kw["n_gen"] = idf["generations"]
        if "choose" in idf:
            kw["choice"] = str(idf["choose"]).replace("-", "_")
        ident = IdentifySettings(**kw)
    dg = merged["diagnose"]
    diag = DiagnoseSettings(workers=job.workers, fit_budget_s=float(dg["fit_budget_s"])) \
        if "fit_budget_s" in dg else None
    un = merged["uncertainty"]
    unc = None
    if un:
        unc = UncertaintySettings(n_boot=int(un.get("bootstrap", 500)), n_draws=int(un.get("draws", 16)),
                                  seed=int(un.get("seed", 0)), bands=bool(un.get("bands", True)))
    return ChainSettings(skip=tuple(merged["run"].get("skip", ())), identify=ident,
                         unseen=tuple(idf["unseen"]) if "unseen" in idf else None, diagnose=diag,
                         diagnose_unseen=tuple(dg["unseen"]) if "unseen" in dg else None, uncertainty=unc,
                         control=merged["control"], design=merged["design"] or None, job=job)

