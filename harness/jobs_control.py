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

__all__ = ["control_settings", "control", "estimate"]


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


def estimate(dataset, out: str | Path, params_file, test: str, sample: str | None = None, overwrite: bool = False,
             noise_factor: float = 1.0) -> tuple[list[Path], str]:
    """Filter one measured record with the EKF (``harness.control.estimator.filter_record``): the sample's model of
    ``params_file`` (effects included) at the record's gap, readings x (displacement) and I (current), the force
    too where the record has it, noise levels from the dataset's noise floors (times ``noise_factor``). Writes
    estimate.csv and figures/estimate.png into ``out``; returns the paths and a one-line summary.

    Raises
    ------
    PipelineError, SampleChoiceError, DataFormatError, OutputPathError
        Missing or bad dataset, parameter file, sample or test (naming them), ``out`` not writable.
    """
    import numpy as np

    from harness.control.estimator import EstimatorError, NoiseLevels, filter_record
    from harness.data.dataset import read_dataset
    from harness.report.estimate_out import write_estimate

    sid, p = _sample_of("--params", params_file, sample)
    ds = read_dataset(dataset, samples=[sid])   # DataFormatError naming the sample when it is not there
    rec = ds.samples[0].tests.get(test)
    if rec is None:
        raise PipelineError(f"--test {test}: sample {sid} of {dataset} has no such test (it has "
                            f"{', '.join(ds.samples[0].tests)})")
    if not hasattr(rec, "time_s"):
        raise PipelineError(f"--test {test} is a gap sweep, not a time series: nothing to filter")
    if rec.displacement_mm is None or p.blocked:
        raise PipelineError(f"--test {test}: the estimator needs a displacement record (a blocked test has none)")
    force = rec.force_N is not None and bool(np.all(np.isfinite(rec.force_N)))
    try:
        noise = NoiseLevels.from_rig(ds.rig, data=ds, force=force).scaled(noise_factor)
        model = p.with_(r0=rec.gap_mm / 1000.0).validated()
        z = [rec.displacement_mm / 1000.0, rec.current_A] + ([rec.force_N] if force else [])
        est = filter_record(model, rec.time_s, rec.voltage_V, np.column_stack(z), noise)
    except (EstimatorError, ValueError) as e:
        raise PipelineError(f"estimate {sid} {test}: {e}") from None
    measured = {"V_V": rec.voltage_V, "x_read_m": rec.displacement_mm / 1000.0, "I_read_A": rec.current_A}
    if force:
        measured["F_read_N"] = rec.force_N
    target = check_output_target(out, overwrite)
    with output_transaction(target, overwrite) as tmp:
        written = write_estimate(tmp, est, measured, f"EKF estimate: sample {sid}, {test}, gap {rec.gap_mm:g} mm "
                                                     f"(noise x {1e6 * noise.sigma_x_m:.3g} um, I "
                                                     f"{1e3 * noise.sigma_I_A:.3g} mA)")
    v = est["x"][:, est["names"].index("v")]
    summary = (f"estimated {', '.join(est['names'])} of sample {sid}, {test} ({len(v)} samples); "
               f"peak |v| {1e3 * float(np.max(np.abs(v))):.3g} mm/s")
    return final_paths(written, tmp, target), summary

