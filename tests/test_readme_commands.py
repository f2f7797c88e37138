"""Every command of the README is run (issue 23 "Done when"; ``tests/test_docs.py`` only checks that the commands
and options exist in the parser).

* default suite: ``fmpy simulate mpc_actuator.fmu --output-file step.csv`` and ``fmpy validate mpc_actuator.fmu``
  exactly as the README writes them (on the session's FMU, in a temporary folder), and ``make run`` / ``make test``
  through ``make -n`` (what they would run: the set-up, the FMU builds, ``mpc-actuator run --out out`` and the
  pytest line; running them for real takes the whole main job or the whole suite, which CI does);
* ``-m slow``: the five-minute tour's shell block, line by line, in a temporary folder. ``mpc-actuator`` is run as
  ``python -m harness`` of this checkout; ``identify`` gets ``--pop-size 12 --generations 5`` (the README's default
  64 x 60 takes minutes more) and every command ``--quiet``; nothing else is changed. Each must exit 0 and leave
  the files the README names (``id/validation_table3.md``, ``diag/diagnosis.md``, the FMU, ``step.csv``).
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
            if words[1] != "check":
                args.append("--quiet")
        elif words[0] == "fmpy":
            args = [sys.executable, "-m", "fmpy.cli", *words[1:]]
        else:
            raise AssertionError(f"unexpected command in the tour: {line}")
        _run(args, tmp_path, timeout=1800)
    for f in ("id/validation_table3.md", "diag/diagnosis.md", "diag/extended_params.json", "W20-D45.fmu", "step.csv"):
        assert (tmp_path / f).is_file() and (tmp_path / f).stat().st_size > 0, f
    assert "filler_saturation" in (tmp_path / "diag" / "diagnosis.md").read_text()
