"""The main job (``mpc-actuator run``) and its steps as library functions.

:func:`run`: the FMU's default experiment (:func:`default_step`), a synthetic dataset from the virtual
rig with one hidden effect, the paper's identification of the training samples (analytic R, L, Em,
K1, K2; NSGA-II for C, m on the vectorized simulator), validation of T1-T8 through the FMU via fmpy
(Tables 3-5), generalization to the unseen samples (:func:`identify_validate`), and the blind
diagnosis (:func:`run_diagnosis`). The command line's other jobs: :mod:`harness.jobs`; output
folders: :mod:`harness.outputs`.

Errors a user can fix (bad input named) are :class:`PipelineError` subclasses or
:class:`harness.outputs.OutputPathError`; the command line turns them into messages.
"""
from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np

from fmu_src.specs import EFFECTS, SPEC_BY_NAME
from harness.analysis import diagnosis as diagnose_mod
from harness.report.diagnosis_md import write_diagnosis
from harness.analysis.identification import generalize
from harness.analysis.identification import identify as identify_mod
from harness.analysis.validation import run as validation
from harness.analysis.identification.settings import IdentifySettings
from harness.data import rig
from harness.sim import virtual_rig
from harness.data.dataset import Dataset, read_dataset
from harness.data.paramsjson import read_params_file
from harness import scratch
from harness.outputs import check_output_target, output_transaction
from harness.report import figures, tables
from harness.sim.fmurun import default_fmu_path

__all__ = [
    "DEFAULT_HIDDEN_EFFECT", "PipelineError", "FMUNotFoundError", "JobSettings", "DatasetSettings", "RunSettings",
    "RunOutputs", "fmu_path", "default_step", "identify_validate", "run_diagnosis", "summary_lines", "run",
]

# The default dataset of the main job hides one effect the paper's model lacks (issue 5): the
# filler's magnetization saturates, so the force grows more slowly than I^2 at high field.
DEFAULT_HIDDEN_EFFECT = MappingProxyType({"filler_saturation": 1.0})

Echo = Callable[[str], None]


class PipelineError(ValueError):
    """A job cannot run on the given input; the message names the input."""


class FMUNotFoundError(PipelineError):
    """The FMU file does not exist."""


@dataclass(frozen=True)
class JobSettings:
    """How a job runs (not what it computes).

    Parameters
    ----------
    workers : int
        Processes for the FMU runs, identification and diagnosis fits (>= 1; 1: in this process).
    progress : bool
        Show progress bars.
    """
    workers: int = 2
    progress: bool = True

    def __post_init__(self):
        if isinstance(self.workers, bool) or int(self.workers) != self.workers or self.workers < 1:
            raise ValueError(f"workers must be an integer >= 1, got {self.workers!r}")


@dataclass(frozen=True)
class DatasetSettings:
    """What the virtual rig generates.

    Parameters
    ----------
    seed : int
        Seed of the rig's noise.
    samples : tuple of (float, float)
        (filler fraction [wt%], diameter [mm]) of each sample (default: the paper's 11).
    hidden_effects : tuple of (str, float)
        (effect name, magnitude) pairs hidden in the data (``fmu_src.effects``; default: none).
    """
    seed: int = 0
    samples: tuple = rig.ALL_SAMPLES
    hidden_effects: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "samples", tuple(tuple(s) for s in self.samples))
        object.__setattr__(self, "hidden_effects", tuple((str(k), float(v)) for k, v in self.hidden_effects))
        if not self.samples or any(len(s) != 2 for s in self.samples):
            raise ValueError(f"samples: expected (wt_pct, diameter_mm) pairs, got {self.samples!r}")
        unknown = sorted({k for k, _ in self.hidden_effects} - set(EFFECTS))
        if unknown:                          # checked here, before any output folder or simulation
            raise ValueError(f"unknown effect(s) {unknown}; known effects: {', '.join(EFFECTS)}")


@dataclass(frozen=True)
class RunSettings:
    """Settings of the main job :func:`run`.

    Parameters
    ----------
    dataset : DatasetSettings
        The generated dataset (default: the paper's 11 samples, seed 0, :data:`DEFAULT_HIDDEN_EFFECT`).
    identify : IdentifySettings or None
        NSGA-II and identification settings (None: the defaults).
    diagnose : harness.analysis.diagnosis.DiagnoseSettings or None
        Diagnosis settings (None: the defaults with ``job.workers``).
    job : JobSettings
        Workers and progress bars.
    """
    dataset: DatasetSettings = DatasetSettings(hidden_effects=tuple(DEFAULT_HIDDEN_EFFECT.items()))
    identify: IdentifySettings | None = None
    diagnose: diagnose_mod.DiagnoseSettings | None = None
    job: JobSettings = JobSettings()


@dataclass(frozen=True)
class RunOutputs:
    """Folders written by :func:`run` (all inside ``out``).

    Parameters
    ----------
    out : Path
        The output folder.
    step : Path
        The default step response (``step/``).
    dataset : Path
        The generated dataset (``dataset/``).
    identification : Path
        Identification, validation, generalization (``identification/``).
    diagnosis : Path
        The diagnosis (``diagnosis/``).
    """
    out: Path
    step: Path
    dataset: Path
    identification: Path
    diagnosis: Path


def _quiet(_line: str) -> None:
    """Echo that prints nothing (the library default)."""


# --------------------------------------------------------------------------- inputs
def fmu_path(path: str | Path | None = None) -> Path:
    """The FMU to run: ``path``, or the one built in the repository (``$MPC_ACTUATOR_FMU``).

    Raises
    ------
    FMUNotFoundError
        The file does not exist, or it is not an FMU (a zip archive holding modelDescription.xml).
    """
    import zipfile
    p = Path(path) if path else default_fmu_path()
    if not p.exists():
        raise FMUNotFoundError(f"FMU {p} not found; build it with `python build_fmu.py`")
    try:
        with zipfile.ZipFile(p) as z:
            has_md = "modelDescription.xml" in z.namelist()
    except (OSError, zipfile.BadZipFile) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else "not a zip archive"
        raise FMUNotFoundError(f"FMU {p} is not an FMU ({why}); build one with `python build_fmu.py`") from None
    if not has_md:
        raise FMUNotFoundError(f"FMU {p} is not an FMU (the archive holds no modelDescription.xml); build one with "
                               f"`python build_fmu.py`")
    return p


# --------------------------------------------------------------------------- steps
def default_step(out: Path, fmu: Path) -> tuple[Path, Path, dict]:
    """Simulate the FMU's DefaultExperiment with fmpy; write a CSV and a PNG of V, I, x, F.

    Parameters
    ----------
    out : Path
        Existing folder for ``default_step.csv`` (time [s], voltage [V], current [A],
        displacement [mm], force [N], field [T], contact flag) and ``default_step.png``.
    fmu : Path
        The FMU.

    Returns
    -------
    tuple of (Path, Path, dict)
        CSV path, PNG path and fmpy's result (SI units: x in m).
    """
    import fmpy
    md = fmpy.read_model_description(str(fmu))
    de = md.defaultExperiment
    unzipdir = fmpy.extract(str(fmu), unzipdir=scratch.new_dir("fmu-"))     # removed however the command ends
    try:
        res = fmpy.simulate_fmu(unzipdir, model_description=md, stop_time=float(de.stopTime),
                                output_interval=float(de.stepSize), output=["V", "I", "x", "F", "B", "contact"])
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    cols = [("time_s", res["time"]), ("voltage_V", res["V"]), ("current_A", res["I"]),
            ("displacement_mm", res["x"] * 1e3), ("force_N", res["F"]), ("field_T", res["B"]),
            ("contact", res["contact"].astype(int))]
    csv = out / "default_step.csv"
    with open(csv, "w") as f:
        f.write(",".join(c for c, _ in cols) + "\n")
        for row in zip(*(v for _, v in cols)):
            f.write(",".join(f"{x:.9g}" for x in row) + "\n")
    png = out / "default_step.png"
    start = {v.name: v.start for v in md.modelVariables}
    r0 = f", gap $r_0$ = {1e3 * float(start['r0']):g} mm" if start.get("r0") is not None else ""
    figures.plot_default_step(png, figures.StepTraces(res["time"], res["V"], res["I"], res["x"] * 1e3,
                                                      res["F"]),
                              title=f"FMU default experiment: {float(abs(res['V']).max()):.3g} V step at $t$ = 0\n"
                                    f"default parameters{r0}")
    return csv, png, res


def _predicted(fits, w: float, d: float, name: str) -> float:
    """A surface's value at (w, d), NaN outside the samples' convex hull (not drawn)."""
    try:
        return generalize.predict(fits, w, d)[name]
    except generalize.GeneralizationError:
        return float("nan")


def _surface_figures(results: dict, fig: Path) -> None:
    """Figure-6-like surface fit of each generalized parameter over filler fraction and diameter."""
    fits = generalize.fit_surfaces(results)
    ws = [r.wt_pct for r in results.values()]
    ds_ = [r.diameter_mm for r in results.values()]
    for name in generalize.FIT_PARAMS:
        vals = [getattr(r.params, name) for r in results.values()]
        grid = np.vectorize(lambda w, d, n=name: _predicted(fits, float(w), float(d), n))
        figures.plot_surface(fig / f"surface_{name}.png",
                             figures.SurfaceData(name, SPEC_BY_NAME[name].unit, ws, ds_, vals, list(results)), grid)


def identify_validate(ds: Dataset, out: Path, fmu: Path, settings: IdentifySettings | None = None,
                      job: JobSettings = JobSettings(), choice: identify_mod.SampleChoice = identify_mod.SampleChoice()
                      ) -> tuple[dict, list, list[Path]]:
    """Identify, validate through the FMU, generalize to the unseen samples; tables and figures.

    Identifies the training samples (paper section 3), runs T1-T8 of every sample with
    parameters through the FMU (Tables 3, 4), predicts the samples declared unseen from the
    surface fits and validates those (Table 5).

    Parameters
    ----------
    ds : Dataset
        The measured (or synthetic) dataset.
    out : Path
        Existing output folder: identification.json, pareto/, generalization.json,
        validation_*.{csv,md} and figures/.
    fmu : Path
        The FMU for the validation runs.
    settings : IdentifySettings or None
        Identification settings (None: the defaults).
    job : JobSettings
        Workers and progress bars.
    choice : harness.analysis.identification.identify.SampleChoice
        The samples declared unseen, and whether incomplete samples are skipped (then listed as
        skipped in identification.json, generalization.json and the tables' Markdown).

    Returns
    -------
    tuple of (dict, list, list of Path)
        ``{id: SampleIdentification}``, the validation records and the written files.
    """
    selection = identify_mod.select_samples(ds, None, choice)
    results, written = identify_mod.identify_and_write(ds, out, settings=settings, workers=job.workers,
                                                       progress=job.progress, choice=choice)
    fig = out / "figures"
    fig.mkdir(exist_ok=True)
    for sid, r in results.items():
        figures.plot_pareto(fig / f"pareto_{sid}.png", r.pareto.objectives, r.chosen,
                            list(identify_mod.OBJECTIVE_NAMES), sample_id=sid)
    params = {sid: r.params for sid, r in results.items()}
    unseen = {}
    gen = out / "generalization.json"
    if gen.exists():
        if json.loads(gen.read_text()).get("samples"):
            unseen = read_params_file(gen)
        _surface_figures(results, fig)
    runs = validation.run_dataset(ds, {**params, **unseen}, fmu_path=fmu, workers=job.workers, progress=job.progress)
    records = [r for run in runs for r in run.records]
    table5 = [sid for sid in selection.unseen if sid in unseen]
    written += tables.write_tables(records, out, "validation", table5_samples=table5, skipped=selection.skipped,
                                   summary_samples=sorted(results))
    for run in runs:
        written.append(figures.plot_sample_figure(fig / f"sample_{run.sample}.png", run.sample, run.traces,
                                                  synthetic=ds.synthetic))
    return results, records, written


def run_diagnosis(ds: Dataset, out: Path, settings: diagnose_mod.DiagnoseSettings | None = None,
                  job: JobSettings = JobSettings()) -> tuple:
    """Diagnose a dataset blind; write diagnosis.json, diagnosis.md, figures, extended_params.json.

    Parameters
    ----------
    ds : Dataset
        The dataset (its manifest's hidden effects and true parameters are not read).
    out : Path
        Output folder.
    settings : DiagnoseSettings or None
        Diagnosis settings (None: the defaults with ``job.workers``).
    job : JobSettings
        Workers and progress output.

    Returns
    -------
    tuple of (Diagnosis, list of Path)
        The diagnosis and the written files.
    """
    st = settings or diagnose_mod.DiagnoseSettings(workers=job.workers)
    diag = diagnose_mod.diagnose(ds, st, progress=job.progress)
    written = write_diagnosis(diag, out)
    return diag, written


def summary_lines(diag) -> list[str]:
    """Cause and held-out gain of a diagnosis in a few lines for the terminal."""
    lines = [f"diagnosis (blind): cause = {diag.cause}"]
    label = getattr(diag, "verdict", "") or diag.cause
    if label != diag.cause:
        lines.append(f"  verdict: {label}")
    for c in diag.causes:
        if isinstance(c, dict):
            nums = ", ".join(f"{k} {v:.4g}" for k, v in c.items()
                             if isinstance(v, (int, float)) and not isinstance(v, bool) and k != "rank")
            lines.append(f"  {c.get('rank', '-')}. {c.get('effect', c.get('name', '?'))}: {nums}")
    for t in getattr(diag, "discovered", None) or []:
        lines.append(f"  discovered term: {t.summary()}")
    ov = (diag.gain or {}).get("overall_normalized_rmse")
    if isinstance(ov, dict) and "before" in ov and "after" in ov:
        if all(isinstance(ov[k], (int, float)) for k in ("before", "after")):
            lines.append(f"  held-out RMSE (in sensor noise floors), paper model -> extended model: "
                         f"{ov['before']:.3g} -> {ov['after']:.3g}")
        else:          # the dataset has none of the held-out tests (T2, T4, T6, T7): nothing to compare
            lines.append("  held-out RMSE: none (the dataset has no held-out test)")
    cut = getattr(diag, "fits_cut_short", None) or []
    timed = [c for c in cut if c.get("stop") == "time_budget"]
    if timed:
        lines.append(f"  warning: {len(timed)} fit(s) stopped on the time budget (fit_budget_s), not at a minimum: "
                     f"the verdict may change with more time (diagnosis.md, 'Fits cut short')")
    undecided = ((getattr(diag, "remainder", None) or {}).get("undecided_within_budget") or [])
    if undecided:
        lines.append("  not decided within the fit budget: " + ", ".join(
            f"{q['candidate']} (cut after {q['iterations']} iteration(s))" for q in undecided)
            + ": supported by the fit data, not confirmed by the held-out tests of its unconverged fit")
    return lines


# --------------------------------------------------------------------------- jobs
def run(out: str | Path, settings: RunSettings = RunSettings(), fmu: str | Path | None = None,
        overwrite: bool = False, echo: Echo = _quiet) -> RunOutputs:
    """The main job: default step, synthetic dataset, identification, validation, diagnosis.

    Parameters
    ----------
    out : str or Path
        Output folder, written as a transaction (:func:`harness.outputs.output_transaction`: a
        temporary folder beside it, moved into place at the end; on an error or Ctrl-C the earlier
        state is left as it was): ``step/``, ``dataset/``, ``identification/`` and ``diagnosis/``.
    settings : RunSettings
        Seed, samples, hidden effects, identification and diagnosis settings, workers.
    fmu : str, Path or None
        The FMU (None: the one built in the repository).
    overwrite : bool
        Replace an earlier output folder made by this tool (the whole folder).
    echo : callable
        Receives the summary lines (e.g. ``print``); the default prints nothing.

    Returns
    -------
    RunOutputs
        The folders written.

    Raises
    ------
    harness.outputs.OutputPathError
        ``out`` may not be written into.
    FMUNotFoundError
        The FMU does not exist.
    """
    target = check_output_target(out, overwrite)          # everything checked before any work
    fmu = fmu_path(fmu)
    with output_transaction(target, overwrite) as tmp:
        _run_into(tmp, target, settings, fmu, echo)
    return RunOutputs(out=target, step=target / "step", dataset=target / "dataset",
                      identification=target / "identification", diagnosis=target / "diagnosis")


def _run_into(out: Path, target: Path, settings: RunSettings, fmu: Path, echo: Echo) -> None:
    """The stages of :func:`run`, written into ``out`` (the transaction's temporary folder); the
    messages name the paths they will have in ``target`` after the commit."""
    job, dset = settings.job, settings.dataset

    def final(p: Path) -> Path:
        return target / Path(p).relative_to(out)
    (out / "step").mkdir(exist_ok=True)
    csv, png, res = default_step(out / "step", fmu)
    echo(f"default step: x settles at {res['x'][-1] * 1e3:.3f} mm, I = {res['I'][-1]:.4f} A, "
         f"F = {res['F'][-1]:.4f} N  ->  {final(csv)}, {final(png)}")
    dpath = out / "dataset"
    virtual_rig.generate_dataset(dpath, seed=dset.seed, samples=dset.samples, fmu_path=fmu, workers=job.workers,
                                 effects=dict(dset.hidden_effects), progress=job.progress, overwrite=False)
    ds = read_dataset(dpath)
    echo(f"synthetic dataset (virtual rig, seed {dset.seed}): {len(ds.samples)} samples, one hidden effect "
         f"(recorded in its manifest; the diagnosis does not read it) -> {final(dpath)}")
    idir = out / "identification"
    idir.mkdir(exist_ok=True)
    results, _, written = identify_validate(ds, idir, fmu, settings.identify, job)
    echo(f"identified {len(results)} samples (R, L, Em, K1, K2 analytic; C, m by NSGA-II), validated T1-T8 "
         f"through the FMU, predicted the unseen samples: {len(written)} files -> {final(idir)}")
    for name in ("validation_table3.md", "validation_table4.md", "validation_table5.md"):
        if (idir / name).exists():
            echo((idir / name).read_text())
    ddir = out / "diagnosis"
    ddir.mkdir(exist_ok=True)
    diag, written = run_diagnosis(ds, ddir, settings.diagnose, job)
    echo("\n".join(summary_lines(diag)))
    echo(f"diagnosis report: {final(ddir / 'diagnosis.md')} ({len(written)} files)")
