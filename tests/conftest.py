"""Shared fixtures: the FMU is built once per test session (per xdist worker) into a temp dir.

The build runs in a subprocess so that the test process never imports the slave
module ``mpc_actuator`` itself (pythonfmu imports it by that name when an FMU is
instantiated in-process, and a cached copy would shadow the one in the FMU).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def fmu_path(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fmu") / "mpc_actuator.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, f"build_fmu.py failed:\n{proc.stdout}\n{proc.stderr}"
    assert out.is_file()
    return out


@pytest.fixture(scope="session")
def unzipdir(fmu_path, tmp_path_factory) -> str:
    from fmpy import extract
    return extract(str(fmu_path), unzipdir=str(tmp_path_factory.mktemp("fmu_unzipped")))


@pytest.fixture(scope="session")
def model_description(fmu_path):
    from fmpy import read_model_description
    return read_model_description(str(fmu_path), validate=True)


@pytest.fixture(scope="session")
def controller_fmu_path(tmp_path_factory) -> Path:
    """mpc_controller.fmu (``build_fmu.py --controller``), built once per session into a temp dir."""
    out = tmp_path_factory.mktemp("controller_fmu") / "mpc_controller.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--controller", "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, f"build_fmu.py --controller failed:\n{proc.stdout}\n{proc.stderr}"
    return out


@pytest.fixture(scope="session")
def fmu3_path(tmp_path_factory) -> Path:
    """mpc_actuator_fmi3.fmu (``build_fmu.py --fmi 3``, pythonfmu3), built once per session."""
    out = tmp_path_factory.mktemp("fmu3") / "mpc_actuator_fmi3.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--fmi", "3", "--out", str(out)], cwd=REPO,
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


@pytest.fixture(scope="session")
def native_fmu_path(tmp_path_factory) -> Path:
    """mpc_actuator_native.fmu (``build_fmu.py --native``: the model compiled to C), built once per session."""
    out = tmp_path_factory.mktemp("native_fmu") / "mpc_actuator_native.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--native", "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, f"build_fmu.py --native failed:\n{proc.stdout}\n{proc.stderr}"
    assert not proc.stderr.strip(), f"build_fmu.py --native warned:\n{proc.stderr}"
    return out
