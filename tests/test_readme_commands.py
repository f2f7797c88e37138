"""Every command of the README is run (issue 23 "Done when"; ``tests/test_docs.py`` only checks that the commands
and options exist in the parser).

* default suite: ``fmpy simulate mpc_actuator.fmu --output-file step.csv`` and ``fmpy validate mpc_actuator.fmu``
  exactly as the README writes them (on the session's FMU, in a temporary folder), and ``make run`` / ``make test``
  through ``make -n`` (what they would run: the set-up, the FMU builds, ``mpc-actuator run --out out`` and the
  pytest line; running them for real takes the whole main job or the whole suite, which CI does);
* ``-m slow``: the five-minute tour's shell block, line by line, in a temporary folder. ``mpc-actuator`` is run as
  ``python -m harness`` of this checkout; ``identify`` gets ``--pop-size 12 --generations 5`` (the README's default
  64 x 60 takes minutes more) and every command that has it ``--quiet``; nothing else is changed. Each must exit 0
  and leave the files the README names (``id/validation_table3.md``, ``diag/diagnosis.md``, the FMU, ``step.csv``).
"""
from __future__ import annotations

import csv
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_docs import subcommand_options

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text(encoding="utf-8")
REDUCED = {"identify": ["--pop-size", "12", "--generations", "5"]}


def sh_blocks(text: str) -> list[list[str]]:
    """The command lines (comments dropped, ``[...]`` continuation lines joined) of every sh block."""
    blocks, cur, inside = [], None, False
    for line in text.splitlines():
        if line.strip().startswith("```"):
            if not inside and line.strip()[3:].strip() in ("sh", "bash", "shell"):
                inside, cur = True, []
            elif inside:
                inside = False
                blocks.append(cur)
            continue
        if inside:
            code = re.split(r"\s#\s|\s#$", " " + line)[0].strip()
            if code and not code.startswith("["):
                cur.append(code)
    return blocks


def readme_line(prefix: str) -> str:
    lines = [c for b in sh_blocks(README) for c in b if c.startswith(prefix)]
    assert lines, f"the README shows no `{prefix} ...` command"
    return lines[0]


def _run(args, cwd, timeout=600):
    done = subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env={**__import__("os").environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"})
    assert done.returncode == 0, f"{' '.join(map(str, args))} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done


def test_readme_blocks_found():
    blocks = sh_blocks(README)
    assert any(b and b[0].startswith("make run") for b in blocks)               # the two commands
    assert any(b and b[0].startswith("mpc-actuator generate") for b in blocks)  # the tour
    assert sum(len(b) for b in blocks) >= 20


@pytest.mark.parametrize("prefix", ["fmpy simulate mpc_actuator.fmu", "fmpy validate mpc_actuator.fmu"])
def test_fmpy_commands_as_written(prefix, fmu_path, tmp_path):
    line = readme_line(prefix)
    shutil.copy(fmu_path, tmp_path / "mpc_actuator.fmu")
    words = shlex.split(line)
    done = _run([sys.executable, "-m", "fmpy.cli", *words[1:]], tmp_path)
    if words[1] == "validate":
        assert "No problems found" in done.stdout
        return
    out = tmp_path / words[words.index("--output-file") + 1]
    rows = list(csv.reader(out.read_text().splitlines()))
    header = [h.strip('"') for h in rows[0]]
    assert {"time", "x", "I", "F", "B", "x_sensor", "F_sensor"} <= set(header)
    last = {h: float(v) for h, v in zip(header, rows[-1]) if v not in ("True", "False")}
    assert last["time"] == pytest.approx(1.0)                                    # DefaultExperiment: 1 s
    # the 0.23 T step at the coil face: the steady current 0.23 T / kB = 0.23 / 0.29 A (V = that * R)
    assert last["I"] == pytest.approx(0.23 / 0.29, rel=1e-3)
    assert 0.0 < last["x"] < 9e-3                                                # pulled toward the coil, no contact


@pytest.mark.parametrize("target", ["run", "test"])
def test_make_targets_dry_run(target, tmp_path):
    """``make -n`` prints what the README's two commands run, without running it (the real runs are the main job
    and the whole suite)."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    line = readme_line(f"make {target}")
    assert shlex.split(line) == ["make", target]
    done = _run(["make", "-n", "-B", target, "PYTHON=python3.11"], REPO)
    text = done.stdout
    assert "-m venv .venv" in text and "pip install --quiet -e '.[test,docs]'" in text
    assert "build_fmu.py --controller" in text and ".venv/bin/python build_fmu.py" in text
    if target == "run":
        assert ".venv/bin/mpc-actuator run --out out --overwrite" in text
    else:
        assert "-m pytest" in text and " tests" in text


@pytest.mark.slow
def test_the_five_minute_tour(tmp_path, fmu_path, monkeypatch):
    tour = next(b for b in sh_blocks(README) if b and b[0].startswith("mpc-actuator generate"))
    shutil.copy(fmu_path, tmp_path / "mpc_actuator.fmu")
    monkeypatch.setenv("MPC_ACTUATOR_FMU", str(fmu_path))
    for line in tour:
        words = shlex.split(line)
        if words[0] == "mpc-actuator":
            args = [sys.executable, "-m", "harness", *words[1:], *REDUCED.get(words[1], [])]
            if "--quiet" in subcommand_options()[words[1]]:
                args.append("--quiet")
        elif words[0] == "fmpy":
            args = [sys.executable, "-m", "fmpy.cli", *words[1:]]
        else:
            raise AssertionError(f"unexpected command in the tour: {line}")
        _run(args, tmp_path, timeout=1800)
    for f in ("id/validation_table3.md", "diag/diagnosis.md", "diag/extended_params.json", "W20-D45.fmu", "step.csv"):
        assert (tmp_path / f).is_file() and (tmp_path / f).stat().st_size > 0, f
    assert "filler_saturation" in (tmp_path / "diag" / "diagnosis.md").read_text()


# --------------------------------------------------------------------------- the README's command list
def commands_block() -> list[str]:
    return next(b for b in sh_blocks(README) if b and b[0].startswith("mpc-actuator run --out DIR"))


def required_words(line: str) -> tuple[str, ...]:
    """A command line without its optional ``[...]`` parts (nested ones too) and ``...``."""
    prev = None
    while prev != line:
        prev, line = line, re.sub(r"\s*\[[^\[\]]*\]", "", line)
    return tuple(w for w in line.split() if w != "...")


FIXTURE = REPO / "tests" / "fixtures" / "clean-500hz-3-samples"
REDUCE_NSGA = ["--pop-size", "12", "--generations", "5"]
# required words of a README command -> (placeholder -> value, options added, files it must write); {t}: the test's
# folder, {fmu}/{ctl}: the session's FMUs. Options added are reductions (smaller NSGA-II, fewer samples, draws and
# grid points, skipped chain steps) and --quiet; the order is the order they run in (later ones read earlier outputs).
RECIPES: dict[tuple[str, ...], tuple[dict, list, list]] = {
    ("python", "build_fmu.py"): ({}, ["--out", "{t}/built.fmu"], ["built.fmu"]),
    ("python", "build_fmu.py", "--controller"): ({}, ["--out", "{t}/ctl.fmu"], ["ctl.fmu"]),
    ("python", "build_fmu.py", "--native"): ({}, ["--out", "{t}/native.fmu"], ["native.fmu"]),
    ("python", "build_fmu.py", "--native", "--fmi", "3"): ({}, ["--out", "{t}/native3.fmu"], ["native3.fmu"]),
    ("fmpy", "simulate", "mpc_actuator.fmu", "--output-file", "step.csv"): ({}, [], ["step.csv"]),
    ("fmpy", "validate", "mpc_actuator.fmu"): ({}, [], []),
    ("mpc-actuator", "crosscheck", "check", "references/W20-D45"): (
        {"references/W20-D45": str(REPO / "references" / "W20-D45")}, ["--fmu", "{fmu}"], []),
    ("mpc-actuator", "import", "MAPPING.json", "--out", "DIR"): (
        {"MAPPING.json": "{t}/map.json", "DIR": "{t}/imported"}, [], ["imported/manifest.json"]),
    ("mpc-actuator", "generate", "--out", "DIR"): (
        {"DIR": "{t}/ds"}, ["--samples", "W10-D30", "W20-D45", "W30-D45", "--effect", "filler_saturation=1",
                           "--quiet"], ["ds/manifest.json"]),
    ("mpc-actuator", "check", "DATASET"): ({"DATASET": "{t}/ds"}, [], []),
    ("mpc-actuator", "identify", "DATASET", "--out", "DIR"): (
        {"DATASET": "{t}/ds", "DIR": "{t}/id"}, REDUCE_NSGA + ["--quiet"], ["id/identification.json"]),
    ("mpc-actuator", "protocols", "DATASET", "--out", "DIR"): (
        {"DATASET": "{t}/ds", "DIR": "{t}/proto"}, ["--quiet"], ["proto/protocols_table3.md"]),
    ("mpc-actuator", "diagnose", "DATASET", "--out", "DIR"): (
        {"DATASET": "{t}/ds", "DIR": "{t}/diag"}, ["--quiet"], ["diag/diagnosis.md", "diag/extended_params.json"]),
    ("mpc-actuator", "uncertainty", "DATASET", "--params", "identification.json", "--out", "DIR"): (
        {"DATASET": "{t}/ds", "identification.json": "{t}/id/identification.json", "DIR": "{t}/unc"},
        ["--draws", "8", "--bootstrap", "200", "--workers", "2", "--quiet"], ["unc/uncertainty.json"]),
    ("mpc-actuator", "design", "--uncertainty", "DIR/uncertainty.json", "--out", "DIR2"): (
        {"DIR/uncertainty.json": "{t}/unc/uncertainty.json", "DIR2": "{t}/design"},
        # the default grid: the box around the three samples' triangle (its points outside the triangle are left out)
        ["--stroke-mm", "1", "--points", "4", "--draws", "4", "--refine", "1", "--step-s", "0.2", "--workers", "1",
         "--quiet"], ["design/design.json"]),
    ("mpc-actuator", "build", "--params", "FILE", "--out", "X.fmu"): (
        {"FILE": "{t}/diag/extended_params.json", "X.fmu": "{t}/W20-D45.fmu"}, ["--sample", "W20-D45"],
        ["W20-D45.fmu"]),
    ("mpc-actuator", "estimate", "DATASET", "--params", "FILE", "--test", "T5", "--out", "DIR"): (
        {"DATASET": "{t}/ds", "FILE": "{t}/id/identification.json", "DIR": "{t}/est"}, ["--sample", "W20-D45"],
        ["est/estimate.csv"]),
    ("mpc-actuator", "control", "--out", "DIR"): (
        {"DIR": "{t}/control"}, ["--fmu", "{fmu}", "--controller-fmu", "{ctl}", "--quiet"], ["control/control.json"]),
    ("mpc-actuator", "run", "DATASET", "--out", "DIR"): (
        {"DATASET": str(FIXTURE), "DIR": "{t}/chain"}, REDUCE_NSGA + ["--skip", "uncertainty", "control",
                                                                      "--workers", "2", "--quiet"],
        ["chain/report.md"]),
    ("mpc-actuator", "run", "--out", "DIR"): (
        {"DIR": "{t}/main"}, REDUCE_NSGA + ["--workers", "2", "--quiet"],
        ["main/identification/validation_table3.md", "main/diagnosis/diagnosis.md"]),
}
FAST = [("fmpy", "validate", "mpc_actuator.fmu"), ("mpc-actuator", "crosscheck", "check", "references/W20-D45"),
        ("mpc-actuator", "import", "MAPPING.json", "--out", "DIR"), ("mpc-actuator", "check", "DATASET"),
        ("mpc-actuator", "design", "--uncertainty", "DIR/uncertainty.json", "--out", "DIR2")]


def test_every_readme_command_has_a_recipe():
    shown = [required_words(line) for line in commands_block()]
    assert len(shown) >= 15
    assert set(shown) == set(RECIPES), (f"README commands without a recipe: {set(shown) - set(RECIPES)}; "
                                        f"recipes for no README command: {set(RECIPES) - set(shown)}")


def write_mapping(t: Path) -> None:
    """A lab-import mapping of the example dataset's files as they are (its CSVs, its columns)."""
    import json
    from harness.data.dataset import read_dataset
    ds = read_dataset(FIXTURE)
    samples = []
    for s in ds.samples:
        tests = {}
        for name, test in s.tests.items():
            spec = {"file": str(Path(test.file).resolve())}
            if hasattr(test, "time_s"):
                cols = {"time": "time_s", "voltage": "voltage_V", "current": "current_A"}
                spec.update(field_T=test.field_T, gap_mm=test.gap_mm)
                if test.frequency_hz is not None:
                    spec["frequency_hz"] = test.frequency_hz
            else:
                cols = {"gap": "gap_mm", "current": "current_A"}
                if test.field_T is not None:
                    spec["field_T"] = test.field_T
            if test.displacement_mm is not None:
                cols["displacement"] = "displacement_mm"
            else:
                cols["force"] = "force_N"
            tests[name] = {**spec, "columns": cols}
        samples.append({"id": s.id, "wt_pct": s.wt_pct, "diameter_mm": s.diameter_mm,
                        "thickness_mm": s.thickness_mm, "tests": tests})
    rig = {k: ds.rig[k] for k in ("coil_radius_mm", "field_per_amp_T_per_A", "sweep_average_s", "sweep_hold_s",
                                  "sample_period_s") if k in ds.rig}
    (t / "map.json").write_text(json.dumps({"format": "mpc-actuator-labimport/1", "rig": rig, "samples": samples}))


def run_readme_command(key, t: Path, fmu: Path, ctl: Path) -> None:
    subs, extra, outputs = RECIPES[key]
    fill = lambda w: w.format(t=t, fmu=fmu, ctl=ctl)
    words = [fill(subs.get(w, w)) for w in key] + [fill(w) for w in extra]
    if words[0] == "mpc-actuator":
        args = [sys.executable, "-m", "harness", *words[1:]]
    elif words[0] == "python":
        args = [sys.executable, str(REPO / words[1]), *words[2:]]
    else:
        args = [sys.executable, "-m", "fmpy.cli", *words[1:]]
    done = _run(args, t, timeout=3600)
    for f in outputs:
        assert (t / f).is_file() and (t / f).stat().st_size > 0, f"{' '.join(key)}: {f} not written"
    if key[:2] == ("mpc-actuator", "crosscheck"):
        assert done.stdout.rstrip().endswith("all passed"), done.stdout
    if key[:2] == ("mpc-actuator", "design"):          # the triangle's default grid: its corners left out
        import json
        d = json.loads((t / "design" / "design.json").read_text())
        assert 0 < d["grid_points_outside_hull"] < 16 and d["designs_evaluated"] < 256, d


def _prepare(t: Path, fmu_path: Path, monkeypatch) -> None:
    shutil.copy(fmu_path, t / "mpc_actuator.fmu")
    monkeypatch.setenv("MPC_ACTUATOR_FMU", str(fmu_path))
    write_mapping(t)


def write_triangle_uncertainty(t: Path) -> None:
    """``unc/uncertainty.json`` of the recipe's three samples (W10-D30, W20-D45, W30-D45: a triangle in (wt%, D)) at
    the virtual rig's true parameters with 1 % standard deviations (what ``uncertainty`` writes after the slow
    steps), for the design recipe in the default suite."""
    import json
    import numpy as np
    from harness.analysis.identification import parameter_uncertainty as U
    from harness.data import rig
    uncs = {}
    for w, d in ((10, 30), (20, 45), (30, 45)):
        p, sid = rig.true_params(w, d), rig.sample_id(w, d)
        uncs[sid] = U.ParameterUncertainty(sid, float(w), float(d), p, np.diag(
            (0.01 * np.array([getattr(p, n) for n in U.PARAMS])) ** 2))
    (t / "unc").mkdir()
    (t / "unc" / "uncertainty.json").write_text(json.dumps(U.uncertainty_to_json(uncs)))


def test_fast_readme_commands(tmp_path, fmu_path, monkeypatch):
    """The command-list lines that take seconds, in the default suite (``check`` on the example dataset, ``design``
    on the triangle's true parameters; the other inputs of the recipes are those of the slow test)."""
    _prepare(tmp_path, fmu_path, monkeypatch)
    shutil.copytree(FIXTURE, tmp_path / "ds")
    write_triangle_uncertainty(tmp_path)
    for key in FAST:
        run_readme_command(key, tmp_path, fmu_path, tmp_path / "no-controller.fmu")
    from harness.data.dataset import read_dataset
    assert [s.id for s in read_dataset(tmp_path / "imported").samples] == ["W10-D30", "W20-D45", "W30-D60"]


@pytest.mark.slow
def test_every_readme_command(tmp_path, fmu_path, controller_fmu_path, monkeypatch):
    """Every line of the README's command list, reduced as RECIPES says, in an order where each finds its inputs."""
    _prepare(tmp_path, fmu_path, monkeypatch)
    for key in RECIPES:
        run_readme_command(key, tmp_path, fmu_path, controller_fmu_path)


# --------------------------------------------------------------------------- which test runs each command, fast
# README command (required words) -> the default-suite test or fixture that runs it to success in a reduced form
# (besides FAST above); SLOW_ONLY: run only by test_every_readme_command (and the tests named), with the reason.
DEFAULT_RUNS = {
    ("python", "build_fmu.py"): "tests/conftest.py::fmu_path",
    ("python", "build_fmu.py", "--controller"): "tests/conftest.py::controller_fmu_path",
    ("python", "build_fmu.py", "--native"): "tests/conftest.py::native_fmu_path",
    ("python", "build_fmu.py", "--native", "--fmi", "3"): "tests/fmu/test_native_fmu_fmi3.py::native3_fmu_path",
    ("fmpy", "simulate", "mpc_actuator.fmu", "--output-file", "step.csv"):
        "tests/test_readme_commands.py::test_fmpy_commands_as_written",
    ("mpc-actuator", "generate", "--out", "DIR"): "tests/test_chain.py::test_chain_control_on_a_generated_dataset",
    ("mpc-actuator", "identify", "DATASET", "--out", "DIR"):
        "tests/cli/test_cli.py::test_identify_skip_incomplete_end_to_end",
    ("mpc-actuator", "build", "--params", "FILE", "--out", "X.fmu"):
        "tests/cli/test_cli.py::test_build_bakes_parameters_and_effects",
    ("mpc-actuator", "estimate", "DATASET", "--params", "FILE", "--test", "T5", "--out", "DIR"):
        "tests/cli/test_estimate_cli.py::test_estimate_writes_velocity_and_temperature",
    ("mpc-actuator", "run", "DATASET", "--out", "DIR"): "tests/test_chain.py::test_chain_on_the_reduced_bug_report_dataset",
}
SLOW_ONLY = {
    ("mpc-actuator", "protocols", "DATASET", "--out", "DIR"): "T1-T8 through the FMU per sample: minutes",
    ("mpc-actuator", "diagnose", "DATASET", "--out", "DIR"):
        "its function runs in the default suite inside `run DATASET` (test_chain), the command itself only here",
    ("mpc-actuator", "uncertainty", "DATASET", "--params", "identification.json", "--out", "DIR"):
        "needs an identification first; its function runs in tests/analysis",
    ("mpc-actuator", "control", "--out", "DIR"): "the study's closed loops: tests/cli/test_cli_control.py (slow)",
    ("mpc-actuator", "run", "--out", "DIR"): "the main job: 11 samples generated and identified (CI's make run)",
}


def _function_node(ref: str):
    import ast
    path, name = ref.split("::")
    tree = ast.parse((REPO / path).read_text(encoding="utf-8"))
    return next((n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name), None), path


def test_each_readme_command_runs_in_the_default_suite_or_is_said_slow():
    """Every command-list line is run fast (FAST here, or the test named in DEFAULT_RUNS, which exists, is not
    behind a marker and runs that command), or is listed in SLOW_ONLY with the reason."""
    import ast
    keys = set(RECIPES)
    assert set(FAST) | set(DEFAULT_RUNS) | set(SLOW_ONLY) == keys
    assert not (set(FAST) & set(DEFAULT_RUNS) or set(FAST) & set(SLOW_ONLY) or set(DEFAULT_RUNS) & set(SLOW_ONLY))
    for key, ref in DEFAULT_RUNS.items():
        node, path = _function_node(ref)
        assert node is not None, f"{ref} (for `{' '.join(key)}`) does not exist"
        marks = {ast.unparse(d) for d in node.decorator_list}
        assert not any("slow" in m or "deep" in m for m in marks), (ref, marks)
        src = ast.unparse(node)
        word = key[1] if key[0] != "python" else (key[2] if len(key) > 2 else "build_fmu.py")
        assert word in src, f"{ref} does not run `{' '.join(key)}`"
        if path != "tests/conftest.py":
            assert not re.search(r"^pytestmark", (REPO / path).read_text(encoding="utf-8"), re.M), path
