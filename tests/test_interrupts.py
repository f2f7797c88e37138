"""Ctrl-C, SIGTERM and SIGKILL during the parallel commands: no hang, one line, no orphan (issue 24, parts 1-2).

Each command runs in its own session (process group), as from a terminal; the signal goes to the whole group
(Ctrl-C: the terminal sends SIGINT to every process of the foreground group, workers included), or SIGTERM /
SIGKILL to the main process alone (``timeout``, a CI runner). Checked: the command ends (a hang would be caught by
the generous ``END_S`` bound: this is no speed test), with exit code 130 (SIGINT), 143 (SIGTERM) or 0 (it
finished first); stderr holds no traceback and one ``interrupted:``/``terminated:`` line; the output folder is
left as it was (absent); no process of the group is left after ``ORPHAN_S`` (after SIGKILL of the main process
its workers notice their parent is gone: ``harness.parallel``). The default suite sends one signal per command at
a random moment; ``-m deep`` sends 20 per command and signal (``MPC_INTERRUPT_TRIES`` overrides).
"""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FIXTURE = REPO / "tests" / "fixtures" / "clean-500hz-3-samples"
END_S = 30.0           # a command still running this long after the signal is hung
ORPHAN_S = 5.0         # workers must be gone this long after the main process ended


def _commands(tmp: Path) -> dict:
    py = [sys.executable, "-m", "harness"]
    return {
        "generate": py + ["generate", "--out", str(tmp / "out"), "--samples", "W20-D45", "W10-D30", "--quiet",
                          "--workers", "2"],
        "diagnose": py + ["diagnose", str(FIXTURE), "--out", str(tmp / "out"), "--quiet", "--workers", "2"],
        "identify": py + ["identify", str(FIXTURE), "--out", str(tmp / "out"), "--quiet", "--workers", "2",
                          "--pop-size", "12", "--generations", "4"],
    }


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def _wait_group_gone(pgid: int, timeout_s: float) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        # zombies of the group count as gone once reaped; the main process is reaped by communicate()
        if not _group_alive(pgid):
            return True
        time.sleep(0.1)
    return not _group_alive(pgid)


def interrupt_once(cmd: list, out: Path, how: str, delay_s: float) -> dict:
    """Run ``cmd``, send ``how`` ("int" to the group, "term" or "kill" to the main process) after ``delay_s``;
    return what happened."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    pgid = p.pid
    time.sleep(delay_s)
    sent = p.poll() is None
    if sent:
        if how == "int":
            os.killpg(pgid, signal.SIGINT)
        else:
            os.kill(p.pid, signal.SIGTERM if how == "term" else signal.SIGKILL)
    t0 = time.monotonic()
    try:
        stdout, stderr = p.communicate(timeout=END_S)
        hung = False
    except subprocess.TimeoutExpired:
        hung = True
        os.killpg(pgid, signal.SIGKILL)
        stdout, stderr = p.communicate()
    ended_s = time.monotonic() - t0
    orphans = not _wait_group_gone(pgid, ORPHAN_S)
    if orphans:
        os.killpg(pgid, signal.SIGKILL)
    return dict(sent=sent, hung=hung, ended_s=ended_s, code=p.returncode, stderr=stderr, orphans=orphans,
                out_exists=out.exists())


def _check(r: dict, how: str, name: str):
    assert not r["hung"], f"{name}: still running {END_S} s after SIG{how.upper()}; stderr: {r['stderr'][-800:]!r}"
    assert not r["orphans"], f"{name}: worker processes left {ORPHAN_S} s after the main process ended"
    if not r["sent"] or r["code"] == 0:
        return                                       # it finished before the signal
    err = r["stderr"]
    if how == "kill":
        assert r["code"] == -signal.SIGKILL
        return
    assert "Traceback" not in err, f"{name}: traceback after SIG{how.upper()}:\n{err}"
    want = {"int": (130, "interrupted"), "term": (128 + signal.SIGTERM, "terminated")}[how]
    assert r["code"] == want[0], (name, r["code"], err)
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(want[1]), f"{name}: expected one line '{want[1]}: ...':\n{err}"
    assert not r["out_exists"], f"{name}: the output folder was written although the run was interrupted"


def _tries(default: int) -> int:
    return int(os.environ.get("MPC_INTERRUPT_TRIES", default))


@pytest.mark.parametrize("how", ["int", "term", "kill"])
@pytest.mark.parametrize("name", ["generate", "diagnose"])
def test_one_signal_at_a_random_moment(tmp_path, name, how):
    rng = random.Random(f"{name}-{how}")
    r = interrupt_once(_commands(tmp_path)[name], tmp_path / "out", how, rng.uniform(2.5, 6.0))
    _check(r, how, name)


@pytest.mark.deep
@pytest.mark.parametrize("how", ["int", "term", "kill"])
@pytest.mark.parametrize("name", ["generate", "diagnose", "identify"])
def test_deep_many_signals_at_random_moments(tmp_path, name, how):
    rng = random.Random(f"deep-{name}-{how}")
    for k in range(_tries(20)):
        sub = tmp_path / f"try{k}"
        sub.mkdir()
        r = interrupt_once(_commands(sub)[name], sub / "out", how, rng.uniform(1.0, 12.0))
        _check(r, how, f"{name} try {k}")
