"""Command line: baking parameters into an FMU, output-folder guards, clear errors."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmu_src.model import simulate
from fmu_src.specs import Params
from harness import cli

REPO = Path(__file__).resolve().parents[2]


def _params_file(tmp_path, **extra):
    d = {"R_Ohm": 14.0, "L_H": 0.1, "Em_N_m_per_T2": {"value": 0.05, "uncertainty": 0.001}, "K1_N_per_m3": 3e5,
         "K2_N_per_m": 35.0, "C_N_s_per_m": 0.45, "m_kg": 0.005, "a_m": 0.015, "kB_T_per_A": 0.29, "D_m": 0.045}
    d.update(extra)
    f = tmp_path / "params.json"
    f.write_text(json.dumps({"samples": {"W20-D45": {"parameters": d}}}))
    return f


def test_build_bakes_parameters_and_effects(tmp_path):
    pf = _params_file(tmp_path, Rth_K_per_W=8.0, tau_th_s=4.0)
    out = tmp_path / "baked.fmu"
    # a separate interpreter: the FMU must load its own shipped copy of the physics
    proc = subprocess.run([sys.executable, "-m", "harness.cli", "build", "--params", str(pf), "--gap-mm", "6",
                           "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    code = f"""
import fmpy, json, numpy as np
md = fmpy.read_model_description({str(out)!r}, validate=True)
start = {{v.name: v.start for v in md.modelVariables}}
r = fmpy.simulate_fmu({str(out)!r}, stop_time=1.0, output_interval=1e-3, output=['x', 'I'])
print(json.dumps({{'start': start, 'x': r['x'].tolist(), 'I': r['I'].tolist()}}))
"""
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    s = got["start"]
    assert float(s["r0"]) == 0.006 and float(s["Em"]) == 0.05 and float(s["Rth"]) == 8.0 and float(s["R"]) == 14.0
    assert float(s["V"]) == pytest.approx(0.23 / 0.29 * 14.0)
    p = Params(R=14.0, L=0.1, Em=0.05, K1=3e5, K2=35.0, C=0.45, m=0.005, r0=0.006, Rth=8.0, tau_th=4.0)
    t = np.arange(1001) * 1e-3
    py = simulate(p, t, 0.23 / 0.29 * 14.0)
    assert np.max(np.abs(np.array(got["x"]) - py["x"])) < 1e-9 * np.max(np.abs(py["x"]))
    # heating is really on: the current droops below the cold steady value V/R
    assert got["I"][-1] < 0.99 * 0.23 / 0.29


def test_build_rejects_bad_parameters_by_name(tmp_path):
    pf = _params_file(tmp_path, m_kg=-1.0)
    with pytest.raises(SystemExit, match=r"W20-D45: parameter m \[kg\] must be > 0"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "x.fmu")])
    assert not (tmp_path / "x.fmu").exists()
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(SystemExit, match="broken.json"):
        cli.main(["build", "--params", str(tmp_path / "broken.json"), "--out", str(tmp_path / "x.fmu")])


def test_out_folder_guards_end_the_program_with_the_option_named(tmp_path):
    # the library's checks (tests/test_outputs.py) reach the user as "error: --out ..."
    user = tmp_path / "mine"
    user.mkdir()
    (user / "thesis.tex").write_text("precious")
    with pytest.raises(SystemExit, match=r"^error: --out .*mine is not empty; choose another folder or pass "
                                         r"--overwrite$"):
        cli.main(["crosscheck", "make", str(user)])
    with pytest.raises(SystemExit, match=r"^error: --out .*mine is not empty and was not made by mpc-actuator"):
        cli.main(["run", "--out", str(user), "--overwrite"])
    assert sorted(p.name for p in user.iterdir()) == ["thesis.tex"]
    assert (user / "thesis.tex").read_text() == "precious"
    ds = tmp_path / "dataset"
    ds.mkdir()
    with pytest.raises(SystemExit, match="^error: --out .* is inside the input dataset"):
        cli.main(["diagnose", str(ds), "--out", str(ds / "results")])
    assert not (ds / "results").exists()


def test_missing_fmu_is_named(tmp_path):
    with pytest.raises(SystemExit, match=r"^error: FMU .*nothere.fmu not found; build it with `python build_fmu.py`$"):
        cli.main(["crosscheck", "check", str(tmp_path), "--fmu", str(tmp_path / "nothere.fmu")])


def test_build_refuses_bad_output_paths_and_samples(tmp_path):
    pf = _params_file(tmp_path)
    with pytest.raises(SystemExit, match=r"^error: --out .*x.zip: expected a file name ending in .fmu$"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "x.zip")])
    (tmp_path / "old.fmu").write_text("mine")
    with pytest.raises(SystemExit, match=r"^error: --out .*old.fmu exists; pass --overwrite to replace it$"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "old.fmu")])
    assert (tmp_path / "old.fmu").read_text() == "mine"
    with pytest.raises(SystemExit, match=r"^error: --out .*old.fmu/x.fmu: cannot create it, .*old.fmu is a file, "
                                         r"not a folder$"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "old.fmu" / "x.fmu")])
    with pytest.raises(SystemExit, match=r"^error: --sample: choose one of \['W20-D45'\]$"):
        cli.main(["build", "--params", str(pf), "--sample", "W99-D45", "--out", str(tmp_path / "y.fmu")])


def test_build_writes_its_fmu_as_a_transaction(tmp_path, monkeypatch, fmu_path, capsys):
    """--overwrite replaces only an FMU this tool made; an interrupted or failed build leaves the earlier
    file as it was and no temporary file; a second build into the same file is refused while one runs."""
    import shutil
    import build_fmu
    from harness import jobs
    from harness.outputs import file_transaction
    pf = _params_file(tmp_path)
    theirs = tmp_path / "theirs.fmu"
    theirs.write_text("someone else's file")
    with pytest.raises(SystemExit, match=r"^error: --out .*theirs.fmu exists and is not an FMU made by mpc-actuator; "
                                         r"refusing to replace it$"):
        cli.main(["build", "--params", str(pf), "--out", str(theirs), "--overwrite"])
    assert theirs.read_text() == "someone else's file"
    ours = tmp_path / "ours.fmu"
    shutil.copy(fmu_path, ours)
    before = ours.read_bytes()

    def interrupted(out, **kw):
        Path(out).write_bytes(b"half an FMU")
        raise KeyboardInterrupt

    monkeypatch.setattr(build_fmu, "build", interrupted)
    with pytest.raises(SystemExit) as e:
        cli.main(["build", "--params", str(pf), "--out", str(ours), "--overwrite"])
    assert e.value.code == 130 and "ours.fmu left as it was" in capsys.readouterr().err
    assert ours.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ours.fmu", "params.json", "theirs.fmu"]

    def built(out, **kw):
        Path(out).write_bytes(b"new FMU")
        return Path(out)

    monkeypatch.setattr(build_fmu, "build", built)
    with pytest.raises(RuntimeError, match="abandon"):       # the outer "run" is abandoned: commits nothing
        with file_transaction(ours, True, jobs.fmu_made_by_us, "an FMU made by mpc-actuator"):
            with pytest.raises(SystemExit, match=r"^error: --out .*ours.fmu is being written by another "
                                                 r"mpc-actuator run"):
                cli.main(["build", "--params", str(pf), "--out", str(ours), "--overwrite"])
            raise RuntimeError("abandon")
    assert ours.read_bytes() == before
    cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "new.fmu")])
    assert (tmp_path / "new.fmu").read_bytes() == b"new FMU"


def test_check_names_the_broken_file(tmp_path):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "manifest.json").write_text(json.dumps({
        "format": "mpc-actuator-data/1", "synthetic": True,
        "samples": [{"id": "S", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
                     "tests": {"T5": {"file": "S/T5.csv", "field_T": 0.23, "gap_mm": 5.0}}}]}))
    (ds / "S").mkdir()
    (ds / "S" / "T5.csv").write_text("time_s,voltage_V,current_A,displacment_mm\n0,0,0,0\n0.001,1,0.1,0\n")
    with pytest.raises(SystemExit) as e:
        cli.main(["check", str(ds)])
    msg = str(e.value)
    assert "T5.csv" in msg and "displacement_mm" in msg


# --------------------------------------------------------------------------- user errors: one line, --debug
def test_unknown_test_name_is_one_line_and_debug_shows_the_traceback(tmp_path, capsys):
    with pytest.raises(SystemExit, match=r"^error: unknown test name\(s\) 'T9' \(known: T1, .*T8\)$"):
        cli.main(["check", str(tmp_path), "--tests", "T9"])
    assert "Traceback" not in capsys.readouterr().err
    for argv in (["--debug", "check", str(tmp_path), "--tests", "T9"], ["check", str(tmp_path), "--tests", "T9",
                                                                         "--debug"]):
        with pytest.raises(SystemExit, match=r"^error: unknown test name"):
            cli.main(argv)
        err = capsys.readouterr().err
        assert "Traceback" in err and "ValueError" in err


def test_unexpected_errors_are_one_line_too(tmp_path, monkeypatch, capsys):
    def boom(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(cli.jobs, "check", boom)
    with pytest.raises(SystemExit, match=r"^error: unexpected RuntimeError: boom \(rerun with --debug for the "
                                         r"traceback\)$"):
        cli.main(["check", str(tmp_path)])
    assert "Traceback" not in capsys.readouterr().err


def test_a_defect_inside_a_command_is_unexpected_not_a_user_error(tmp_path, monkeypatch, capsys):
    """numpy's broadcast error (a plain ValueError out of an operation) inside the diagnosis is a defect: it is
    reported as "error: unexpected ...; rerun with --debug", not as an ordinary user error; a ValueError raised
    by a check of the project's code stays a user error."""
    def broadcast(*a, **k):
        return np.zeros(2608) - np.zeros(2596)

    monkeypatch.setattr(cli.jobs, "diagnose", broadcast)
    with pytest.raises(SystemExit, match=r"^error: unexpected ValueError: operands could not be broadcast "
                                         r".*\(rerun with --debug for the traceback\)$"):
        cli.main(["diagnose", str(tmp_path), "--out", str(tmp_path / "d")])
    try:
        np.zeros(3) + np.zeros(2)
    except ValueError as e:
        assert not cli.raised_by_a_check(e)
    from harness.data.dataset import read_dataset      # a check of the project: `raise ValueError(...)`
    with pytest.raises(ValueError, match="unknown test name") as e:
        read_dataset(tmp_path, tests=["T9"])
    assert cli.raised_by_a_check(e.value)


def test_workers_below_one_are_refused(tmp_path, capsys):
    for n in ("0", "-1"):
        with pytest.raises(SystemExit) as e:
            cli.main(["generate", "--out", str(tmp_path / "g"), "--workers", n])
        assert e.value.code == f"error: --workers must be a whole number >= 1 (1 = run in this process), got {n}"
        assert capsys.readouterr().err == ""      # no usage text: the one line above, exit code 1
    assert not (tmp_path / "g").exists()


def test_a_gap_the_model_refuses_is_named(tmp_path):
    pf = _params_file(tmp_path, r0_m=1e300)
    with pytest.raises(SystemExit, match=r"^error: --params .*params.json: sample W20-D45: parameter r0 \[m\] = "
                                         r"1e\+300 is too large"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "x.fmu")])
    pf = _params_file(tmp_path)
    with pytest.raises(SystemExit, match=r"^error: --gap-mm 1e\+300: parameter r0 \[m\] = 1e\+297 is too large"):
        cli.main(["build", "--params", str(pf), "--gap-mm", "1e300", "--out", str(tmp_path / "x.fmu")])
    assert not (tmp_path / "x.fmu").exists()


def test_absurd_parameter_combinations_are_refused_by_build(tmp_path):
    """Em = 1e30 (a force at the coil face 1.6e29 times what a field can pull) and a coil time constant of a week:
    refused before an FMU is written, naming the parameters (fmu_src.model.check_integrable)."""
    pf = _params_file(tmp_path, Em_N_m_per_T2=1e30)
    with pytest.raises(SystemExit, match=r"^error: --params .*params.json: sample W20-D45: parameters Em = 1e\+30 "
                                         r"N.m/T2, a = 0.015 m, D = 0.045 m: the magnetic force at the coil face"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "x.fmu")])
    pf = _params_file(tmp_path, L_H=1e7)
    with pytest.raises(SystemExit, match=r"^error: --params .*: time scale\(s\) L/R \(parameters L, R\) = 7.14e\+05 s above 100000 s"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "x.fmu")])
    assert not (tmp_path / "x.fmu").exists()


def _dataset_lacking_t8(tmp_path, synthetic=True):
    from harness.data import rig
    from harness.data.dataset import Dataset, Sample, write_dataset
    from harness.sim import virtual_rig

    samples = []
    for w, d in ((10, 30), (30, 30), (20, 60), (20, 45)):
        sid, _, tests = virtual_rig.generate_sample(w, d, simulator=virtual_rig.ModelSimulator())
        if sid == "W20-D45":
            tests = {k: v for k, v in tests.items() if k != "T8"}
        samples.append(Sample(id=sid, wt_pct=float(w), diameter_mm=float(d), thickness_mm=1.5, tests=tests))
    ds = Dataset(root=None, synthetic=synthetic, description="test", rig=rig.rig_description(), samples=samples)
    return write_dataset(ds, tmp_path / "ds")


def test_identify_stops_on_a_sample_lacking_a_test_before_any_work(tmp_path, capsys):
    ds = _dataset_lacking_t8(tmp_path)
    out = tmp_path / "ident"
    with pytest.raises(SystemExit, match=r"^error: sample W20-D45, test T8: missing test T8 .*--skip-incomplete"):
        cli.main(["identify", str(ds), "--out", str(out), "--quiet"])
    with pytest.raises(SystemExit, match=r"^error: sample W99-D45: declared unseen but not in the dataset"):
        cli.main(["identify", str(ds), "--out", str(out), "--quiet", "--unseen", "W99-D45"])
    assert not out.exists() and "Traceback" not in capsys.readouterr().err


def test_identify_skip_incomplete_end_to_end(tmp_path, capsys):
    # the sample lacking T8 is skipped with a warning, listed in every report, and not passed off as unseen
    ds = _dataset_lacking_t8(tmp_path, synthetic=False)
    out = tmp_path / "ident"
    cli.main(["identify", str(ds), "--out", str(out), "--quiet", "--skip-incomplete", "--pop-size", "8",
              "--generations", "2", "--workers", "2"])
    cap = capsys.readouterr()
    assert "warning: skipped sample W20-D45, test T8: missing test T8" in cap.err
    assert cap.out.startswith("identified 3 samples; wrote ")
    ident = json.loads((out / "identification.json").read_text())
    assert sorted(ident["samples"]) == ["W10-D30", "W20-D60", "W30-D30"] and list(ident["skipped_samples"]) == [
        "W20-D45"] and ident["unseen_samples"] == []
    gen = json.loads((out / "generalization.json").read_text())
    assert gen["samples"] == {} and list(gen["skipped_samples"]) == ["W20-D45"]
    assert not (out / "validation_table5.md").exists()
    for md in out.glob("validation_*.md"):
        assert "Skipped samples" in md.read_text() and "W20-D45" in md.read_text(), md.name


def test_output_into_a_closed_pipe_ends_quietly(tmp_path):
    """`mpc-actuator check DS | head -0`: the reader is gone before the first line; no 'error: Broken pipe'."""
    import os
    ds = tmp_path / "ds"
    (ds / "S").mkdir(parents=True)
    (ds / "S" / "T3.csv").write_text("time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n0.01,6,0.2,0.3\n")
    (ds / "manifest.json").write_text(json.dumps({
        "format": "mpc-actuator-data/1", "synthetic": True, "rig": {"coil_radius_mm": 15.0},
        "samples": [{"id": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
                     "tests": {"T3": {"file": "S/T3.csv", "field_T": 0.11, "gap_mm": 9.0}}}]}))
    r, w = os.pipe()
    os.close(r)                                  # the reader has gone
    try:
        proc = subprocess.run([sys.executable, "-m", "harness.cli", "check", str(ds)], stdout=w,
                              stderr=subprocess.PIPE, text=True, cwd=REPO, timeout=120)
    finally:
        os.close(w)
    assert proc.stderr == "", proc.stderr
    assert proc.returncode == 141
    ok = subprocess.run([sys.executable, "-m", "harness.cli", "check", str(ds)], capture_output=True, text=True,
                        cwd=REPO, timeout=120)
    assert ok.returncode == 0 and "W20-D45" in ok.stdout, ok.stderr


def test_diagnose_unknown_unseen_sample_is_one_line_before_any_write(tmp_path, capsys):
    from harness.data.dataset import write_dataset
    from tests.analysis.diagnosis.test_heldout import lab_dataset
    ds = write_dataset(lab_dataset(), tmp_path / "lab")
    with pytest.raises(SystemExit, match=r"^error: sample\(s\) W15-D45 declared unseen \(--unseen\) but not in the "
                                         r"dataset \(its samples: alpha, beta, gamma\)$"):
        cli.main(["diagnose", str(ds), "--out", str(tmp_path / "d"), "--unseen", "alpha", "W15-D45"])
    assert "Traceback" not in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


# --------------------------------------------------------------------------- crosscheck make
def _fake_fmu_run(p, t, V, fmu_path=None, outputs=("x", "F", "I")):
    """A stand-in for the FMU run (fmurun.run): the same keys and grid, cheap values."""
    t = np.asarray(t, float)
    return {"time": t, **{k: np.full(t.shape, 1e-4 * p.Em) for k in outputs}}


def test_crosscheck_make_writes_the_shipped_reference_layout(tmp_path, monkeypatch, capsys):
    """`crosscheck make DIR` (it crashed on a constant moved to harness.data.protocol): in process with a stand-in
    for the FMU runs; the inputs, options and parameter files are those shipped in references/W20-D45."""
    from harness.analysis.validation import crosscheck
    monkeypatch.setattr(crosscheck.fmurun, "run", _fake_fmu_run)
    out = tmp_path / "refs"
    cli.main(["crosscheck", "make", str(out)])
    assert capsys.readouterr().out.strip() == f"wrote 28 reference files to {out}"
    shipped = REPO / "references" / "W20-D45"
    made = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    assert made == {p.name for p in shipped.iterdir()}
    for name in made:
        if name.endswith(("_in.csv", "_params.json", ".opt")):
            assert (out / name).read_bytes() == (shipped / name).read_bytes(), name


@pytest.mark.slow
def test_crosscheck_make_reproduces_the_shipped_references(tmp_path, fmu_path):
    out = tmp_path / "refs"
    cli.main(["crosscheck", "make", str(out), "--fmu", str(fmu_path)])
    shipped = REPO / "references" / "W20-D45"
    for p in shipped.iterdir():
        assert (out / p.name).read_bytes() == p.read_bytes(), p.name


@pytest.mark.slow          # generates a dataset of one sample (15-45 s)
def test_a_finished_job_into_a_closed_pipe_keeps_its_folder(tmp_path):
    """Issue 24.6, decided as docs/guide/commands.md says: `generate --out P --quiet | true` exits 141 (the reader
    has gone before the closing summary line) and keeps the complete folder, written before the summary (the
    transaction has committed: removing it would lose a finished result); nothing on stderr."""
    import os
    out = tmp_path / "P"
    r, w = os.pipe()
    os.close(r)                                  # the reader has gone
    try:
        proc = subprocess.run([sys.executable, "-m", "harness", "generate", "--out", str(out), "--samples",
                               "W20-D45", "--quiet", "--workers", "1"], stdout=w, stderr=subprocess.PIPE, text=True,
                              cwd=REPO, timeout=600)
    finally:
        os.close(w)
    assert proc.returncode == 141 and proc.stderr == "", proc.stderr
    from harness.data.dataset import read_dataset
    ds = read_dataset(out)                       # complete: every file there and valid
    assert [s.id for s in ds.samples] == ["W20-D45"] and len(ds.samples[0].tests) == 8
