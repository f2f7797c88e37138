"""The jobs of the command line as library functions: the main job and the other multi-step jobs.

:func:`run` is the main job (``mpc-actuator run``): the FMU's default experiment, a synthetic dataset
from the virtual rig with one hidden effect, the paper's identification of the training samples
(analytic R, L, Em, K1, K2; NSGA-II for C, m on the vectorized simulator), validation of T1-T8
through the FMU via fmpy (Tables 3-5), generalization to the unseen samples, and the blind
diagnosis. The other jobs are the steps on their own: :func:`generate`, :func:`check`,
:func:`protocols`, :func:`identify`, :func:`diagnose`, :func:`build` and :func:`crosscheck_make` /
:func:`crosscheck_check`. Output folders: :mod:`harness.outputs`.

Errors a user can fix (bad input named) are :class:`PipelineError` subclasses or
:class:`harness.outputs.OutputPathError`; the command line turns them into messages.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np

from fmu_src.effects import EFFECT_SPECS
from fmu_src.params import SPEC_BY_NAME, SPECS
from harness.analysis import crosscheck as crosscheck_mod
from harness.analysis import diagnose as diagnose_mod
from harness.analysis import generalize
from harness.analysis import identify as identify_mod
from harness.analysis.identify import IdentifySettings
from harness.data import rig
from harness.data.dataset import Dataset, dataset_summary, read_dataset
from harness.data.paramsjson import ParamsJSONError, params_from_json, read_params_file
from harness.outputs import OutputPathError, dataset_and_output, output_folder
from harness.report import figures, tables
from harness.sim import replay
from harness.sim.fmurun import default_fmu_path

__all__ = [
    "DEFAULT_HIDDEN_EFFECT", "PipelineError", "FMUNotFoundError", "ParamsFileError", "SampleChoiceError",
    "JobSettings", "DatasetSettings", "RunSettings", "BuildSettings", "RunOutputs",
    "fmu_path", "load_params_file", "true_params", "default_step", "identify_validate", "run_diagnosis",
    "summary_lines", "write_protocol_outputs", "run", "generate", "check", "protocols", "identify",
    "diagnose", "build", "crosscheck_make", "crosscheck_check",
]

# The default dataset of the main job hides one effect the paper's model lacks (issue 5): the
# filler's magnetization saturates, so the force grows more slowly than I^2 at high field.
DEFAULT_HIDDEN_EFFECT = MappingProxyType({"filler_saturation": 1.0})

Echo = Callable[[str], None]


class PipelineError(ValueError):
    """A job cannot run on the given input; the message names the input."""


class FMUNotFoundError(PipelineError):
    """The FMU file does not exist."""


class ParamsFileError(PipelineError):
    """A parameter file given to a job is unreadable or invalid; the message starts with its path."""


class SampleChoiceError(PipelineError):
    """The sample to use is missing or not in the parameter file."""


@dataclass(frozen=True)
class JobSettings:
    """How a job runs (not what it computes).

    Parameters
    ----------
    workers : int
        Processes for the FMU runs, identification and diagnosis fits (0 or 1: in this process).
    progress : bool
        Show progress bars.
    """
    workers: int = 2
    progress: bool = True

    def __post_init__(self):
        if isinstance(self.workers, bool) or int(self.workers) != self.workers or self.workers < 0:
            raise ValueError(f"workers must be an integer >= 0, got {self.workers!r}")


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


@dataclass(frozen=True)
class RunSettings:
    """Settings of the main job :func:`run`.

    Parameters
    ----------
    dataset : DatasetSettings
        The generated dataset (default: the paper's 11 samples, seed 0, :data:`DEFAULT_HIDDEN_EFFECT`).
    identify : IdentifySettings or None
        NSGA-II and identification settings (None: the defaults).
    diagnose : harness.analysis.diagnose.DiagnoseSettings or None
        Diagnosis settings (None: the defaults with ``job.workers``).
    job : JobSettings
        Workers and progress bars.
    """
    dataset: DatasetSettings = DatasetSettings(hidden_effects=tuple(DEFAULT_HIDDEN_EFFECT.items()))
    identify: IdentifySettings | None = None
    diagnose: diagnose_mod.DiagnoseSettings | None = None
    job: JobSettings = JobSettings()


@dataclass(frozen=True)
class BuildSettings:
    """What :func:`build` bakes into an FMU besides the parameters.

    Parameters
    ----------
    sample : str or None
        Sample id in the parameter file (None: its only sample).
    gap_mm : float
        Gap r0 [mm] baked in as start value.
    blocked : bool
        Bake in blocked mode.
    status_shim : bool
        Build with the C status shim (see ``build_fmu.py``).
    """
    sample: str | None = None
    gap_mm: float = 9.0
    blocked: bool = False
    status_shim: bool = True


@dataclass(frozen=True)
class RunOutputs:
    """Folders written by :func:`run` (all inside ``out``)."""
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
        The file does not exist.
    """
    p = Path(path) if path else default_fmu_path()
    if not p.exists():
        raise FMUNotFoundError(f"FMU {p} not found; build it with `python build_fmu.py`")
    return p


def load_params_file(path: str | Path) -> dict:
    """Parameters per sample ``{id: Params}`` from a parameter file.

    Reads identification.json, generalization.json or extended_params.json
    (:func:`harness.data.paramsjson.read_params_file`: layout, keys with units).

    Raises
    ------
    ParamsFileError
        The file is unreadable or invalid; the message names the file, sample and key.
    """
    try:
        return read_params_file(path)
    except ParamsJSONError as e:
        raise ParamsFileError(str(e)) from None


def true_params(ds: Dataset, with_effects: bool = False) -> dict:
    """True parameters ``{id: Params}`` stored by the virtual rig in a synthetic manifest.

    Parameters
    ----------
    ds : Dataset
        A dataset made by the virtual rig (its manifest has ``rig.true_parameters``).
    with_effects : bool
        Keep the hidden effects. Without them: the paper's model with the true paper
        parameters, which shows what that model gets wrong on data holding an effect.

    Raises
    ------
    PipelineError
        The manifest has no true parameters, or they are invalid.
    """
    tp = ds.rig.get("true_parameters")
    if not tp:
        raise PipelineError(f"{ds.root}/manifest.json has no rig.true_parameters (not virtual-rig data)")
    out = {}
    for sid, d in tp.items():
        try:
            p = params_from_json(d, f"{ds.root}/manifest.json: rig.true_parameters.{sid}")
        except ParamsJSONError as e:
            raise PipelineError(str(e)) from None
        if not with_effects:
            p = p.with_(**{s.name: 0.0 for s in EFFECT_SPECS})
        out[sid] = p
    return out


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
    res = fmpy.simulate_fmu(str(fmu), stop_time=float(de.stopTime), output_interval=float(de.stepSize),
                            output=["V", "I", "x", "F", "B", "contact"])
    cols = [("time_s", res["time"]), ("voltage_V", res["V"]), ("current_A", res["I"]),
            ("displacement_mm", res["x"] * 1e3), ("force_N", res["F"]), ("field_T", res["B"]),
            ("contact", res["contact"].astype(int))]
    csv = out / "default_step.csv"
    with open(csv, "w") as f:
        f.write(",".join(c for c, _ in cols) + "\n")
        for row in zip(*(v for _, v in cols)):
            f.write(",".join(f"{x:.9g}" for x in row) + "\n")
    png = out / "default_step.png"
    figures.plot_default_step(png, figures.StepTraces(res["time"], res["V"], res["I"], res["x"] * 1e3,
                                                      res["F"]))
    return csv, png, res


def write_protocol_outputs(runs: Sequence[replay.SampleRun], out: Path, synthetic: bool,
                           stem: str = "protocols") -> list[Path]:
    """Tables (CSV + Markdown, paper layout) and the per-sample figure set of protocol runs.

    Parameters
    ----------
    runs : sequence of harness.sim.replay.SampleRun
        Metric records and traces per sample.
    out : Path
        Output folder (created); figures go to ``out/figures/<sample>.png``.
    synthetic : bool
        Mark the figures "synthetic data".
    stem : str
        File-name stem of the tables.

    Returns
    -------
    list of Path
        The written files.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = [r for run in runs for r in run.records]
    written = list(tables.write_tables(records, out, stem))
    fig_dir = out / "figures"
    fig_dir.mkdir(exist_ok=True)
    for run in runs:
        path = fig_dir / f"{run.sample}.png"
        figures.plot_sample_figure(path, run.sample, run.traces, synthetic=synthetic)
        written.append(path)
    return written


def _surface_figures(results: dict, fig: Path) -> None:
    """Figure-6-like surface fit of each generalized parameter over filler fraction and diameter."""
    fits = generalize.fit_surfaces(results)
    ws = [r.wt_pct for r in results.values()]
    ds_ = [r.diameter_mm for r in results.values()]
    for name in generalize.FIT_PARAMS:
        vals = [getattr(r.params, name) for r in results.values()]
        grid = np.vectorize(lambda w, d, n=name: generalize.predict(fits, float(w), float(d))[n])
        figures.plot_surface(fig / f"surface_{name}.png",
                             figures.SurfaceData(name, SPEC_BY_NAME[name].unit, ws, ds_, vals), grid)


def identify_validate(ds: Dataset, out: Path, fmu: Path, settings: IdentifySettings | None = None,
                      job: JobSettings = JobSettings()) -> tuple[dict, list, list[Path]]:
    """Identify, validate through the FMU, generalize to the unseen samples; tables and figures.

    Identifies the training samples (paper section 3), runs T1-T8 of every sample with
    parameters through the FMU (Tables 3, 4), predicts the unseen samples from the surface
    fits and validates those (Table 5).

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

    Returns
    -------
    tuple of (dict, list, list of Path)
        ``{id: SampleIdentification}``, the validation records and the written files.
    """
    results, written = identify_mod.identify_and_write(ds, out, settings=settings, workers=job.workers,
                                                       progress=job.progress)
    fig = out / "figures"
    fig.mkdir(exist_ok=True)
    for sid, r in results.items():
        figures.plot_pareto(fig / f"pareto_{sid}.png", r.pareto.objectives, r.chosen,
                            list(identify_mod.OBJECTIVE_NAMES))
    params = {sid: r.params for sid, r in results.items()}
    unseen = {}
    gen = out / "generalization.json"
    if gen.exists():
        unseen = read_params_file(gen)
        _surface_figures(results, fig)
    runs = replay.run_dataset(ds, {**params, **unseen}, fmu_path=fmu, workers=job.workers, progress=job.progress)
    records = [r for run in runs for r in run.records]
    written += tables.write_tables(records, out, "validation", table5_samples=sorted(unseen) or None)
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
    written = diagnose_mod.write_diagnosis(diag, out)
    return diag, written


def summary_lines(diag) -> list[str]:
    """Cause and held-out gain of a diagnosis in a few lines for the terminal."""
    lines = [f"diagnosis (blind): cause = {diag.cause}"]
    for c in diag.causes:
        if isinstance(c, dict):
            nums = ", ".join(f"{k} {v:.4g}" for k, v in c.items()
                             if isinstance(v, (int, float)) and not isinstance(v, bool) and k != "rank")
            lines.append(f"  {c.get('rank', '-')}. {c.get('effect', c.get('name', '?'))}: {nums}")
    ov = (diag.gain or {}).get("overall_normalized_rmse")
    if isinstance(ov, dict) and "before" in ov and "after" in ov:
        lines.append(f"  held-out RMSE (in sensor noise floors), paper model -> extended model: "
                     f"{ov['before']:.3g} -> {ov['after']:.3g}")
    return lines


# --------------------------------------------------------------------------- jobs
def run(out: str | Path, settings: RunSettings = RunSettings(), fmu: str | Path | None = None,
        overwrite: bool = False, echo: Echo = _quiet) -> RunOutputs:
    """The main job: default step, synthetic dataset, identification, validation, diagnosis.

    Parameters
    ----------
    out : str or Path
        Output folder (:func:`harness.outputs.output_folder`): ``step/``, ``dataset/``,
        ``identification/`` and ``diagnosis/`` are written into it.
    settings : RunSettings
        Seed, samples, hidden effects, identification and diagnosis settings, workers.
    fmu : str, Path or None
        The FMU (None: the one built in the repository).
    overwrite : bool
        Allow reusing a non-empty output folder made by this tool.
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
    out = output_folder(out, overwrite)
    fmu = fmu_path(fmu)
    job, dset = settings.job, settings.dataset
    (out / "step").mkdir(exist_ok=True)
    csv, png, res = default_step(out / "step", fmu)
    echo(f"default step: x settles at {res['x'][-1] * 1e3:.3f} mm, I = {res['I'][-1]:.4f} A, "
         f"F = {res['F'][-1]:.4f} N  ->  {csv}, {png}")
    dpath = out / "dataset"
    rig.generate_dataset(dpath, seed=dset.seed, samples=dset.samples, fmu_path=fmu, workers=job.workers,
                         effects=dict(dset.hidden_effects), progress=job.progress, overwrite=True)
    ds = read_dataset(dpath)
    echo(f"synthetic dataset (virtual rig, seed {dset.seed}): {len(ds.samples)} samples, one hidden effect "
         f"(recorded in its manifest; the diagnosis does not read it) -> {dpath}")
    idir = out / "identification"
    idir.mkdir(exist_ok=True)
    results, _, written = identify_validate(ds, idir, fmu, settings.identify, job)
    echo(f"identified {len(results)} samples (R, L, Em, K1, K2 analytic; C, m by NSGA-II), validated T1-T8 "
         f"through the FMU, predicted the unseen samples: {len(written)} files -> {idir}")
    for name in ("validation_table3.md", "validation_table4.md", "validation_table5.md"):
        if (idir / name).exists():
            echo((idir / name).read_text())
    ddir = out / "diagnosis"
    ddir.mkdir(exist_ok=True)
    diag, written = run_diagnosis(ds, ddir, settings.diagnose, job)
    echo("\n".join(summary_lines(diag)))
    echo(f"diagnosis report: {ddir / 'diagnosis.md'} ({len(written)} files)")
    return RunOutputs(out=out, step=out / "step", dataset=dpath, identification=idir, diagnosis=ddir)


def generate(out: str | Path, settings: DatasetSettings = DatasetSettings(), fmu: str | Path | None = None,
             overwrite: bool = False, job: JobSettings = JobSettings()) -> Dataset:
    """Generate a synthetic dataset with the virtual rig into ``out``.

    Parameters
    ----------
    out : str or Path
        Dataset folder to write.
    settings : DatasetSettings
        Seed, samples and hidden effects.
    fmu : str, Path or None
        The FMU (None: the one built in the repository).
    overwrite : bool
        Allow replacing an existing dataset.
    job : JobSettings
        Workers and progress bars.

    Returns
    -------
    Dataset
        The generated dataset.

    Raises
    ------
    FMUNotFoundError
        The FMU does not exist.
    ValueError
        Unknown effect, bad magnitude, or ``out`` not writable without ``overwrite``.
    """
    return rig.generate_dataset(Path(out), seed=settings.seed, samples=settings.samples, fmu_path=fmu_path(fmu),
                                effects=dict(settings.hidden_effects), workers=job.workers,
                                progress=job.progress, overwrite=overwrite)


def check(dataset: str | Path, tests: Sequence[str] | None = None) -> str:
    """Read and validate a dataset; return its summary (``tests``: tests every sample must have).

    Raises
    ------
    harness.data.dataset.DataFormatError
        The dataset is invalid; the message names the file, line and column.
    """
    return dataset_summary(read_dataset(dataset, tests=tests or None))


def protocols(dataset: str | Path, out: str | Path, params_file: str | Path | None = None, *,
              with_effects: bool = False, fmu: str | Path | None = None, overwrite: bool = False,
              job: JobSettings = JobSettings()) -> list[Path]:
    """Run T1-T8 of every sample through the FMU and compare with the data: tables and figures.

    Parameters
    ----------
    dataset, out : str or Path
        Dataset folder and output folder (outside the dataset).
    params_file : str, Path or None
        Parameter file (:func:`load_params_file`); None: the virtual rig's true parameters.
    with_effects : bool
        With the true parameters: keep the rig's hidden effects (default: the paper's model only).
    fmu : str, Path or None
        The FMU (None: the one built in the repository).
    overwrite : bool
        Allow reusing a non-empty output folder made by this tool.
    job : JobSettings
        Workers and progress bars.

    Returns
    -------
    list of Path
        The written files.
    """
    ds, out = dataset_and_output(dataset, out, overwrite)
    params = load_params_file(params_file) if params_file else true_params(ds, with_effects=with_effects)
    runs = replay.run_dataset(ds, params, fmu_path=fmu_path(fmu), workers=job.workers, progress=job.progress)
    return write_protocol_outputs(runs, out, synthetic=ds.synthetic)


def identify(dataset: str | Path, out: str | Path, settings: IdentifySettings | None = None, *,
             fmu: str | Path | None = None, overwrite: bool = False,
             job: JobSettings = JobSettings()) -> tuple[dict, list, list[Path]]:
    """Identify a dataset's training samples, validate, generalize (:func:`identify_validate`).

    The output folder must lie outside the dataset (:func:`harness.outputs.dataset_and_output`).
    """
    ds, out = dataset_and_output(dataset, out, overwrite)
    return identify_validate(ds, out, fmu_path(fmu), settings, job)


def diagnose(dataset: str | Path, out: str | Path, overwrite: bool = False,
             job: JobSettings = JobSettings()) -> tuple:
    """Diagnose a dataset blind into ``out`` (outside the dataset); see :func:`run_diagnosis`."""
    ds, out = dataset_and_output(dataset, out, overwrite)
    return run_diagnosis(ds, out, job=job)


def build(params_file: str | Path, out: str | Path, settings: BuildSettings = BuildSettings(),
          overwrite: bool = False) -> tuple[Path, str]:
    """Bake one sample's parameters (paper + effects) into an FMU as its start values.

    Parameters
    ----------
    params_file : str or Path
        identification.json, generalization.json or extended_params.json.
    out : str or Path
        FMU file to write (name ending in ``.fmu``).
    settings : BuildSettings
        Sample, gap [mm], blocked mode, status shim.
    overwrite : bool
        Replace an existing ``out``.

    Returns
    -------
    tuple of (Path, str)
        The FMU written and the sample id baked in.

    Raises
    ------
    ParamsFileError, SampleChoiceError, harness.outputs.OutputPathError
        Bad parameter file, no such sample, or ``out`` not a new ``.fmu`` path.
    """
    import build_fmu
    params = load_params_file(params_file)
    sid = settings.sample or (next(iter(params)) if len(params) == 1 else None)
    if sid is None or sid not in params:
        raise SampleChoiceError(f"choose one of {sorted(params)}")
    out = Path(out)
    if out.suffix != ".fmu":
        raise OutputPathError(f"{out}: expected a file name ending in .fmu")
    if out.exists() and not overwrite:
        raise OutputPathError(f"{out} exists; pass --overwrite to replace it")
    p = params[sid].with_(r0=settings.gap_mm / 1000.0, blocked=settings.blocked)
    d = asdict(p)
    start = {s.name: d[s.name] for s in SPECS + EFFECT_SPECS}
    start["blocked"] = bool(p.blocked)
    return build_fmu.build(out, start_values=start, status_shim=settings.status_shim), sid


def crosscheck_make(out: str | Path, fmu: str | Path | None = None, overwrite: bool = False) -> list[Path]:
    """Write FMI cross-check style reference files (inputs, parameters, reference results) to ``out``."""
    out = output_folder(out, overwrite)
    return crosscheck_mod.make_references(out, fmu_path=fmu_path(fmu))


def crosscheck_check(ref_dir: str | Path, fmu: str | Path | None = None) -> crosscheck_mod.Report:
    """Check an FMU against reference files made by :func:`crosscheck_make`; the report says pass/fail."""
    return crosscheck_mod.check_references(Path(ref_dir), fmu_path=fmu_path(fmu))
