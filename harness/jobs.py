"""The command line's single jobs as library functions (the main job is :func:`harness.pipeline.run`).

:func:`generate` (virtual-rig dataset), :func:`check` (read and validate a dataset), :func:`protocols`
(T1-T8 through the FMU against the data), :func:`identify` (identification, validation,
generalization), :func:`diagnose` (blind diagnosis), :func:`build` (bake parameters into an FMU),
:func:`import_lab` (lab files into a dataset), :func:`crosscheck_make` / :func:`crosscheck_check` (FMI cross-check
style reference files). Jobs on a dataset write into an output folder outside it
(:func:`harness.outputs.dataset_and_output`). The other jobs: ``control`` in :mod:`harness.jobs_control`,
``uncertainty`` and ``design`` in :mod:`harness.jobs_design`.
"""
from __future__ import annotations

import warnings

from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from fmu_src.model import check_integrable
from fmu_src.specs import EFFECT_SPECS, SPECS
from harness.analysis.validation import crosscheck as crosscheck_mod
from harness.analysis.validation import run as validation
from harness.analysis.identification.conventions import infer_conventions, write_conventions
from harness.analysis.diagnosis import DiagnoseSettings, declared_unseen
from harness.analysis.identification.identify import SampleChoice, select_samples
from harness.analysis.identification.settings import IdentifySettings
from harness.sim import virtual_rig
from harness.data.dataset import Dataset, dataset_summary, read_dataset
from harness.data.paramsjson import ParamsJSONError, params_from_json, read_params_file
from harness.data.labimport import import_lab_files
from harness.data.labimport.mapping import load_mapping
from harness.outputs import (OutputPathError, check_output_file, check_output_target, dataset_and_output,
                             file_transaction, final_paths, guard_not_inside, output_transaction)
from harness.pipeline import (DatasetSettings, JobSettings, PipelineError, fmu_path, identify_validate,
                              run_diagnosis)
from harness.report import figures, tables

__all__ = [
    "ParamsFileError", "SampleChoiceError", "BuildSettings", "load_params_file", "load_params_files", "true_params",
    "write_protocol_outputs", "generate", "check", "protocols", "identify", "diagnose", "build",
    "crosscheck_make", "crosscheck_check", "import_lab",
]


class ParamsFileError(PipelineError):
    """A parameter file given to a job is unreadable or invalid; the message starts with its path."""


class SampleChoiceError(PipelineError):
    """The sample to use is missing or not in the parameter file."""


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
    fmi : str
        FMI version of the FMU: "2" or "3" (pythonfmu3, see README).
    """
    sample: str | None = None
    gap_mm: float = 9.0
    blocked: bool = False
    status_shim: bool = True
    fmi: str = "2"

    def __post_init__(self):
        if self.fmi not in ("2", "3"):
            raise ValueError(f"fmi must be '2' or '3', got {self.fmi!r}")


# --------------------------------------------------------------------------- inputs
def load_params_file(path: str | Path) -> dict:
    """Parameters per sample ``{id: Params}`` from a parameter file.

    Reads identification.json, generalization.json or extended_params.json
    (:func:`harness.data.paramsjson.read_params_file`: layout, keys with units).

    Parameters
    ----------
    path : str or Path
        The parameter file.

    Returns
    -------
    dict
        {sample id: Params}.

    Raises
    ------
    ParamsFileError
        The file is unreadable or invalid, or the model refuses a sample's parameters (e.g. a gap r0
        too large for the coil); the message names the file, sample and key or parameter.
    """
    try:
        params = read_params_file(path)
    except ParamsJSONError as e:
        raise ParamsFileError(str(e)) from None
    for sid, p in params.items():
        try:
            check_integrable(p)              # values valid one by one but refused by the model (e.g. r0 = 1e300)
        except ValueError as e:
            raise ParamsFileError(f"{path}: sample {sid}: {e}") from None
    return params


def load_params_files(paths) -> dict:
    """Parameters per sample ``{id: Params}`` from one or several parameter files (e.g. identification.json and
    generalization.json): every sample's parameters come from the file that holds it.

    Raises
    ------
    ParamsFileError
        A file is unreadable or invalid (:func:`load_params_file`), or a sample is in two files with different
        parameters (the message names the sample and both files; the same values in both are accepted).
    """
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    out, where = {}, {}
    for path in paths:
        for sid, p in load_params_file(path).items():
            if sid in out and out[sid] != p:
                diff = [n for n in p.__dataclass_fields__ if getattr(p, n) != getattr(out[sid], n)]
                raise ParamsFileError(f"{where[sid]} and {path} both hold sample {sid}, with different parameters "
                                      f"({', '.join(diff)}); give it in one file only")
            out.setdefault(sid, p)
            where.setdefault(sid, path)
    return out


def params_source(params_file) -> str:
    """"--params FILE" or "--params A, B" for the messages about one or several parameter files."""
    paths = [params_file] if isinstance(params_file, (str, Path)) else list(params_file)
    return "--params " + ", ".join(str(p) for p in paths)


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


# --------------------------------------------------------------------------- jobs
def write_protocol_outputs(runs: Sequence[validation.SampleRun], out: Path, synthetic: bool,
                           stem: str = "protocols", skipped: dict[str, str] | None = None) -> list[Path]:
    """Tables (CSV + Markdown, paper layout) and the per-sample figure set of protocol runs.

    Parameters
    ----------
    runs : sequence of harness.analysis.validation.run.SampleRun
        Metric records and traces per sample.
    out : Path
        Output folder (created); figures go to ``out/figures/<sample>.png``.
    synthetic : bool
        Mark the figures "synthetic data".
    stem : str
        File-name stem of the tables.
    skipped : dict of str to str or None
        Samples of the dataset left out, {id: reason}: listed under every Markdown table.

    Returns
    -------
    list of Path
        The written files.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = [r for run in runs for r in run.records]
    written = list(tables.write_tables(records, out, stem, skipped=skipped or None))
    fig_dir = out / "figures"
    fig_dir.mkdir(exist_ok=True)
    for run in runs:
        path = fig_dir / f"{run.sample}.png"
        figures.plot_sample_figure(path, run.sample, run.traces, synthetic=synthetic)
        written.append(path)
    return written


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
        Replace an earlier output of this tool in ``out`` (never a folder it did not make).
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
    harness.outputs.OutputPathError
        ``out`` may not be written (checked before any simulation): a file, a folder this tool did
        not make, an earlier output without ``overwrite``, or another run is writing it.
    ValueError
        Unknown effect or bad magnitude.
    """
    target = check_output_target(out, overwrite)
    fmu = fmu_path(fmu)
    with output_transaction(target, overwrite) as tmp:
        ds = virtual_rig.generate_dataset(tmp, seed=settings.seed, samples=settings.samples, fmu_path=fmu,
                                          effects=dict(settings.hidden_effects), workers=job.workers,
                                          progress=job.progress, overwrite=False)
    return replace(ds, root=target)


def check(dataset: str | Path, tests: Sequence[str] | None = None) -> str:
    """Read and validate a dataset; return its summary.

    Parameters
    ----------
    dataset : str or Path
        The dataset folder.
    tests : sequence of str or None
        Tests every sample must have (e.g. ``["T3", "T5", "T8"]``); None: no requirement.

    Returns
    -------
    str
        The summary (:func:`harness.data.dataset.dataset_summary`).

    Raises
    ------
    harness.data.dataset.DataFormatError
        The dataset is invalid; the message names the file, line and column.
    """
    return dataset_summary(read_dataset(dataset, tests=tests or None))


def protocols(dataset: str | Path, out: str | Path, params_file=None, *,
              with_effects: bool = False, fmu: str | Path | None = None, overwrite: bool = False,
              job: JobSettings = JobSettings(), skip_missing: bool = False) -> list[Path]:
    """Run T1-T8 of every sample through the FMU and compare with the data: tables and figures.

    Parameters
    ----------
    dataset, out : str or Path
        Dataset folder and output folder (outside the dataset).
    params_file : str, Path, a sequence of them, or None
        Parameter file(s) (:func:`load_params_files`: each sample's parameters from the file that holds it, e.g.
        identification.json and generalization.json); None: the virtual rig's true parameters.
    with_effects : bool
        With the true parameters: keep the rig's hidden effects (default: the paper's model only).
    fmu : str, Path or None
        The FMU (None: the one built in the repository).
    overwrite : bool
        Allow reusing a non-empty output folder made by this tool.
    job : JobSettings
        Workers and progress bars.
    skip_missing : bool
        Run only the samples that have parameters in ``params_file``; the others are reported by a
        :class:`MissingParamsWarning` and listed as skipped under every table. Without it, a sample of
        the dataset without parameters is an error (nothing is dropped silently).

    Returns
    -------
    list of Path
        The written files.

    Raises
    ------
    MissingParamsError
        Before any work: samples of the dataset have no parameters in ``params_file`` and
        ``skip_missing`` is false, or no sample has parameters.
    """
    ds, target = dataset_and_output(dataset, out, overwrite)
    params = load_params_files(params_file) if params_file else true_params(ds, with_effects=with_effects)
    skipped = params_coverage(ds, params, params_file, skip_missing)
    fmu = fmu_path(fmu)
    with output_transaction(target, overwrite, inputs=(dataset,)) as tmp:
        used = {s.id: params[s.id] for s in ds.samples if s.id not in skipped}
        runs = validation.run_dataset(ds, used, fmu_path=fmu,
                                      workers=job.workers, progress=job.progress)
        written = write_protocol_outputs(runs, tmp, synthetic=ds.synthetic, skipped=skipped)
        written += write_conventions(infer_conventions(ds, need_coil_radius=False), tmp, "protocols_conventions")
    return final_paths(written, tmp, target)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


class MissingParamsError(PipelineError):
    """Samples of a dataset have no parameters in the parameter file given to a protocols run."""


class MissingParamsWarning(UserWarning):
    """Samples of a dataset left out of a protocols run because the parameter file has none for them."""


def params_coverage(ds: Dataset, params: dict, params_file, skip_missing: bool) -> dict[str, str]:
    """The dataset's samples without parameters, {id: reason}; an error unless ``skip_missing``.

    Parameters for samples that are not in the dataset are reported by a :class:`MissingParamsWarning`
    (they are not used).

    Raises
    ------
    MissingParamsError
        Samples lack parameters and ``skip_missing`` is false, or no sample of the dataset has any.
    """
    ids = [s.id for s in ds.samples]
    missing = [i for i in ids if i not in params]
    source = params_source(params_file) if params_file else "the virtual rig's true parameters"
    unused = sorted(set(params) - set(ids))
    if unused:
        warnings.warn(f"{source} has parameters for {', '.join(unused)}, which {ds.root} does not hold; "
                      f"they are not used", MissingParamsWarning, stacklevel=3)
    if len(missing) == len(ids):
        raise MissingParamsError(f"{source} has parameters for none of the samples of {ds.root} ({', '.join(ids)})")
    n_run = len(ids) - len(missing)
    if missing and not skip_missing:
        raise MissingParamsError(
            f"{source} has no parameters for {_count(len(missing), 'sample')} of the {len(ids)} of {ds.root}: "
            f"{', '.join(missing)}; pass --skip-missing to run only the {_count(n_run, 'sample')} it has "
            f"(the others are then listed as skipped under every table)")
    if missing:
        warnings.warn(f"skipped {_count(len(missing), 'sample')} of {ds.root} without parameters in {source}: "
                      f"{', '.join(missing)}", MissingParamsWarning, stacklevel=3)
    return {i: f"no parameters in {source}" for i in missing}


def identify(dataset: str | Path, out: str | Path, settings: IdentifySettings | None = None, *,
             fmu: str | Path | None = None, overwrite: bool = False, job: JobSettings = JobSettings(),
             choice: SampleChoice = SampleChoice()) -> tuple[dict, list, list[Path]]:
    """Identify a dataset's training samples, validate, generalize (:func:`identify_validate`).

    The output folder must lie outside the dataset (:func:`harness.outputs.dataset_and_output`);
    the samples (``choice``: declared unseen, incomplete ones skipped or an error) are checked
    before any work, and the folder is written as a transaction.

    Parameters
    ----------
    dataset : str or Path
        The dataset folder.
    out : str or Path
        Output folder (identification.json, generalization.json, validation tables, figures).
    settings : IdentifySettings or None
        NSGA-II size, weights, choice of (C, m) (None: the defaults, 64 x 60).
    fmu : str, Path or None
        The FMU the validation runs (None: the one built in the repository).
    overwrite : bool
        Replace an earlier output of this tool in ``out``.
    job : JobSettings
        Workers and progress bars.
    choice : SampleChoice
        Which samples are identified (declared unseen ones are generalized instead).

    Returns
    -------
    tuple
        (results per sample, validation metric records, written paths).
    """
    ds, target = dataset_and_output(dataset, out, overwrite)
    fmu = fmu_path(fmu)
    select_samples(ds, None, choice)
    with output_transaction(target, overwrite, inputs=(dataset,)) as tmp:
        results, records, written = identify_validate(ds, tmp, fmu, settings, job, choice)
    return results, records, final_paths(written, tmp, target)


def diagnose(dataset: str | Path, out: str | Path, overwrite: bool = False,
             job: JobSettings = JobSettings(), unseen: Sequence[str] | None = None, discover: bool = True,
             fit_budget_s: float | None = None) -> tuple:
    """Diagnose a dataset blind into ``out`` (outside the dataset); see :func:`run_diagnosis`.

    Parameters
    ----------
    dataset : str or Path
        The dataset folder.
    out : str or Path
        Output folder (diagnosis.md, diagnosis.json, extended_params.json, tables, residual figures).
    overwrite : bool
        Replace an earlier output of this tool in ``out``.
    job : JobSettings
        Workers and progress bars.
    unseen : sequence of str or None
        Sample ids declared unseen (held-out samples: never used to fit the shared effect parameters;
        ``harness.analysis.diagnosis.heldout``); checked before anything is written.
    discover : bool
        Run the discovery stage (``harness.analysis.discovery``) when the catalogue leaves structure.
    fit_budget_s : float or None
        [s] CPU time of all the fits (``DiagnoseSettings.fit_budget_s``; None: its default); fits it cuts short
        are listed in the report.

    Returns
    -------
    tuple
        (the diagnosis, written paths).
    """
    ds, target = dataset_and_output(dataset, out, overwrite)
    budget = {} if fit_budget_s is None else {"fit_budget_s": float(fit_budget_s)}
    settings = DiagnoseSettings(workers=job.workers, unseen=tuple(unseen) if unseen is not None else None,
                                discover=discover, **budget)
    declared_unseen([s.id for s in ds.samples], settings.unseen)
    with output_transaction(target, overwrite, inputs=(dataset,)) as tmp:
        diag, written = run_diagnosis(ds, tmp, settings=settings, job=job)
    return diag, final_paths(written, tmp, target)


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
        Replace an existing ``out``, only an FMU this tool made (its modelDescription's author is
        mpc-actuator). The FMU is written beside ``out`` and moved into place at the end, under the
        lock ``<out>.lock`` (:func:`harness.outputs.file_transaction`).

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
    kind = "an FMU made by mpc-actuator"
    check_output_file(out, overwrite, fmu_made_by_us, kind)
    p = params[sid].with_(r0=settings.gap_mm / 1000.0, blocked=settings.blocked)
    try:
        check_integrable(p.validated())
    except ValueError as e:
        raise PipelineError(f"--gap-mm {settings.gap_mm:g}: {e}") from None
    d = asdict(p)
    start = {s.name: d[s.name] for s in SPECS + EFFECT_SPECS}
    start["blocked"] = bool(p.blocked)
    use_installed_pythonfmu()
    with file_transaction(out, overwrite, fmu_made_by_us, kind) as tmp:
        build_fmu.build(tmp, start_values=start, status_shim=settings.status_shim, fmi=settings.fmi)
    return out.resolve(), sid


def use_installed_pythonfmu() -> None:
    """Let pythonfmu's builder copy the installed distribution's binaries: in a process where a pythonfmu FMU was
    instantiated, ``import pythonfmu`` can find that FMU's copy of the package, which has none, and a build then
    made an FMU without binaries (run DATASET's FMU step after in-process FMU runs)."""
    from importlib.metadata import distribution
    from pythonfmu import builder
    if not any((Path(builder.HERE) / "resources" / "binaries").rglob("*.so")):
        builder.HERE = Path(distribution("pythonfmu").locate_file("pythonfmu"))


def fmu_made_by_us(path: str | Path) -> bool:
    """Whether ``path`` is an FMU this project built (a zip whose modelDescription.xml names the author
    ``mpc-actuator``): only such a file may be replaced by ``mpc-actuator build --overwrite``."""
    import xml.etree.ElementTree as ET
    import zipfile
    try:
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return False
    return root.get("author") == "mpc-actuator"


def import_lab(mapping: str | Path, out: str | Path, overwrite: bool = False) -> Path:
    """Import lab files named by a mapping file into a dataset folder ``out``, written as a transaction.

    :func:`harness.data.labimport.import_lab_files` into the temporary folder; ``out`` must not hold
    the mapping or an input file (they would go with an earlier output that ``overwrite`` replaces), and
    a folder holding measured data is never replaced.

    Parameters
    ----------
    mapping : str or Path
        The mapping file (JSON, format ``mpc-actuator-labimport/1``): the rig, the samples and, per test, the lab
        file, its columns and units, and the test's conditions (the user guide's Data format).
    out : str or Path
        The dataset folder to write.
    overwrite : bool
        Replace an earlier output of this tool in ``out`` (never a folder holding measured data).

    Returns
    -------
    Path
        The dataset folder written.

    Raises
    ------
    harness.outputs.OutputPathError
        ``out`` may not be written (see :func:`harness.outputs.output_transaction`).
    harness.data.labimport.LabImportError
        The mapping or a lab file is invalid; ``out`` is left as it was.
    """
    target = check_output_target(out, overwrite)
    m, base, mfile = load_mapping(mapping)
    inputs = [Path(spec["file"]) if Path(spec["file"]).is_absolute() else base / spec["file"]
              for s in m["samples"] for spec in s["tests"].values()] + ([Path(mfile)] if mfile is not None else [])
    for p in inputs:
        try:
            guard_not_inside(p, target)
        except OutputPathError:
            raise OutputPathError(f"{target} holds the input file {p}; choose another output folder") from None
    with output_transaction(target, overwrite) as tmp:
        import_lab_files(mapping, tmp, overwrite=False)
    return target


def crosscheck_make(out: str | Path, fmu: str | Path | None = None, overwrite: bool = False) -> list[Path]:
    """Write FMI cross-check style reference files (inputs, parameters, reference results) to ``out``."""
    target = check_output_target(out, overwrite)
    fmu = fmu_path(fmu)
    with output_transaction(target, overwrite) as tmp:
        written = crosscheck_mod.make_references(tmp, fmu_path=fmu)
    return final_paths(written, tmp, target)


def crosscheck_check(ref_dir: str | Path, fmu: str | Path | None = None) -> crosscheck_mod.Report:
    """Check an FMU against reference files made by :func:`crosscheck_make`; the report says pass/fail."""
    return crosscheck_mod.check_references(Path(ref_dir), fmu_path=fmu_path(fmu))
