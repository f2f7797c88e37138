"""``mpc-actuator run DATASET`` (harness.chain): settings file, step selection, the control sample, and the whole
chain on a user's data: the reduced copy of the bug report's dataset in the default suite; the whole chain (every
step) on that dataset, on the generated default dataset and on a dataset imported from lab files under ``-m slow``.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from harness import chain
from harness.cli import main as cli_main
from harness.data.dataset import read_dataset

FIXTURE = Path(__file__).parent / "fixtures" / "clean-500hz-3-samples"
BUG_REPORT = Path(__file__).resolve().parents[1].parent / "shared" / "bug-reports" / "clean-500hz-11-samples"


# ---------------------------------------------------------------- settings file
def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "run.toml"
    p.write_text(text, encoding="utf-8")
    return p


def test_settings_file_values_are_typed_and_checked(tmp_path):
    p = _write(tmp_path, '[run]\nskip = ["uncertainty"]\n[identify]\npop_size = 16\nunseen = ["W15-D45"]\n'
                         '[control]\nstroke_mm = 1\nsample = "W20-D45"\n[design]\nmax_power_W = 2.5\n')
    v = chain.load_settings_file(p)
    assert v == {"run": {"skip": ("uncertainty",)}, "identify": {"pop_size": 16, "unseen": ("W15-D45",)},
                 "control": {"stroke_mm": 1.0, "sample": "W20-D45"}, "design": {"max_power_W": 2.5}}
    assert isinstance(v["control"]["stroke_mm"], float)


@pytest.mark.parametrize("text, words", [
    ("[identfy]\npop_size = 3\n", ["unknown section [identfy]", "identify"]),
    ("[identify]\npopsize = 3\n", ["[identify]", "unknown key 'popsize'", "pop_size"]),
    ("[identify]\npop_size = 3.5\n", ["[identify] pop_size", "expected int", "3.5"]),
    ("[control]\nstroke_mm = \"1\"\n", ["[control] stroke_mm", "expected float"]),
    ("[run]\nskip = [1, 2]\n", ["[run] skip", "list of strings"]),
    ("[control]\nstroke_mm = nan\n", ["[control] stroke_mm", "finite"]),
    ("[control]\nstroke_mm = 1\n[control\n", ["line 3"]),
    ("skip = 3\n", ["key 'skip' outside any section", "[run]"]),
])
def test_settings_file_errors_name_file_section_and_key(tmp_path, text, words):
    p = _write(tmp_path, text)
    with pytest.raises(chain.SettingsFileError) as e:
        chain.load_settings_file(p)
    msg = str(e.value)
    assert str(p) in msg
    for w in words:
        assert w in msg, (w, msg)


def test_settings_file_error_through_the_cli_is_one_line_exit_1(tmp_path):
    p = _write(tmp_path, "[identify]\npopsize = 3\n")
    with pytest.raises(SystemExit) as e:
        cli_main(["run", str(FIXTURE), "--out", str(tmp_path / "o"), "--settings", str(p)])
    msg = str(e.value.code)
    assert msg.startswith("error: ") and "popsize" in msg and "\n" not in msg
    assert not (tmp_path / "o").exists()


def test_options_override_the_settings_file():
    s = chain.options_to_settings({"identify": {"pop_size": 30, "generations": 7}, "control": {"stroke_mm": 2.0}},
                                  {"identify": {"pop_size": 12, "generations": None}, "control": {"sample": "X"}},
                                  chain.JobSettings(workers=1, progress=False))
    assert (s.identify.pop_size, s.identify.n_gen) == (12, 7)
    assert s.control == {"stroke_mm": 2.0, "sample": "X"}
    assert s.design is None


# ---------------------------------------------------------------- steps and samples
def test_skipping_a_step_skips_the_steps_that_need_it():
    sk = chain.ChainSettings(skip=("identify",)).skipped()
    assert set(sk) == {"identify", "fmus", "uncertainty", "control", "design"}
    assert "needs the identify step" in sk["fmus"] and "(--skip)" in sk["identify"]
    assert "no design spec" in chain.ChainSettings().skipped()["design"]
    assert "needs the uncertainty step" in chain.ChainSettings(skip=("uncertainty",),
                                                               design={"stroke_mm": 1.0}).skipped()["design"]
    with pytest.raises(chain.PipelineError, match="--skip fmu: unknown step"):
        chain.ChainSettings(skip=("fmu",))


def test_chain_options_without_a_dataset_are_refused(tmp_path):
    with pytest.raises(SystemExit) as e:
        cli_main(["run", "--out", str(tmp_path / "o"), "--skip", "fmus"])
    assert str(e.value.code).startswith("error: --skip needs a DATASET")


def test_middle_sample_by_hand():
    r = {sid: SimpleNamespace(wt_pct=w, diameter_mm=d) for sid, w, d in
         (("W10-D30", 10, 30), ("W20-D45", 20, 45), ("W30-D60", 30, 60), ("W30-D30", 30, 30), ("W18-D58", 18, 58))}
    # ranges 10-30 wt% and 30-60 mm scaled to 0-1: W20-D45 is (0.5, 0.5), the centre itself
    assert chain.middle_sample(r) == "W20-D45"
    del r["W20-D45"]
    # distances to (0.5, 0.5): W18-D58 (0.4, 0.933) -> 0.445; W10-D30 (0, 0) and W30-D60 (1, 1) -> 0.707
    assert chain.middle_sample(r) == "W18-D58"
    one = {"A": SimpleNamespace(wt_pct=20, diameter_mm=45)}
    assert chain.middle_sample(one) == "A"


def test_samples_span_an_area_by_hand():
    def r(*pts):
        return {f"S{i}": SimpleNamespace(wt_pct=w, diameter_mm=d) for i, (w, d) in enumerate(pts)}
    assert not chain.samples_span_an_area(r((10, 30), (20, 45), (30, 60)))      # the fixture: one line
    assert not chain.samples_span_an_area(r((10, 45), (20, 45)))                # two samples
    assert not chain.samples_span_an_area(r((10, 45), (20, 45), (30, 45)))      # one diameter
    assert chain.samples_span_an_area(r((10, 30), (20, 45), (30, 45)))          # a triangle


# ---------------------------------------------------------------- the chain on a user's dataset
def _check_report(out: Path, dataset: Path, ran: set):
    rep = json.loads((out / "report.json").read_text())
    steps = {s["step"]: s for s in rep["steps"]}
    assert list(steps) == list(chain.STEPS)
    assert {s for s, v in steps.items() if not v["skipped"] and not v["failed"]} == ran, steps
    md = (out / "report.md").read_text()
    for step in chain.STEPS:
        assert f"({step})" in md
    for s in steps.values():                              # every file the report lists exists and is not empty
        for f in s["files"]:
            assert (out / f).is_file() and (out / f).stat().st_size > 0, f
            assert f"]({f})" in md, f                     # and is in the index
    assert not list(out.parent.glob(f".{out.name}.tmp-*"))
    ds = read_dataset(dataset)
    ident = json.loads((out / "identification" / "identification.json").read_text())["samples"]
    gen = out / "identification" / "generalization.json"
    unseen = set(json.loads(gen.read_text()).get("samples") or {}) if gen.is_file() else set()
    assert set(ident) | unseen == {s.id for s in ds.samples} and not set(ident) & unseen   # synthetic: 15/25 wt% unseen
    for sid, body in ident.items():                       # the report's parameter table is identification.json's
        row = next(ln for ln in md.splitlines() if ln.startswith(f"| {sid} |"))
        r_ohm = float(row.split("|")[4])
        assert r_ohm == pytest.approx(body["parameters"]["R_Ohm"]["value"] if isinstance(
            body["parameters"]["R_Ohm"], dict) else body["parameters"]["R_Ohm"], rel=1e-3)
    return steps, md


def _check_fmus(out: Path, dataset: Path):
    """Every sample has a paper-model and an extended-model FMU; each passes fmpy's validation (run here again)
    and simulates with fmpy (its default experiment) to finite outputs."""
    import fmpy
    from fmpy.validation import validate_fmu
    ds = read_dataset(dataset)
    fmus = sorted((out / "fmus").glob("*.fmu"))
    extended = set(json.loads((out / "diagnosis" / "extended_params.json").read_text())["samples"])
    assert {f.name for f in fmus} == ({f"{s.id}_paper.fmu" for s in ds.samples}
                                      | {f"{sid}_extended.fmu" for sid in extended})
    assert extended <= {s.id for s in ds.samples}
    for f in fmus[:2]:
        assert validate_fmu(str(f)) == []
        md = fmpy.read_model_description(str(f))
        res = fmpy.simulate_fmu(str(f), stop_time=0.2, output_interval=1e-3, output=["x", "I"])
        assert np.all(np.isfinite(res["x"])) and res["I"][-1] > 0
        assert md.author == "mpc-actuator"


def test_chain_on_the_reduced_bug_report_dataset(tmp_path):
    out = tmp_path / "run"
    cli_main(["run", str(FIXTURE), "--out", str(out), "--workers", "2", "--quiet", "--pop-size", "12",
              "--generations", "5", "--skip", "uncertainty", "control"])
    steps, md = _check_report(out, FIXTURE, {"check", "identify", "diagnose", "fmus"})
    _check_fmus(out, FIXTURE)
    diag = json.loads((out / "diagnosis" / "diagnosis.json").read_text())
    assert diag["verdict"] == "none" and "**none**" in md
    assert "no design spec given" in md                         # design: skipped with its reason


def test_chain_on_a_lab_import(tmp_path):
    """The fixture written as lab files (semicolons, decimal commas, ms, mA, um, mN), imported, identified and
    diagnosed: the same verdict as the original files."""
    dataset = _lab_import(FIXTURE, tmp_path)
    out = tmp_path / "run"
    cli_main(["run", str(dataset), "--out", str(out), "--workers", "2", "--quiet", "--pop-size", "12",
              "--generations", "5", "--skip", "fmus", "uncertainty", "control"])
    _, md = _check_report(out, dataset, {"check", "identify", "diagnose"})
    assert json.loads((out / "diagnosis" / "diagnosis.json").read_text())["verdict"] == "none"
    assert "SYNTHETIC" not in (out / "check.txt").read_text()    # imported lab files are measured data


def test_chain_control_on_a_generated_dataset(tmp_path):
    """Three virtual-rig samples with the default hidden effect: identify, then the control study on the middle
    sample (the diagnosis skipped: the plant is the identified paper model)."""
    dataset = tmp_path / "ds"
    cli_main(["generate", "--out", str(dataset), "--quiet", "--samples", "W10-D45", "W20-D45", "W30-D45"])
    out = tmp_path / "run"
    cli_main(["run", str(dataset), "--out", str(out), "--workers", "2", "--quiet", "--pop-size", "12",
              "--generations", "5", "--skip", "diagnose", "fmus", "uncertainty"])
    steps, md = _check_report(out, dataset, {"check", "identify", "control"})
    ctl = json.loads((out / "control" / "control.json").read_text())
    assert {r["controller"] for r in ctl["runs"]} == {"PI", "MPC"}
    assert "control study on W20-D45" in steps["control"]["summary"]
    assert all(np.isfinite(r["rmse_m"]) and r["rmse_m"] < 1e-3 for r in ctl["runs"])


@pytest.mark.slow
@pytest.mark.parametrize("which", ["bug-report", "default", "lab-import"])
def test_whole_chain(which, tmp_path):
    """Every step, on the bug report's 11 samples, on the virtual rig's default dataset and on a dataset imported
    from lab files (the fixture written as semicolon/decimal-comma CSVs in ms, mA, um, mN)."""
    if which == "bug-report":
        dataset = BUG_REPORT
        assert dataset.is_dir(), f"{dataset} not found"
    elif which == "default":
        dataset = tmp_path / "ds"
        cli_main(["generate", "--out", str(dataset), "--quiet"])
    else:
        dataset = _lab_import(FIXTURE, tmp_path)
    out = tmp_path / "run"
    cli_main(["run", str(dataset), "--out", str(out), "--quiet", "--design-stroke-mm", "0.5",
              "--design-max-power-W", "5"])
    if which == "lab-import":
        # the fixture's samples (10/30, 20/45, 30/60) lie on a line in (wt%, D): no surface over both, so the design
        # grid lies outside their (degenerate) hull; the step is reported as failed and the chain goes on
        steps, md = _check_report(out, dataset, set(chain.STEPS) - {"design"})
        assert "span no area" in steps["design"]["failed"] and "**Failed**" in md
    else:
        _check_report(out, dataset, set(chain.STEPS))
    _check_fmus(out, dataset)


def _lab_import(src: Path, tmp_path: Path) -> Path:
    """The dataset ``src`` rewritten as lab files and imported back with ``mpc-actuator import``."""
    ds = read_dataset(src)
    raw = tmp_path / "raw"
    raw.mkdir()
    samples = []
    for s in ds.samples:
        tests = {}
        for name, t in s.tests.items():
            f = f"{s.id}_{name}.csv"
            if hasattr(t, "time_s"):
                cols = [("Time [ms]", t.time_s * 1e3), ("U [V]", t.voltage_V), ("I [mA]", t.current_A * 1e3)]
                cols.append(("x [um]", t.displacement_mm * 1e3) if t.displacement_mm is not None
                            else ("F [mN]", t.force_N * 1e3))
                spec = {"field_T": t.field_T, "gap_mm": t.gap_mm,
                        "columns": {"time": "Time", "voltage": "U", "current": "I",
                                    ("displacement" if t.displacement_mm is not None else "force"):
                                        "x" if t.displacement_mm is not None else "F"}}
                if t.frequency_hz is not None:
                    spec["frequency_hz"] = t.frequency_hz
            else:
                cols = [("Gap [mm]", t.gap_mm), ("I [mA]", t.current_A * 1e3)]
                cols.append(("x [um]", t.displacement_mm * 1e3) if t.displacement_mm is not None
                            else ("F [mN]", t.force_N * 1e3))
                spec = {"columns": {"gap": "Gap", "current": "I",
                                    ("displacement" if t.displacement_mm is not None else "force"):
                                        "x" if t.displacement_mm is not None else "F"}}
                if getattr(t, "field_T", None) is not None:
                    spec["field_T"] = t.field_T
            lines = [";".join(c for c, _ in cols)]
            lines += [";".join(repr(float(v)).replace(".", ",") for v in row) for row in zip(*(c for _, c in cols))]
            (raw / f).write_text("\n".join(lines) + "\n", encoding="utf-8")
            tests[name] = {"file": f, **spec}
        samples.append({"id": s.id, "wt_pct": s.wt_pct, "diameter_mm": s.diameter_mm, "thickness_mm": s.thickness_mm,
                        "tests": tests})
    rig = {k: v for k, v in ds.rig.items() if k in ("coil_radius_mm", "field_per_amp_T_per_A", "sweep_average_s",
                                                   "sweep_hold_s", "sample_period_s")}
    mfile = tmp_path / "map.json"
    mfile.write_text(json.dumps({"format": "mpc-actuator-labimport/1", "base_dir": str(raw), "rig": rig,
                                 "samples": samples}))
    cli_main(["import", str(mfile), "--out", str(tmp_path / "imported")])
    shutil.rmtree(raw)
    return tmp_path / "imported"
