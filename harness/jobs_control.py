"""The ``control`` job (``mpc-actuator control``): the closed-loop study on any sample of a parameter file, with its
report, into an output folder; :func:`control_settings` reads and checks the files before any work (also used by
the chain's control step, :mod:`harness.chain_control`)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from fmu_src.specs import EFFECT_SPECS, active_effects
from harness.control.study import StudySettings, run_study
from harness.jobs import ParamsFileError, SampleChoiceError, load_params_file
from harness.outputs import check_output_target, final_paths, output_transaction
from harness.pipeline import PipelineError, fmu_path
from harness.report.control_md import write_control_report

__all__ = ["control_settings", "control"]


def _sample_of(option: str, path, sample: str | None):
    """(sample id, Params) of ``sample`` in the parameter file ``path`` given to ``option``; its only sample when
    ``sample`` is None. PipelineError naming the option, file and sample (missing or bad file, unknown sample)."""
    try:
        params = load_params_file(path)
    except ParamsFileError as e:
        raise PipelineError(f"{option} {e}") from None
    if sample is None:
        if len(params) == 1:
            return next(iter(params.items()))
        raise SampleChoiceError(f"{option} {path} holds {len(params)} samples ({', '.join(params)}); choose one "
                                f"with --sample")
    if sample not in params:
        raise SampleChoiceError(f"sample {sample} is not in {option} {path} (it holds {', '.join(params)})")
    return sample, params[sample]


def _without_effects(p):
    return p.with_(**{s.name: 0.0 for s in EFFECT_SPECS})


def control_settings(settings: StudySettings, params_file=None, extended_file=None, sample: str | None = None,
                     effect_asked: bool = False) -> StudySettings:
    """``settings`` with the sample of ``params_file`` and the extended model of ``extended_file`` (see
    :func:`control`), read and checked before any work.

    Parameters
    ----------
    settings : StudySettings
        The study's settings to complete.
    params_file, extended_file : str, Path or None
        The plant's and the extended model's parameter files (see :func:`control`).
    sample : str or None
        The sample of those files.
    effect_asked : bool
        ``settings.effect`` was asked for explicitly.

    Returns
    -------
    StudySettings
    """
    if params_file is not None:
        sid, p = _sample_of("--params", params_file, sample)
        eff = {s.name: float(getattr(p, s.name)) for s in EFFECT_SPECS if getattr(p, s.name) != 0.0}
        eff = eff if active_effects(p) else {}   # e.g. a time constant without its effect's strength: off
        if eff and effect_asked and settings.effect is not None:
            raise PipelineError(f"--effect {settings.effect}: sample {sid} of --params {params_file} has effects of "
                                f"its own ({', '.join(active_effects(p))}); the plant is that sample with them "
                                f"(leave --effect out)")
        settings = replace(settings, base=_without_effects(p), sample_effects=eff or None,
                           effect=settings.effect if not eff else None, sample=f"{sid} of {params_file}")
    if extended_file is not None:
        sid, ext = _sample_of("--extended-params", extended_file, sample)
        if params_file is None:
            settings = replace(settings, base=_without_effects(ext), sample=f"{sid} of {extended_file}")
        settings = replace(settings, extended_params=ext)
    return settings


def control(out: str | Path, settings: StudySettings, overwrite: bool = False, extended_file: str | Path | None = None,
            sample: str | None = None, progress=None, params_file: str | Path | None = None,
            effect_asked: bool = False) -> list[Path]:
    """The closed-loop control study (``harness.control.study``) with its report, into the folder ``out``.

    ``params_file`` (identification.json, generalization.json, extended_params.json, any parameter file) with
    ``sample``: the study runs on that sample. Its parameters without effects are the paper model; with effects
    in the file (a diagnosis's extended_params.json) the plant is the sample with them and the extended model
    the same (``settings.effect`` is dropped, or an error if ``effect_asked``: the hidden effect was asked for
    explicitly), else the plant is the sample with ``settings.effect``.
    ``extended_file`` with ``sample``: the extended model is that file's sample, its own parameters, effects
    included (an imperfect diagnosis against the hidden effect's plant); without ``params_file`` the paper model
    is the same sample without effects.

    Parameters
    ----------
    out : str or Path
        Output folder (control.md, control.json, figures).
    settings : StudySettings
        The FMUs, the plant's effect, the task (stroke [m], frequency [Hz]), the MPC's settings.
    overwrite : bool
        Replace an earlier output of this tool in ``out``.
    extended_file : str, Path or None
        A parameter file whose ``sample`` is the extended model (None: the plant's own model).
    sample : str or None
        The sample of ``params_file`` / ``extended_file`` (None: the file's only sample).
    progress : callable or None
        Called with progress lines (None: quiet).
    params_file : str, Path or None
        A parameter file whose ``sample`` is the plant (None: ``settings.base``).
    effect_asked : bool
        ``settings.effect`` was asked for explicitly (an error if the sample has effects of its own).

    Returns
    -------
    list of Path
        The written files.

    Raises
    ------
    PipelineError, SampleChoiceError, harness.outputs.OutputPathError, ValueError
        Bad parameter file or sample (naming the option, file and sample), ``out`` not writable as an output
        folder, bad settings or FMUs.
    """
    settings = control_settings(settings, params_file, extended_file, sample, effect_asked)
    settings = replace(settings, actuator_fmu=str(fmu_path(settings.actuator_fmu or None)))
    if not Path(settings.controller_fmu).is_file():
        raise PipelineError(f"controller FMU {settings.controller_fmu} not found; build it with "
                            "`python build_fmu.py --controller`")
    target = check_output_target(out, overwrite)
    with output_transaction(target, overwrite) as tmp:
        res = run_study(settings, progress=progress)
        written = write_control_report(tmp, res, settings)
    return final_paths(written, tmp, target)
