"""Output folders (harness.outputs): never write into a user's folder or into the input dataset."""
import pytest

from harness.outputs import MARKER, OutputPathError, guard_not_inside, output_folder


def test_out_folder_guards(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "thesis.tex").write_text("precious")
    with pytest.raises(OutputPathError, match="not empty"):
        output_folder(str(user), overwrite=False)
    with pytest.raises(OutputPathError, match="not made by mpc-actuator"):
        output_folder(str(user), overwrite=True)
    assert (user / "thesis.tex").read_text() == "precious"
    assert not (user / MARKER).exists()
    ours = output_folder(str(tmp_path / "run"), overwrite=False)
    assert (ours / MARKER).is_file()
    (ours / "table.md").write_text("x")
    assert output_folder(str(ours), overwrite=True) == ours       # our own folder may be reused
    with pytest.raises(OutputPathError, match="not empty"):
        output_folder(str(ours), overwrite=False)                   # ... only when allowed
    ds = tmp_path / "dataset"
    ds.mkdir()
    with pytest.raises(OutputPathError, match="inside the input dataset"):
        guard_not_inside(ds / "results", ds)
    with pytest.raises(OutputPathError, match="inside the input dataset"):
        guard_not_inside(ds, ds)
    guard_not_inside(tmp_path / "results", ds)                      # a sibling is fine


def test_a_file_is_not_an_output_folder(tmp_path):
    f = tmp_path / "notes.txt"
    f.write_text("x")
    with pytest.raises(OutputPathError, match="exists and is not a folder"):
        output_folder(f, overwrite=True)


# --------------------------------------------------------------------------- output folders as a transaction
import subprocess
import sys
import time
from pathlib import Path

from harness import cli, jobs, pipeline
from harness.outputs import COMPLETE, output_transaction

REPO = Path(__file__).resolve().parents[1]


def _tree(root: Path) -> dict:
    """{relative path: bytes (None for a folder)} of everything below root."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in sorted(root.rglob("*"))}


def _earlier_output(out: Path) -> dict:
    with output_transaction(out, overwrite=False) as tmp:
        (tmp / "table.md").write_text("earlier table\n")
        (tmp / "figures").mkdir()
        (tmp / "figures" / "old.png").write_bytes(b"\x89PNG old")
        (tmp / "generalization.json").write_text("{}\n")
    return _tree(out)


def _no_leftovers(out: Path) -> None:
    assert sorted(p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")) == []
    assert not out.with_name(out.name + ".lock").exists()


def test_transaction_writes_all_or_nothing_and_overwrite_replaces_the_whole_folder(tmp_path):
    out = tmp_path / "res"
    before = _earlier_output(out)
    assert {"table.md", "figures/old.png", "generalization.json", MARKER, COMPLETE} <= set(before)
    with pytest.raises(OutputPathError, match="not empty; choose another folder or pass --overwrite"):
        with output_transaction(out, overwrite=False):
            raise AssertionError("no work may start")
    with output_transaction(out, overwrite=True) as tmp:
        assert tmp != out and tmp.parent == out.parent
        (tmp / "table.md").write_text("new table\n")
    # no stale figures or generalization.json from the earlier run
    assert sorted(_tree(out)) == sorted([COMPLETE, MARKER, "table.md"])
    assert (out / "table.md").read_text() == "new table\n"
    _no_leftovers(out)


def test_an_error_or_interruption_leaves_the_earlier_output_byte_identical(tmp_path):
    out = tmp_path / "res"
    before = _earlier_output(out)
    for exc in (KeyboardInterrupt, RuntimeError):
        with pytest.raises(exc):
            with output_transaction(out, overwrite=True) as tmp:
                (tmp / "table.md").write_text("half written")
                raise exc()
        assert _tree(out) == before
        _no_leftovers(out)
    with pytest.raises(KeyboardInterrupt):                  # a new folder is not created either
        with output_transaction(tmp_path / "new", overwrite=False):
            raise KeyboardInterrupt
    assert not (tmp_path / "new").exists()


def test_interrupted_main_job_leaves_the_earlier_output_as_it_was(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    before = _earlier_output(out)
    fmu = tmp_path / "fake.fmu"                            # an FMU in form (the stages that run it are replaced)
    import zipfile
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")

    def stage(folder, _fmu):                                # the first stage writes, then Ctrl-C
        (folder / "default_step.csv").write_text("partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "default_step", stage)
    with pytest.raises(SystemExit) as e:
        cli.main(["run", "--out", str(out), "--overwrite", "--fmu", str(fmu), "--quiet"])
    assert e.value.code == 130
    assert capsys.readouterr().err.strip().endswith(f"interrupted: {out} left as it was")
    assert _tree(out) == before
    _no_leftovers(out)

    def failing_stage(folder, _fmu):                        # an error says so too
        (folder / "default_step.csv").write_text("partial")
        raise pipeline.PipelineError("the stage failed")

    monkeypatch.setattr(pipeline, "default_step", failing_stage)
    with pytest.raises(SystemExit, match=rf"^error: the stage failed \({out} left as it was\)$"):
        cli.main(["run", "--out", str(out), "--overwrite", "--fmu", str(fmu), "--quiet"])
    assert _tree(out) == before
    _no_leftovers(out)


def test_a_second_concurrent_run_into_the_same_folder_is_refused(tmp_path):
    out, ready, go = tmp_path / "res", tmp_path / "ready", tmp_path / "go"
    code = f"""
import time
from pathlib import Path
from harness.outputs import output_transaction
with output_transaction({str(out)!r}, overwrite=False) as tmp:
    (tmp / "first.txt").write_text("first")
    Path({str(ready)!r}).write_text("x")
    while not Path({str(go)!r}).exists():
        time.sleep(0.05)
"""
    first = subprocess.Popen([sys.executable, "-c", code], cwd=REPO)
    try:
        t0 = time.time()
        while not ready.exists():
            assert first.poll() is None and time.time() - t0 < 60, "the first run did not start"
            time.sleep(0.05)
        assert out.with_name("res.lock").exists()
        with pytest.raises(OutputPathError, match=r"res is being written by another mpc-actuator run"):
            with output_transaction(out, overwrite=True):
                raise AssertionError("the second run must not start")
        with pytest.raises(SystemExit, match=r"^error: --out .*res is being written by another mpc-actuator run"):
            cli.main(["crosscheck", "make", str(out), "--overwrite"])
    finally:
        go.write_text("x")
        assert first.wait(60) == 0
    assert (out / "first.txt").read_text() == "first" and (out / COMPLETE).is_file()
    _no_leftovers(out)


def test_remains_of_an_interrupted_older_run(tmp_path):
    # a marker-only folder (a run interrupted before this fix) is replaced without --overwrite
    out = tmp_path / "res"
    out.mkdir()
    (out / MARKER).write_text("x")
    with output_transaction(out, overwrite=False) as tmp:
        (tmp / "a.txt").write_text("a")
    assert sorted(_tree(out)) == sorted([COMPLETE, MARKER, "a.txt"])
    # with files but no completion record: named incomplete, replaced with --overwrite
    (out / COMPLETE).unlink()
    with pytest.raises(OutputPathError, match="incomplete earlier output .* pass --overwrite"):
        output_transaction(out, overwrite=False).__enter__()
    with output_transaction(out, overwrite=True) as tmp:
        (tmp / "b.txt").write_text("b")
    assert sorted(_tree(out)) == sorted([COMPLETE, MARKER, "b.txt"])


def test_generate_refuses_a_folder_it_did_not_make_before_simulating(tmp_path, monkeypatch):
    def no_simulation(*a, **k):
        raise AssertionError("simulated before checking --out")

    monkeypatch.setattr(jobs.virtual_rig, "generate_dataset", no_simulation)
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "manifest.json").write_text('{"format": "mpc-actuator-data/1", "synthetic": true, "samples": []}')
    before = _tree(theirs)
    with pytest.raises(SystemExit, match=r"^error: --out .*theirs is not empty and was not made by mpc-actuator"):
        cli.main(["generate", "--out", str(theirs), "--overwrite", "--samples", "W20-D45", "--quiet"])
    with pytest.raises(SystemExit, match=r"^error: --out .*theirs is not empty; choose another folder"):
        cli.main(["generate", "--out", str(theirs), "--samples", "W20-D45", "--quiet"])
    assert _tree(theirs) == before
    ours = tmp_path / "ours"
    _earlier_output(ours)
    with pytest.raises(SystemExit, match=r"^error: --out .*ours is not empty; choose another folder or pass "
                                         r"--overwrite$"):
        cli.main(["generate", "--out", str(ours), "--samples", "W20-D45", "--quiet"])


def test_an_output_folder_that_cannot_be_created_is_one_line(tmp_path, capsys):
    f = tmp_path / "plain.txt"
    f.write_text("x")
    with pytest.raises(SystemExit, match=r"^error: --out .*plain.txt/sub: cannot create it, .*plain.txt is a file, "
                                         r"not a folder$"):
        cli.main(["generate", "--out", str(f / "sub"), "--samples", "W20-D45", "--quiet"])
    with pytest.raises(SystemExit, match=r"^error: --out /proc/mpc-actuator-test: "):
        cli.main(["generate", "--out", "/proc/mpc-actuator-test", "--samples", "W20-D45", "--quiet"])
    assert "Traceback" not in capsys.readouterr().err


def _lab_mapping(tmp_path, synthetic=False) -> Path:
    import json
    (tmp_path / "raw").mkdir(exist_ok=True)
    (tmp_path / "raw" / "t7.csv").write_text("Gap (mm),I (A),F (N)\n25,0,0\n20,0.25,0.12\n15,0.5,0.24\n")
    mfile = tmp_path / "map.json"
    mfile.write_text(json.dumps({
        "format": "mpc-actuator-labimport/1", "synthetic": synthetic,
        "rig": {"coil_radius_mm": 15.0, "field_per_amp_T_per_A": 0.29},
        "samples": [{"id": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
                     "tests": {"T7": {"file": "raw/t7.csv", "field_T": 0.23,
                                      "columns": {"gap": "Gap", "current": "I", "force": "F"}}}}]}))
    return mfile


def test_import_is_a_transaction_and_never_replaces_measured_data_or_its_own_inputs(tmp_path):
    mfile = _lab_mapping(tmp_path)
    out = tmp_path / "ds"
    cli.main(["import", str(mfile), "--out", str(out)])
    assert (out / MARKER).is_file() and (out / COMPLETE).is_file() and (out / "manifest.json").is_file()
    before = _tree(out)
    with pytest.raises(SystemExit, match=r"^error: --out .*ds holds a measured \(non-synthetic\) dataset; measured "
                                         r"data are never overwritten"):
        cli.main(["import", str(mfile), "--out", str(out), "--overwrite"])
    assert _tree(out) == before
    # an earlier output of ours that now holds the raw files is not replaced (they would go with it)
    ours = tmp_path / "ours"
    _earlier_output(ours)
    (ours / "raw").mkdir()
    (ours / "raw" / "t7.csv").write_text((tmp_path / "raw" / "t7.csv").read_text())
    (ours / "map.json").write_text(mfile.read_text())
    with pytest.raises(SystemExit, match=r"^error: --out .*ours holds the input file .*; choose another output"):
        cli.main(["import", str(ours / "map.json"), "--out", str(ours), "--overwrite"])
    assert (ours / "raw" / "t7.csv").is_file() and (ours / "table.md").is_file()
