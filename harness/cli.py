"""Command-line interface: a thin layer over the library functions.

    mpc-actuator run --out DIR            the main job on the default (synthetic) dataset
    mpc-actuator generate --out DIR       virtual-rig dataset
    mpc-actuator check DATASET            read and validate a dataset
    mpc-actuator protocols DATASET --out DIR [--params identification.json | --true-params]
    mpc-actuator crosscheck make --out DIR / crosscheck check DIR
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


MARKER = ".mpc-actuator-output"
# The default dataset of the main job hides one effect the paper's model lacks (issue 5): the
# filler's magnetization saturates, so the force grows more slowly than I^2 at high field.
DEFAULT_HIDDEN_EFFECT = {"filler_saturation": 1.0}


def _out_dir(path: str, overwrite: bool) -> Path:
    """Create the output folder. A non-empty folder is used only with --overwrite, and only if
    this tool made it (it holds the marker file), so nothing of the user's is ever overwritten."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise SystemExit(f"error: --out {out} exists and is not a folder")
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise SystemExit(f"error: --out {out} is not empty; choose another folder or pass --overwrite")
        if not (out / MARKER).exists():
            raise SystemExit(f"error: --out {out} is not empty and was not made by mpc-actuator "
                             f"(no {MARKER} file); refusing to write into it")
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("output folder of mpc-actuator; --overwrite may replace files here\n")
    return out


def _guard_not_inside(out: Path, dataset: Path):
    o, d = out.resolve(), dataset.resolve()
    if o == d or d in o.parents:
        raise SystemExit(f"error: --out {out} is inside the input dataset {dataset}; outputs never go into input data")


def _dataset_and_out(args):
    """Read args.dataset (clear errors) and make args.out, which must lie outside the dataset."""
    from harness.data.dataset import read_dataset, DataFormatError
    _guard_not_inside(Path(args.out), Path(args.dataset))
    try:
        ds = read_dataset(args.dataset)
    except DataFormatError as e:
        raise SystemExit(f"error: {e}")
    return ds, _out_dir(args.out, args.overwrite)


def _fmu(args) -> Path:
    from harness.sim.fmurun import default_fmu_path
    p = Path(args.fmu) if getattr(args, "fmu", None) else default_fmu_path()
    if not p.exists():
        raise SystemExit(f"error: FMU {p} not found; build it with `python build_fmu.py`")
    return p


def _true_params(ds, with_effects: bool = False) -> dict:
    """True parameters stored by the virtual rig in a synthetic manifest.

    Without ``with_effects`` the hidden effects are dropped: the paper's model with the true
    paper parameters, which shows what that model gets wrong on data holding an effect.
    """
    from harness.data.paramsjson import ParamsJSONError, params_from_json
    from fmu_src.effects import EFFECT_SPECS
    tp = ds.rig.get("true_parameters")
    if not tp:
        raise SystemExit(f"error: {ds.root}/manifest.json has no rig.true_parameters (not virtual-rig data)")
    out = {}
    for sid, d in tp.items():
        try:
            p = params_from_json(d, f"{ds.root}/manifest.json: rig.true_parameters.{sid}")
        except ParamsJSONError as e:
            raise SystemExit(f"error: {e}") from None
        if not with_effects:
            p = p.with_(**{s.name: 0.0 for s in EFFECT_SPECS})
        out[sid] = p
    return out


def cmd_generate(args):
    from harness.data import rig
    out = Path(args.out)
    effects = dict(_parse_effect(e) for e in (args.effect or []))
    samples = rig.ALL_SAMPLES if not args.samples else [_parse_sample(s) for s in args.samples]
    try:
        ds = rig.generate_dataset(out, seed=args.seed, samples=samples, fmu_path=_fmu(args), effects=effects,
                                  workers=args.workers, progress=not args.quiet, overwrite=args.overwrite)
    except ValueError as e:
        raise SystemExit(f"error: {e}")
    print(f"wrote synthetic dataset with {len(ds.samples)} samples to {out}")


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


def cmd_check(args):
    from harness.data.dataset import read_dataset, dataset_summary, DataFormatError
    try:
        ds = read_dataset(args.dataset, tests=args.tests or None)
    except DataFormatError as e:
        raise SystemExit(f"error: {e}")
    print(dataset_summary(ds))


def cmd_protocols(args):
    from harness.analysis import validation
    from harness.sim import replay
    ds, out = _dataset_and_out(args)
    if args.params:
        params = load_params_file(args.params)
    else:
        params = _true_params(ds, with_effects=args.with_effects)
    runs = validation.run_dataset(ds, params, fmu_path=_fmu(args), workers=args.workers, progress=not args.quiet)
    written = replay.write_outputs(runs, out, synthetic=ds.synthetic)
    print(f"wrote {len(written)} files to {out}")


def load_params_file(path) -> dict:
    """Parameters per sample {id: Params} from identification.json, generalization.json or
    extended_params.json (``harness.data.paramsjson.read_params_file``: layout, keys with units);
    SystemExit naming the file, sample and key on bad input."""
    from harness.data.paramsjson import ParamsJSONError, read_params_file
    try:
        return read_params_file(path)
    except ParamsJSONError as e:
        raise SystemExit(f"error: --params {e}") from None


def cmd_build(args):
    """Bake one sample's parameters (paper + effects) into an FMU as its start values."""
    import importlib.util
    from dataclasses import asdict
    from fmu_src.params import SPECS
    from fmu_src.effects import EFFECT_SPECS
    params = load_params_file(args.params)
    sid = args.sample or (next(iter(params)) if len(params) == 1 else None)
    if sid is None or sid not in params:
        raise SystemExit(f"error: --sample: choose one of {sorted(params)}")
    out = Path(args.out)
    if out.suffix != ".fmu":
        raise SystemExit(f"error: --out {out}: expected a file name ending in .fmu")
    if out.exists() and not args.overwrite:
        raise SystemExit(f"error: --out {out} exists; pass --overwrite to replace it")
    p = params[sid].with_(r0=args.gap_mm / 1000.0, blocked=args.blocked)
    d = asdict(p)
    start = {s.name: d[s.name] for s in SPECS + EFFECT_SPECS}
    start["blocked"] = bool(p.blocked)
    spec = importlib.util.spec_from_file_location("build_fmu", Path(__file__).resolve().parents[1] / "build_fmu.py")
    builder = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(builder)
    path = builder.build(out, start_values=start, status_shim=not args.no_status_shim)
    print(f"wrote {path} with the parameters of {sid} at a {args.gap_mm:g} mm gap as start values")


def default_step(out: Path, fmu_path: Path):
    """Simulate the FMU's DefaultExperiment with fmpy; write CSV and a PNG of I, x, F."""
    import fmpy
    from harness.report import figures
    md = fmpy.read_model_description(str(fmu_path))
    de = md.defaultExperiment
    res = fmpy.simulate_fmu(str(fmu_path), stop_time=float(de.stopTime), output_interval=float(de.stepSize),
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
    figures.plot_default_step(png, res["time"], res["V"], res["I"], res["x"] * 1e3, res["F"])
    return csv, png, res


def cmd_run(args):
    """The main job: default step, synthetic dataset, protocols through the FMU, tables and figures."""
    from harness.data import rig
    from harness.data.dataset import read_dataset
    out = _out_dir(args.out, args.overwrite)
    fmu = _fmu(args)
    (out / "step").mkdir(exist_ok=True)
    csv, png, res = default_step(out / "step", fmu)
    print(f"default step: x settles at {res['x'][-1] * 1e3:.3f} mm, I = {res['I'][-1]:.4f} A, "
          f"F = {res['F'][-1]:.4f} N  ->  {csv}, {png}")
    dpath = out / "dataset"
    rig.generate_dataset(dpath, seed=args.seed, fmu_path=fmu, workers=args.workers, effects=DEFAULT_HIDDEN_EFFECT,
                         progress=not args.quiet, overwrite=True)
    ds = read_dataset(dpath)
    print(f"synthetic dataset (virtual rig, seed {args.seed}): {len(ds.samples)} samples, one hidden effect "
          f"(recorded in its manifest; the diagnosis does not read it) -> {dpath}")
    idir = out / "identification"
    idir.mkdir(exist_ok=True)
    results, records, written = identify_validate(ds, idir, fmu, workers=args.workers, progress=not args.quiet)
    print(f"identified {len(results)} samples (R, L, Em, K1, K2 analytic; C, m by NSGA-II), validated T1-T8 "
          f"through the FMU, predicted the unseen samples: {len(written)} files -> {idir}")
    for name in ("validation_table3.md", "validation_table4.md", "validation_table5.md"):
        if (idir / name).exists():
            print((idir / name).read_text())
    ddir = out / "diagnosis"
    ddir.mkdir(exist_ok=True)
    diag, written = run_diagnosis(ds, ddir, args.workers, not args.quiet)
    print("\n".join(summary_lines(diag)))
    print(f"diagnosis report: {ddir / 'diagnosis.md'} ({len(written)} files)")


def identify_validate(ds, out: Path, fmu: Path, settings=None, workers: int = 2, progress: bool = True):
    """Identify the training samples (paper section 3), validate them through the FMU (Tables 3, 4),
    predict the unseen samples from the surface fits and validate those (Table 5); figures."""
    import numpy as np
    from fmu_src.params import SPEC_BY_NAME
    from harness.analysis import generalize, identify
    from harness.analysis import validation
    from harness.report import figures, tables
    results, written = identify.identify_and_write(ds, out, settings=settings, workers=workers, progress=progress)
    fig = out / "figures"
    fig.mkdir(exist_ok=True)
    for sid, r in results.items():
        figures.plot_pareto(fig / f"pareto_{sid}.png", r.pareto.objectives, r.chosen, list(identify.OBJECTIVE_NAMES))
    params = {sid: r.params for sid, r in results.items()}
    unseen = {}
    gen = out / "generalization.json"
    if gen.exists():
        unseen = load_params_file(gen)
        fits = generalize.fit_surfaces(results)
        ws = [r.wt_pct for r in results.values()]
        ds_ = [r.diameter_mm for r in results.values()]
        for name in generalize.FIT_PARAMS:
            vals = [getattr(r.params, name) for r in results.values()]
            grid = np.vectorize(lambda w, d, n=name: generalize.predict(fits, float(w), float(d))[n])
            figures.plot_surface(fig / f"surface_{name}.png", name, SPEC_BY_NAME[name].unit, ws, ds_, vals, grid)
    runs = validation.run_dataset(ds, {**params, **unseen}, fmu_path=fmu, workers=workers, progress=progress)
    records = [r for run in runs for r in run.records]
    written += tables.write_tables(records, out, "validation", table5_samples=sorted(unseen) or None)
    for run in runs:
        written.append(figures.plot_sample_figure(fig / f"sample_{run.sample}.png", run.sample, run.traces,
                                                synthetic=ds.synthetic))
    return results, records, written


def cmd_identify(args):
    from harness.analysis.identify import IdentifySettings, IdentificationError
    ds, out = _dataset_and_out(args)
    try:
        kw = {"weights": tuple(args.weights)} if args.weights else {}
        settings = IdentifySettings.paper(**kw) if args.paper_settings else IdentifySettings(
            pop_size=args.pop_size, n_gen=args.generations, **kw)
        results, records, written = identify_validate(ds, out, _fmu(args), settings, args.workers, not args.quiet)
    except (IdentificationError, ValueError) as e:
        raise SystemExit(f"error: {e}")
    print(f"identified {len(results)} samples; wrote {len(written)} files to {out}")


def run_diagnosis(ds, out: Path, workers: int = 2, progress: bool = True):
    """Diagnose a dataset blind; write diagnosis.json, diagnosis.md, figures, extended_params.json."""
    from harness.analysis import diagnose
    diag = diagnose.diagnose(ds, diagnose.DiagnoseSettings(workers=workers), progress=progress)
    written = diagnose.write_diagnosis(diag, out)
    return diag, written


def summary_lines(diag) -> list:
    """Cause and held-out gain in a few lines for the terminal."""
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


def cmd_diagnose(args):
    ds, out = _dataset_and_out(args)
    try:
        diag, written = run_diagnosis(ds, out, args.workers, not args.quiet)
    except ValueError as e:
        raise SystemExit(f"error: {e}")
    print("\n".join(summary_lines(diag)))
    print(f"wrote {len(written)} files to {out}")


def cmd_crosscheck(args):
    from harness.analysis import crosscheck
    if args.action == "make":
        out = _out_dir(args.dir, args.overwrite)
        files = crosscheck.make_references(out, fmu_path=_fmu(args))
        print(f"wrote {len(files)} reference files to {out}")
    else:
        report = crosscheck.check_references(Path(args.dir), fmu_path=_fmu(args))
        for line in report.lines():
            print(line)
        if not report.passed:
            raise SystemExit(1)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="mpc-actuator", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p, out=True):
        if out:
            p.add_argument("--out", required=True, help="output folder (created; must be empty unless --overwrite)")
            p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
        p.add_argument("--fmu", help="path of mpc_actuator.fmu (default: the one built in the repository)")
        p.add_argument("--workers", type=int, default=2, help="processes for the FMU runs (default 2)")
        p.add_argument("--quiet", action="store_true", help="no progress bars")

    p = sub.add_parser("run", help="main job on the default synthetic dataset")
    common(p)
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("generate", help="generate a synthetic dataset with the virtual rig")
    common(p)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--samples", nargs="*", help="samples like W20-D45 (default: the paper's 11)")
    p.add_argument("--effect", action="append", help="hidden effect NAME=MAGNITUDE (repeatable)")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("check", help="read and validate a dataset")
    p.add_argument("dataset")
    p.add_argument("--tests", nargs="*", help="tests every sample must have, e.g. T3 T5 T8")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("protocols", help="run T1-T8 through the FMU and compare with the data")
    p.add_argument("dataset")
    common(p)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--params", help="identification.json with parameters per sample")
    g.add_argument("--true-params", action="store_true", help="use the virtual rig's true parameters (default)")
    p.add_argument("--with-effects", action="store_true",
                   help="with --true-params: include the rig's hidden effects (default: the paper's model only)")
    p.set_defaults(func=cmd_protocols)

    p = sub.add_parser("identify", help="identify parameters (paper section 3), validate, generalize")
    p.add_argument("dataset")
    common(p)
    p.add_argument("--paper-settings", action="store_true", help="NSGA-II with population 200, 200 generations")
    p.add_argument("--pop-size", type=int, default=64)
    p.add_argument("--generations", type=int, default=60)
    p.add_argument("--weights", type=float, nargs=4, metavar=("T3_STE", "T3_RMSE", "T5_STE", "T5_RMSE"),
                   help="Eq. 6 weights (default equal)")
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser("diagnose", help="what the paper's model gets wrong: named cause, extended model, gain")
    p.add_argument("dataset")
    common(p)
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser("build", help="bake identified (and extended) parameters into an FMU")
    p.add_argument("--params", required=True, help="identification.json or extended_params.json")
    p.add_argument("--sample", help="sample id (needed when the file holds several)")
    p.add_argument("--gap-mm", type=float, default=9.0, help="gap r0 [mm] to bake in (default 9)")
    p.add_argument("--blocked", action="store_true", help="bake in blocked mode")
    p.add_argument("--out", required=True, help="FMU file to write (.fmu)")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--no-status-shim", action="store_true",
                   help="build without the C status shim (see build_fmu.py; bad parameters then give fmi2Fatal)")
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("crosscheck", help="FMI cross-check style reference files: make, or check an FMU against them")
    p.add_argument("action", choices=("make", "check"))
    p.add_argument("dir", help="reference folder")
    p.add_argument("--fmu")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=cmd_crosscheck)
    return ap


def main(argv=None):
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
