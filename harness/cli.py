"""Command-line interface: a thin layer over the library functions.

    mpc-actuator run --out DIR            the main job on the default (synthetic) dataset
    mpc-actuator generate --out DIR       virtual-rig dataset
    mpc-actuator check DATASET            read and validate a dataset
    mpc-actuator import MAPPING --out DIR lab files (CSV/TSV, LVM, TDMS, MAT) -> dataset
    mpc-actuator protocols DATASET --out DIR [--params identification.json | --true-params]
    mpc-actuator crosscheck make --out DIR / crosscheck check DIR

Each subcommand parses its options and calls one function of :mod:`harness.pipeline` (the main job) or
:mod:`harness.jobs` (``control``: :mod:`harness.jobs_control`; ``uncertainty``, ``design``:
:mod:`harness.jobs_design`); the errors a user can fix end the program with one line ``error: ...`` (exit
code 1; ``--debug`` also prints the traceback); Ctrl-C ends it with ``interrupted: <out> left as it
was`` (exit code 130).
"""
from __future__ import annotations

import argparse
import os
import sys
import traceback
import warnings
from contextlib import contextmanager
from pathlib import Path

from harness import jobs, jobs_control, jobs_design, pipeline
from harness.analysis.identification.identify import IncompleteSampleWarning, SampleChoice
from harness.analysis.identification.settings import IdentifySettings
from harness.analysis.core.sweep import SweepError
from harness.data import rig
from harness.data.dataset import DataFormatError
from harness.data.protocol import BLOCKED_TESTS, TIME_SERIES_TESTS
from harness.data.labimport import LabImportError
from harness.options import OptionValueError, choice, number
from harness.outputs import OutputPathError, stdout_closed
from harness import signals as _signals
from harness.signals import interrupt_exit_code, interrupt_word

# load_params_file below keeps the CLI's message for a bad parameter file (tests/data/test_paramsjson.py and
# tests/analysis/test_identify.py check it).


def _text(e: BaseException) -> str:
    """The message of an error with its notes, e.g. "(OUT left as it was)" from the output transaction."""
    return str(e) + "".join(f" ({n})" for n in getattr(e, "__notes__", ()))


_PACKAGES = tuple(str(Path(m.__file__).resolve().parent) for m in (jobs,)) + (
    str(Path(__file__).resolve().parent.parent / "fmu_src"),)


def raised_by_a_check(e: BaseException) -> bool:
    """True when ``e`` was raised by a ``raise`` statement of this project's code (a validation that names what
    is wrong), False when it came out of an operation or a library (numpy's "operands could not be broadcast",
    a scipy routine's refusal): a defect, reported as unexpected. Typed errors of the project are always
    checks; this tells the plain ``ValueError`` of a check from one of numpy's."""
    tb = traceback.extract_tb(e.__traceback__)
    if not tb:
        return True
    last = tb[-1]
    return (Path(last.filename).resolve().as_posix().startswith(_PACKAGES)
            and (last.line or "").lstrip().startswith("raise"))


@contextmanager
def _user_errors(*more: type[BaseException]):
    """Turn the errors a user can fix (and ``more``) into ``SystemExit("error: ...")``; an exception of a
    ``more`` type that was not raised by a check of the project (:func:`raised_by_a_check`: e.g. numpy's
    broadcast error, a plain ValueError) is a defect and goes on to ``main``'s "error: unexpected ..."."""
    try:
        yield
    except OutputPathError as e:
        raise SystemExit(f"error: --out {_text(e)}") from e
    except jobs.ParamsFileError as e:
        raise SystemExit(f"error: --params {_text(e)}") from e
    except jobs.SampleChoiceError as e:
        raise SystemExit(f"error: --sample: {_text(e)}") from e
    except pipeline.PipelineError as e:
        raise SystemExit(f"error: {_text(e)}") from e
    except more as e:
        if type(e) in (ValueError, TypeError, KeyError, IndexError) and not raised_by_a_check(e):
            raise
        raise SystemExit(f"error: {_text(e)}") from e


def load_params_file(path) -> dict:
    """``harness.jobs.load_params_file``, ending the program with ``error: --params ...`` on bad input."""
    with _user_errors():
        return jobs.load_params_file(path)


def _job(args) -> pipeline.JobSettings:
    return pipeline.JobSettings(workers=args.workers, progress=not args.quiet)


def _parse_sample(s: str):
    try:
        w, d = s.upper().lstrip("W").split("-D")
        return float(w), float(d)
    except ValueError:
        raise SystemExit(f"error: sample {s!r}: expected the form W20-D45") from None


def _parse_effect(s: str):
    name, _, mag = s.partition("=")
    try:
        return name, float(mag)
    except ValueError:
        raise SystemExit(f"error: --effect {s!r}: expected NAME=MAGNITUDE") from None


def cmd_run(args):
    if args.dataset is not None:
        return _cmd_run_chain(args)
    chain_only = [o for o, v in (("--settings", args.settings), ("--skip", args.skip),
                                 ("--control-sample", args.control_sample), ("--unseen", args.unseen),
                                 ("--design-stroke-mm", args.design_stroke_mm),
                                 ("--design-max-power-W", args.design_max_power_W)) if v]
    if chain_only:
        raise SystemExit(f"error: {chain_only[0]} needs a DATASET (`mpc-actuator run DATASET --out DIR ...`); "
                         f"without one, run is the main job on the default synthetic dataset")
    with _user_errors():
        pipeline.run(args.out, pipeline.RunSettings(dataset=pipeline.DatasetSettings(
            seed=args.seed, hidden_effects=tuple(pipeline.DEFAULT_HIDDEN_EFFECT.items())), job=_job(args)),
            fmu=args.fmu, overwrite=args.overwrite, echo=print)


def _cmd_run_chain(args):
    """``run DATASET``: the whole chain on the user's dataset (harness.chain)."""
    from harness import chain
    with _user_errors(DataFormatError, ValueError, SweepError):
        file_values = chain.load_settings_file(args.settings) if args.settings else {}
        options = {"run": {"skip": tuple(args.skip or ())},
                   "identify": {"pop_size": args.pop_size, "generations": args.generations,
                                "unseen": tuple(args.unseen) if args.unseen else None},
                   "control": {"sample": args.control_sample},
                   "design": {"stroke_mm": args.design_stroke_mm, "max_power_W": args.design_max_power_W}}
        settings = chain.options_to_settings(file_values, options, _job(args))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", IncompleteSampleWarning)
            chain.run_chain(args.dataset, args.out, settings, fmu=args.fmu, overwrite=args.overwrite,
                            echo=(lambda _line: None) if args.quiet else print)
    _print_warnings(caught, IncompleteSampleWarning)


def cmd_generate(args):
    effects = dict(_parse_effect(e) for e in (args.effect or []))
    samples = rig.ALL_SAMPLES if not args.samples else [_parse_sample(s) for s in args.samples]
    with _user_errors(ValueError):
        settings = pipeline.DatasetSettings(seed=args.seed, samples=samples, hidden_effects=tuple(effects.items()))
        ds = jobs.generate(args.out, settings, fmu=args.fmu, overwrite=args.overwrite, job=_job(args))
    print(f"wrote synthetic dataset with {len(ds.samples)} samples to {Path(args.out)}")


def cmd_check(args):
    with _user_errors(DataFormatError, ValueError):
        print(jobs.check(args.dataset, tests=args.tests))


def cmd_import(args):
    with _user_errors(LabImportError):
        print(f"wrote dataset {jobs.import_lab(args.mapping, args.out, overwrite=args.overwrite)}")


def cmd_protocols(args):
    with _user_errors(DataFormatError), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", jobs.MissingParamsWarning)
        written = jobs.protocols(args.dataset, args.out, args.params, with_effects=args.with_effects,
                                 fmu=args.fmu, overwrite=args.overwrite, job=_job(args),
                                 skip_missing=args.skip_missing)
    _print_warnings(caught, jobs.MissingParamsWarning)
    print(f"wrote {len(written)} files to {Path(args.out)}")


def _print_warnings(caught, kind: type[Warning]) -> None:
    """Print the caught warnings of ``kind`` as ``warning: ...`` lines on stderr (others as Python would)."""
    for w in caught:
        if issubclass(w.category, kind):
            print(f"warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def cmd_identify(args):
    with _user_errors(DataFormatError, ValueError):
        if args.weights and not any(args.weights):
            raise SystemExit(f"error: --weights must not all be zero, got {' '.join(f'{w:g}' for w in args.weights)}")
        kw = {"weights": tuple(args.weights)} if args.weights else {}
        kw["choice"] = args.choose.replace("-", "_")
        settings = IdentifySettings.paper(**kw) if args.paper_settings else IdentifySettings(
            pop_size=args.pop_size, n_gen=args.generations, **kw)
        choice = SampleChoice(unseen=tuple(args.unseen) if args.unseen is not None else None,
                              skip_incomplete=args.skip_incomplete)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", IncompleteSampleWarning)
            results, _, written = jobs.identify(args.dataset, args.out, settings, fmu=args.fmu,
                                                overwrite=args.overwrite, job=_job(args), choice=choice)
    _print_warnings(caught, IncompleteSampleWarning)
    print(f"identified {len(results)} samples; wrote {len(written)} files to {Path(args.out)}")


def cmd_diagnose(args):
    with _user_errors(DataFormatError, ValueError):
        diag, written = jobs.diagnose(args.dataset, args.out, overwrite=args.overwrite, job=_job(args),
                                      unseen=args.unseen, discover=not args.no_discovery,
                                      fit_budget_s=args.fit_budget_s)
    print("\n".join(pipeline.summary_lines(diag)))
    print(f"wrote {len(written)} files to {Path(args.out)}")


def cmd_control(args):
    """Closed-loop control study: PI controller FMU and MPC on the actuator FMU (see harness.control)."""
    from harness.control.mpc import MpcSettings
    from harness.control.study import StudySettings, TargetClippedWarning
    _check_control_options(args, StudySettings.__dataclass_fields__["base"].default_factory().r0 * 1000.0)
    if args.sample is not None and args.params is None and args.extended_params is None:
        raise SystemExit(f"error: --sample {args.sample}: give the parameter file that holds it with --params")
    if args.estimator != "ekf" and (args.offset_free or args.noise_factor is not None):
        opt = "--offset-free" if args.offset_free else "--noise-factor"
        raise SystemExit(f"error: {opt} needs --estimator ekf (the disturbances and the noisy readings are the "
                         "estimator's)")
    effect = args.effect or "filler_saturation"
    with _user_errors(ValueError), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", TargetClippedWarning)
        settings = StudySettings(actuator_fmu=args.fmu or "", controller_fmu=args.controller_fmu,
                                 effect=None if effect == "none" else effect,
                                 stroke_m=args.stroke_mm / 1000.0, freq_Hz=args.freq_hz,
                                 mpc=MpcSettings(V_max_V=args.v_max, margin_m=args.margin_mm / 1000.0),
                                 estimator=args.estimator, offset_free=args.offset_free,
                                 noise_factor=1.0 if args.noise_factor is None else args.noise_factor)
        written = jobs_control.control(args.out, settings, overwrite=args.overwrite, extended_file=args.extended_params,
                               sample=args.sample, progress=None if args.quiet else print, params_file=args.params,
                               effect_asked=args.effect is not None and args.effect != "none")
    _print_warnings(caught, TargetClippedWarning)
    print(f"wrote {len(written)} files to {Path(args.out)} (report: control.md)")


def cmd_estimate(args):
    """Filter a measured record with the EKF: estimated velocity and states as a CSV and a figure."""
    with _user_errors(DataFormatError):
        written, summary = jobs_control.estimate(args.dataset, args.out, args.params, args.test, sample=args.sample,
                                                 overwrite=args.overwrite, noise_factor=args.noise_factor)
    print(summary)
    print(f"wrote {len(written)} files to {Path(args.out)} (estimate.csv, figures/estimate.png)")


def _check_control_options(args, gap_mm: float) -> None:
    """Cross-option checks of `control` against the plant's gap r0 [mm]: the stroke must lie inside the gap,
    and the MPC's constraint x <= r0 - margin must leave the stroke reachable."""
    if not args.stroke_mm < gap_mm:
        raise SystemExit(f"error: --stroke-mm {args.stroke_mm:g} must be below the plant's gap r0 = {gap_mm:g} mm")
    if not args.margin_mm + args.stroke_mm < gap_mm:
        raise SystemExit(f"error: --margin-mm {args.margin_mm:g} plus --stroke-mm {args.stroke_mm:g} must be below "
                         f"the plant's gap r0 = {gap_mm:g} mm (the MPC keeps x <= r0 - margin = "
                         f"{gap_mm - args.margin_mm:g} mm)")


def cmd_build(args):
    """Bake one sample's parameters (paper + effects) into an FMU as its start values."""
    settings = jobs.BuildSettings(sample=args.sample, gap_mm=args.gap_mm, blocked=args.blocked,
                                      status_shim=not args.no_status_shim, fmi=args.fmi)
    with _user_errors():
        path, sid = jobs.build(args.params, args.out, settings, overwrite=args.overwrite)
    print(f"wrote {path} with the parameters of {sid} at a {args.gap_mm:g} mm gap as start values")


def cmd_crosscheck(args):
    if args.action == "make":
        with _user_errors():
            files = jobs.crosscheck_make(args.dir, fmu=args.fmu, overwrite=args.overwrite)
        print(f"wrote {len(files)} reference files to {Path(args.dir)}")
    else:
        with _user_errors():
            report = jobs.crosscheck_check(args.dir, fmu=args.fmu)
        for line in report.lines():
            print(line)
        if not report.passed:
            raise SystemExit(1)


def _cluster(args):
    """Where the Dask tasks run: --scheduler ADDRESS, else a LocalCluster of --workers processes."""
    return jobs_design.ClusterSettings(workers=args.workers, scheduler=args.scheduler, progress=not args.quiet)


def cmd_uncertainty(args):
    with _user_errors(DataFormatError, ValueError, SweepError):
        settings = jobs_design.UncertaintySettings(n_boot=args.bootstrap, n_draws=args.draws, seed=args.seed,
                                            bands=not args.no_bands)
        res, written = jobs_design.uncertainty(args.dataset, args.out, args.params, settings, _cluster(args),
                                        overwrite=args.overwrite)
    print(f"parameter uncertainty of {len(res.uncertainties)} samples, bands of {len(res.bands)}; "
          f"wrote {len(written)} files to {Path(args.out)}")


def cmd_design(args):
    for opt in ("--wt-pct", "--diameter-mm", "--gap-mm", "--voltage-V"):   # a range is low then high
        vals = getattr(args, opt[2:].replace("-", "_"))
        if vals and len(vals) == 2 and vals[0] > vals[1]:
            raise SystemExit(f"error: {opt} {vals[0]:g} {vals[1]:g}: a range is given low then high (did you mean "
                             f"{opt} {vals[1]:g} {vals[0]:g}?)")
    with _user_errors(ValueError, SweepError):
        targets = jobs_design.DesignTargets(stroke_mm=args.stroke_mm, blocked_force_N=args.blocked_force_N,
                                     settling_ms=args.settling_ms, max_current_A=args.max_current_A,
                                     max_power_W=args.max_power_W, allow_contact=args.allow_contact,
                                     min_bandwidth_Hz=args.min_bandwidth_Hz)
        spec = {"wt_pct": args.wt_pct, "diameter_mm": args.diameter_mm, "gap_mm": args.gap_mm,
                "voltage_V": args.voltage_V, "points": args.points}
        settings = jobs_design.DesignSettings(n_draws=args.draws, seed=args.seed, max_candidates=args.candidates,
                                       t_step_s=args.step_s, objective=args.minimise, refine=args.refine,
                                       min_probability=args.min_probability)
        res, written = jobs_design.design(args.uncertainty, args.out, targets, spec, settings, _cluster(args),
                                   overwrite=args.overwrite)
    if not res.candidates:     # the report (with the nearest designs) is written; a script sees the failure
        raise SystemExit(f"error: no design of the {res.evaluated} in the space meets the spec; the "
                         f"{len(res.nearest)} nearest (what each misses) are in {Path(args.out) / 'design.md'}")
    n_grid = sum(1 for c in res.candidates if c["source"] == "grid")
    print(f"{n_grid} of {res.evaluated} grid designs meet the spec (+{len(res.candidates) - n_grid} refined); "
          f"wrote {len(written)} files to {Path(args.out)}")


_SEED = number("--seed", 0, integer=True)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="mpc-actuator", description=__doc__.splitlines()[0])
    ap.add_argument("--debug", action="store_true", help="print the traceback of an error")
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p, out=True):
        if out:
            p.add_argument("--out", required=True, help="output folder (created; must be empty unless --overwrite)")
            p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
        p.add_argument("--fmu", help="path of mpc_actuator.fmu (default: the one built in the repository)")
        p.add_argument("--workers", type=number("--workers", 1, integer=True, why="(1 = run in this process)"), default=2, help="processes for the FMU runs (>= 1, default 2)")
        p.add_argument("--quiet", action="store_true", help="no progress bars")

    p = sub.add_parser("run", help="the whole chain on DATASET (check, identify, diagnose, FMUs, uncertainty, "
                                   "control, design, report.md); without DATASET the main job on the default "
                                   "synthetic dataset")
    p.add_argument("dataset", nargs="?", help="dataset folder (mpc-actuator-data/1); default: generate the "
                                              "virtual rig's default dataset and run the main job")
    common(p)
    p.add_argument("--seed", type=_SEED, default=0, help="seed of the generated default dataset")
    p.add_argument("--settings", help="TOML settings file of the steps (sections [run], [identify], [diagnose], "
                                      "[uncertainty], [control], [design]; README 'Your dataset, end to end')")
    p.add_argument("--skip", nargs="+", metavar="STEP", help="steps not to run: check identify diagnose fmus "
                                                             "uncertainty control design")
    p.add_argument("--control-sample", help="sample of the control study (default: the one nearest the middle)")
    p.add_argument("--unseen", nargs="+", help="samples identify predicts from the surfaces instead of identifying")
    p.add_argument("--pop-size", type=number("--pop-size", 4, integer=True), help="NSGA-II population")
    p.add_argument("--generations", type=number("--generations", 1, integer=True), help="NSGA-II generations")
    p.add_argument("--design-stroke-mm", type=number("--design-stroke-mm", 0.0, lo_open=True, why="(a stroke in mm)"),
                   help="design step: minimum stroke [mm] (a design spec turns the design step on)")
    p.add_argument("--design-max-power-W", type=number("--design-max-power-W", 0.0, lo_open=True, why="(a power in W)"),
                   help="design step: maximum steady power [W]")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("generate", help="generate a synthetic dataset with the virtual rig")
    common(p)
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--samples", nargs="*", help="samples like W20-D45 (default: the paper's 11)")
    p.add_argument("--effect", action="append", help="hidden effect NAME=MAGNITUDE (repeatable)")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("check", help="read and validate a dataset")
    p.add_argument("dataset")
    p.add_argument("--tests", nargs="*", help="tests every sample must have, e.g. T3 T5 T8")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("import", help="import lab files (CSV/TSV, LVM, TDMS, MAT) into an mpc-actuator-data/1 dataset",
                       description="Convert lab exports into the dataset format, as described by a JSON mapping file "
                                   "(schema: harness/data/labimport/mapping.py). Input files are only read; the dataset "
                                   "is written into the new or empty folder given by --out.")
    p.add_argument("mapping", help="mapping file (JSON): which file and column is which, sample metadata")
    p.add_argument("--out", required=True, help="output folder (new or empty)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an earlier output of mpc-actuator in --out (never measured data)")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("protocols", help="run T1-T8 through the FMU and compare with the data")
    p.add_argument("dataset")
    common(p)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--params", action="append", help="parameter file per sample (identification.json, "
                   "generalization.json, ...); repeatable: each sample's parameters come from the file that holds it")
    g.add_argument("--true-params", action="store_true", help="use the virtual rig's true parameters (default)")
    p.add_argument("--with-effects", action="store_true",
                   help="with --true-params: include the rig's hidden effects (default: the paper's model only)")
    p.add_argument("--skip-missing", action="store_true",
                   help="run only the samples that have parameters (the others are listed as skipped); "
                        "default: a sample without parameters is an error")
    p.set_defaults(func=cmd_protocols)

    p = sub.add_parser("identify", help="identify parameters (paper section 3), validate, generalize")
    p.add_argument("dataset")
    common(p)
    p.add_argument("--paper-settings", action="store_true", help="NSGA-II with population 200, 200 generations")
    p.add_argument("--pop-size", type=number("--pop-size", 4, integer=True), default=64)
    p.add_argument("--generations", type=number("--generations", 1, integer=True), default=60)
    p.add_argument("--weights", type=number("--weights", 0), nargs=4, metavar=("T3_STE", "T3_RMSE", "T5_STE", "T5_RMSE"),
                   help="Eq. 6 weights (default equal)")
    p.add_argument("--choose", choices=("least-squares", "paper", "eq6"), default="least-squares",
                   help="the (C, m) of the identified model handed downstream: the least-squares estimate of "
                        "the T3 + T5 displacement residuals (default) or the paper's Eq. 6 choice on the Pareto "
                        "front (paper; eq6 is its old name); both are written either way")
    p.add_argument("--unseen", nargs="*", metavar="SAMPLE",
                   help="samples kept out of the identification and predicted from the surfaces (Table 5); "
                        "default: none for measured data, the 15 and 25 wt%% samples for synthetic data")
    p.add_argument("--skip-incomplete", action="store_true",
                   help="skip (with a warning) samples lacking T3, T5 or T8 instead of stopping with an error")
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser("diagnose", help="what the paper's model gets wrong: named cause, extended model, gain")
    p.add_argument("dataset")
    common(p)
    p.add_argument("--unseen", nargs="*", metavar="SAMPLE",
                   help="samples held out of the fit of the shared effect parameters (their gain shows whether "
                        "the effect transfers); default: none declared, the held-out samples then follow the "
                        "README's rule (every sample outside the shared fit of up to 4)")
    p.add_argument("--no-discovery", action="store_true",
                   help="skip the discovery of terms outside the catalogue (run when the catalogue leaves structure "
                        "beyond the noise): the catalogue's verdict alone")
    p.add_argument("--fit-budget-s", type=number("--fit-budget-s", 0, lo_open=True), default=None,
                   help="[s] CPU time of all the fits along the diagnosis's critical path (the wall time on idle "
                        "cores, whatever the load; default 75): no fit iteration starts after it, and the report "
                        "lists the fits it cut short")
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser("control", help="closed-loop control: controller FMU and MPC on the actuator FMU, report")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--fmu", help="actuator FMU (default: mpc_actuator.fmu of the repository)")
    p.add_argument("--controller-fmu", default=str(Path(__file__).resolve().parents[1] / "mpc_controller.fmu"),
                   help="controller FMU (default: mpc_controller.fmu of the repository, `python build_fmu.py --controller`)")
    p.add_argument("--params", help="parameter file (identification.json, generalization.json, extended_params.json) "
                                     "holding the sample to control (default: the default sample); with effects in "
                                     "it (a diagnosis) the plant and the extended model are the sample with them")
    p.add_argument("--sample", help="sample id in --params / --extended-params (needed when the file holds several)")
    p.add_argument("--effect", help="hidden effect of the second plant, or none (default filler_saturation; not with a "
                                    "--params sample that has effects of its own)")
    p.add_argument("--extended-params", help="parameter file (e.g. extended_params.json) whose sample, effects "
                                             "included, is the extended model (the plant keeps the hidden --effect)")
    p.add_argument("--stroke-mm", type=number("--stroke-mm", 0, lo_open=True), default=1.0, help="stroke of the trapezoid [mm] (default 1)")
    p.add_argument("--freq-hz", type=number("--freq-hz", 0.1, 10.0), default=2.0,
                   help="stroke frequency [Hz] in [0.1, 10] (default 2; the MPC acts every 10 ms: at most 10 Hz keeps "
                        "10 control periods per stroke, at least 0.1 Hz keeps a run of two periods within 20 s)")
    p.add_argument("--v-max", type=number("--v-max", 0.0, 100.0, lo_open=True), default=30.0,
                   help="upper voltage limit [V] in (0, 100] (default 30)")
    p.add_argument("--margin-mm", type=number("--margin-mm", 0.0), default=0.5,
                   help="MPC no-contact margin [mm] (>= 0, below the gap minus the stroke; default 0.5)")
    p.add_argument("--estimator", type=choice("--estimator", ("none", "ekf")), default="none",
                   help="the MPC's state: none (the plant's exact I, x, v; default) or ekf (an extended Kalman filter "
                        "from the noisy displacement reading and current only)")
    p.add_argument("--offset-free", action="store_true",
                   help="offset-free MPC: the EKF's input disturbances in the MPC's prediction (needs --estimator ekf)")
    p.add_argument("--noise-factor", type=number("--noise-factor", 0.0, 100.0, lo_open=True), default=None,
                   help="measurement noise of the EKF's readings, times the rig's noise floors, in (0, 100] "
                        "(default 1; needs --estimator ekf)")
    p.set_defaults(func=cmd_control)

    p = sub.add_parser("estimate", help="filter a measured record with the EKF: velocity and unmeasured states")
    p.add_argument("dataset", help="dataset folder")
    p.add_argument("--params", required=True, help="parameter file holding the sample's model (identification.json, "
                                                    "extended_params.json: its effects' states are estimated too)")
    p.add_argument("--sample", help="sample id (needed when --params holds several)")
    free_tests = tuple(t for t in TIME_SERIES_TESTS if t not in BLOCKED_TESTS)
    p.add_argument("--test", type=choice("--test", free_tests), required=True,
                   help=f"time-series test to filter ({', '.join(free_tests)}; not the blocked ones)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--noise-factor", type=number("--noise-factor", 0.0, 100.0, lo_open=True), default=1.0,
                   help="measurement noise assumed, times the dataset's noise floors, in (0, 100] (default 1)")
    p.set_defaults(func=cmd_estimate)

    p = sub.add_parser("build", help="bake identified (and extended) parameters into an FMU")
    p.add_argument("--params", required=True, help="identification.json or extended_params.json")
    p.add_argument("--sample", help="sample id (needed when the file holds several)")
    p.add_argument("--gap-mm", type=number("--gap-mm", 0.0), default=9.0, help="gap r0 [mm] to bake in (default 9)")
    p.add_argument("--blocked", action="store_true", help="bake in blocked mode")
    p.add_argument("--out", required=True, help="FMU file to write (.fmu)")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--no-status-shim", action="store_true",
                   help="build without the C status shim (see build_fmu.py; bad parameters then give fmi2Fatal)")
    p.add_argument("--fmi", choices=("2", "3"), default="2", help="FMI version of the FMU (3: pythonfmu3; see README)")
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("uncertainty", help="parameter covariances and intervals, Monte-Carlo prediction bands (Dask)")
    p.add_argument("dataset")
    common(p)
    p.add_argument("--params", required=True, help="identification.json (the identified samples)")
    p.add_argument("--draws", type=number("--draws", 8, integer=True), default=64, help="Monte-Carlo draws per sample for the bands (>= 8)")
    p.add_argument("--bootstrap", type=number("--bootstrap", 100, integer=True), default=2000, help="bootstrap draws of the analytic part (>= 100)")
    p.add_argument("--seed", type=_SEED, default=0, help="random seed (same seed, same results on any number of workers)")
    p.add_argument("--no-bands", action="store_true", help="parameter uncertainty only")
    p.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a local cluster of "
                                       "--workers processes)")
    p.set_defaults(func=cmd_uncertainty)

    p = sub.add_parser("design", help="inverse design: targets -> feasible (wt%%, D, gap, voltage), P(spec) (Dask)")
    common(p)
    p.add_argument("--uncertainty", required=True, help="uncertainty.json written by `mpc-actuator uncertainty`")
    for name, h in (("--stroke-mm", "minimum stroke [mm]"), ("--blocked-force-N", "minimum blocked force at the gap [N]"),
                    ("--settling-ms", "maximum 2 %% settling time [ms]"), ("--max-current-A", "maximum coil current [A]"),
                    ("--max-power-W", "maximum coil power [W]"),
                    ("--min-bandwidth-Hz", "minimum small-signal -3 dB bandwidth, voltage to displacement [Hz]")):
        p.add_argument(name, type=number(name, 0.0, lo_open=True), help=h)
    p.add_argument("--allow-contact", action="store_true", help="a stroke may end on the coil face")
    for name, h in (("--wt-pct", "filler fraction [wt%%]"), ("--diameter-mm", "diameter [mm]"),
                    ("--gap-mm", "gap [mm] (default 3 12)"), ("--voltage-V", "voltage [V] (default 1 12)")):
        p.add_argument(name, type=number(name, 0.0, lo_open=True), nargs="+", metavar="V", help=f"{h}: one value (fixed) or two (a range)")
    p.add_argument("--points", type=number("--points", 2, integer=True), default=12, help="grid points per ranged axis (default 12)")
    p.add_argument("--draws", type=number("--draws", 1, integer=True), default=32, help="parameter draws for the probability (default 32)")
    p.add_argument("--minimise", type=choice("--minimise", jobs_design.DESIGN_OBJECTIVES), default="power",
                   help="what the ranking and the refinement minimise: power [W] (default), current [A], "
                        "diameter [mm] or filler [wt%%]")
    p.add_argument("--refine", type=number("--refine", 0, integer=True), default=5,
                   help="best grid designs refined off the grid by a local optimisation (default 5; 0: none)")
    p.add_argument("--min-probability", type=number("--min-probability", 0.0, 1.0, hi_open=True), default=0.95,
                   help="linearised probability of meeting the spec a recommended design must reach: ranked first, "
                        "kept by the refinement (default 0.95; 0: rank by the objective alone)")
    p.add_argument("--candidates", type=number("--candidates", 0, integer=True), default=200,
                   help="first designs of the ranking given a Monte-Carlo probability besides the linearised one "
                        "(default 200)")
    p.add_argument("--step-s", type=number("--step-s", 0.0, lo_open=True), default=0.5, help="step-response duration [s] (default 0.5)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a local cluster of "
                                       "--workers processes)")
    p.set_defaults(func=cmd_design)

    p = sub.add_parser("crosscheck", help="FMI cross-check style reference files: make, or check an FMU against them")
    p.add_argument("action", choices=("make", "check"))
    p.add_argument("dir", help="reference folder")
    p.add_argument("--fmu")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_crosscheck)
    for p in sub.choices.values():             # --debug also after the subcommand
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="print the traceback of an error")
    return ap


def main(argv=None):
    try:
        args = build_parser().parse_args(argv)
    except OptionValueError as e:      # a value of one of our options (harness.options): one line, exit 1
        raise SystemExit(f"error: {e}") from None
    debug = getattr(args, "debug", False)
    _signals.WHERE[0] = getattr(args, "out", None) or getattr(args, "dir", None)
    try:
        try:
            return args.func(args)
        except Exception as e:             # an error made of the interrupt (in an import: signals.from_interrupt)
            if _signals.from_interrupt(e):
                raise KeyboardInterrupt from e
            raise
    except KeyboardInterrupt:
        _signals.mark_handled()
        if debug:
            traceback.print_exc()
        where = getattr(args, "out", None) or getattr(args, "dir", None)
        what = interrupt_word()
        print(f"{what}: {where} left as it was" if where else what, file=sys.stderr)
        raise SystemExit(interrupt_exit_code()) from None
    except SystemExit as e:
        if debug and e.__cause__ is not None:
            traceback.print_exception(e.__cause__)
        raise
    except BrokenPipeError:
        if stdout_closed():   # `mpc-actuator ... | head`: the reader has gone; end quietly as a Unix filter does
            raise SystemExit(141) from None  # (128 + SIGPIPE); an unfinished output folder is left as it was
        raise SystemExit("error: a pipe to another process broke (a worker process ended?)"
                         + ("" if debug else " (rerun with --debug for the traceback)")) from None
    except OSError as e:                   # a file or folder the system refuses (permissions, disk full, ...)
        if debug:
            traceback.print_exc()
        msg = f"{e.strerror or e}: {e.filename}" if e.filename else str(e.strerror or e)
        raise SystemExit(f"error: {msg}" + "".join(f" ({n})" for n in getattr(e, "__notes__", ()))) from None
    except Exception as e:                 # a bug: one line, the traceback with --debug
        if debug:
            traceback.print_exc()
        raise SystemExit(f"error: unexpected {type(e).__name__}: {_text(e)} (rerun with --debug for the "
                         f"traceback)") from None


if __name__ == "__main__":
    _signals.install()      # as harness.entry does for the console script
    _code = main()
    _signals.finish()
    sys.exit(_code)
