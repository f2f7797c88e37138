"""Run mpc_actuator.fmu through fmpy: one place that knows how the harness calls the FMU.

The FMU is extracted once per process and per path (under ``harness.scratch``'s folder); every run passes an explicit
``output_interval`` (the communication step in co-simulation) and the input
voltage as a time series held constant over each communication step.
"""
from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path

import numpy as np

from fmu_src.specs import EFFECT_FIELDS, TERM_FIELDS, Params, param_names
from harness import scratch

OUTPUTS = ("x", "v", "F", "I", "B", "contact", "x_sensor", "F_sensor")
_EXTRACTED: dict[str, tuple] = {}


def default_fmu_path() -> Path:
    """mpc_actuator.fmu next to the repository root, or $MPC_ACTUATOR_FMU."""
    env = os.environ.get("MPC_ACTUATOR_FMU")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / "mpc_actuator.fmu"   # harness/sim/fmurun.py -> repository root


def _prepared(fmu_path: Path):
    import fmpy
    key = str(Path(fmu_path).resolve())
    mtime = Path(key).stat().st_mtime_ns
    hit = _EXTRACTED.get(key)
    if hit is None or hit[0] != mtime:
        if not Path(key).exists():
            raise FileNotFoundError(f"FMU not found: {key} (build it with `python build_fmu.py`)")
        md = fmpy.read_model_description(key)
        # under the command's scratch folder (harness.scratch): removed however the command ends (the atexit
        # handler used before never ran in a pool worker, which ends with os._exit)
        unzipdir = fmpy.extract(key, unzipdir=scratch.new_dir("fmu-"))
        hit = (mtime, md, unzipdir)
        _EXTRACTED[key] = hit
    return hit[1], hit[2]


def start_values(params: Params) -> dict:
    """FMU start values for a parameter set (SI, names as in the modelDescription).

    Effect parameters (fmu_src.effects) and the term set's (fmu_src.terms) are passed when they are not 0
    (their default, off), so runs of the plain model set exactly what they set before.
    """
    d = asdict(params)
    sv = {k: float(d[k]) for k in param_names()}
    sv["blocked"] = bool(d["blocked"])
    sv.update({k: float(d[k]) for k in EFFECT_FIELDS + TERM_FIELDS if d[k] != 0.0})
    return sv


def run(params: Params, t, V, fmu_path=None, outputs=OUTPUTS) -> dict:
    """Simulate the FMU on the uniform grid t [s] with input voltage samples V [V].

    V[k] is applied over [t[k], t[k+1]). Returns a dict of numpy arrays keyed by
    output name plus "time"; outputs are sampled at every grid point.
    """
    import fmpy
    t = np.asarray(t, dtype=float)
    V = np.broadcast_to(np.asarray(V, dtype=float), t.shape)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError("time grid t must be 1-D with at least two points")
    dt = np.diff(t)
    step = float(np.median(dt))
    if np.max(np.abs(dt - step)) > 1e-9 * max(1.0, abs(t[-1])):
        raise ValueError("time grid t must be uniform (the communication step)")
    md, unzipdir = _prepared(Path(fmu_path or default_fmu_path()))
    sig = np.zeros(len(t), dtype=[("time", np.float64), ("V", np.float64)])
    sig["time"] = t
    sig["V"] = V
    res = fmpy.simulate_fmu(
        unzipdir, model_description=md, start_time=float(t[0]), stop_time=float(t[-1]),
        output_interval=step, input=sig, start_values=start_values(params),
        output=list(outputs), validate=False,
    )
    n = len(t)
    out = {"time": np.asarray(res["time"][:n], dtype=float)}
    for k in outputs:
        out[k] = np.asarray(res[k][:n])
    if len(out["time"]) != n or np.max(np.abs(out["time"] - t)) > 1e-9 * max(1.0, abs(t[-1])):
        raise RuntimeError(f"FMU returned {len(res)} samples on another grid than requested ({n})")
    return out
