"""The virtual test rig, run: SYNTHETIC datasets of the paper's 11 samples and tests T1-T8.

The rig itself (samples, "true" parameters, hidden effects, sensor models) is described in
``harness.data.rig``; this module runs it: each test through a simulator (by default mpc_actuator.fmu through
fmpy, ``harness.sim.fmurun``; any callable ``simulator(params, t, V) -> {"time", "I", "x_sensor", "F_sensor"}``
can stand in, e.g. :class:`ModelSimulator`, the in-process model of the same code), then the sensor models.
The laser and force-transducer readings are the simulator's x_sensor and F_sensor (equal to x and F unless
sensor_lag is on). Each T1/T7 gap is a separate run from rest (the coil starts cold at every gap). Same seed,
same bytes.
"""
from __future__ import annotations

import zlib
import contextlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fmu_src.coil import voltage_for_field
from fmu_src.specs import Params
from harness.data import protocol
from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries, write_dataset
from harness.data.paramsjson import params_to_json
from harness.data.protocol import (FIELDS_T, PRE_STEP_S as PRE_S, STEP_POST_S, SWEEP_GAPS_MM, SWEEP_HOLD_S,
                                   T6_FREQUENCY_HZ, T6_PERIODS, sine_voltage, step_voltage, time_grid)
from harness.data.rig import (ALL_SAMPLES, CURRENT, SENSORS, THICKNESS_MM, apply_effects, check_effects,
                              rig_description, sample_id, true_params)
from harness.parallel import process_pool
from harness.sim import fmurun


@dataclass(frozen=True)
class FMUSimulator:
    """Runs of mpc_actuator.fmu through fmpy (``fmu_path`` None: the repository's build); picklable."""
    fmu_path: str | Path | None = None

    def __call__(self, params: Params, t, V) -> dict:
        return fmurun.run(params, t, V, fmu_path=self.fmu_path)


@dataclass(frozen=True)
class ModelSimulator:
    """Runs of the in-process model ``fmu_src.model.simulate`` (the code the FMU wraps, without fmpy)."""

    def __call__(self, params: Params, t, V) -> dict:
        from fmu_src.model import simulate
        r = simulate(params, t, V)
        r["time"] = r["t"]
        return r


def _rng(seed: int, *key) -> np.random.Generator:
    words = [zlib.crc32("/".join(map(str, key)).encode())]
    return np.random.default_rng(np.random.SeedSequence([int(seed), *words]))


def _sweep_point(args):
    params, gap_mm, blocked, V, simulator = args
    t = time_grid(SWEEP_HOLD_S)
    return simulator(params.with_(r0=gap_mm / 1000.0, blocked=blocked), t, np.full(t.shape, V))


def _steady(values, t):
    return values[protocol.sweep_average_mask(t, protocol.SWEEP_AVERAGE_S)]


def generate_sample(wt_pct, diameter_mm, seed=0, simulator=None, pool=None, effects=None):
    """Generate all eight tests of one sample; returns (sample id, true Params, {test: table}).

    ``simulator``: ``simulator(params, t, V) -> dict`` (default :class:`FMUSimulator` of the repository's
    FMU); ``pool``: an executor whose ``map`` runs the simulations (None: in this process)."""
    simulator = simulator if simulator is not None else FMUSimulator()
    sid = sample_id(wt_pct, diameter_mm)
    p = apply_effects(true_params(wt_pct, diameter_mm), effects)
    Vf = {k: voltage_for_field(b, p.kB, p.R) for k, b in FIELDS_T.items()}
    mapper = pool.map if pool is not None else map
    tests = {}
    # T1 and T7: one run per gap
    for test in protocol.SWEEP_TESTS:
        blocked, col = protocol.TESTS[test].blocked, protocol.TESTS[test].measured
        runs = list(mapper(_sweep_point, [(p, g, blocked, Vf[test], simulator) for g in SWEEP_GAPS_MM]))
        rng = _rng(seed, sid, test)
        gaps, cur, val = [], [], []
        for g, r in zip(SWEEP_GAPS_MM, runs):
            tt = r["time"]
            true_y = r["x_sensor"] * 1e3 if col == "displacement_mm" else r["F_sensor"]
            y = SENSORS[col].measure(_steady(true_y, tt), rng)
            i = CURRENT.measure(_steady(r["I"], tt), rng)
            gaps.append(float(g)); cur.append(float(np.mean(i))); val.append(float(np.mean(y)))
        kw = {"displacement_mm": None, "force_N": None}
        kw[col] = np.array(val)
        tests[test] = GapSweep(test=test, file=Path(sid) / f"{test}.csv", gap_mm=np.array(gaps),
                               current_A=np.array(cur), field_T=FIELDS_T[test], **kw)
    # gap of maximum T1 displacement, from the measured sweep (as an experimenter would)
    g_max = protocol.max_displacement_gap_mm(tests["T1"].gap_mm, tests["T1"].displacement_mm)
    plan = {n: (protocol.planned_gap_mm(n, g_max), protocol.TESTS[n].blocked) for n in protocol.TIME_SERIES_TESTS}
    jobs = []
    for test, (gap, blocked) in plan.items():
        if protocol.TESTS[test].drive == "sine":
            t = time_grid(PRE_S + T6_PERIODS / T6_FREQUENCY_HZ)
            V = sine_voltage(t, Vf[test])
        else:
            t = time_grid(PRE_S + STEP_POST_S)
            V = step_voltage(t, Vf[test])
        jobs.append((test, gap, blocked, t, V))
    results = list(mapper(_run_job, [(p.with_(r0=g / 1000.0, blocked=b), t, V, simulator) for _, g, b, t, V in jobs]))
    for (test, gap, blocked, t, V), r in zip(jobs, results):
        rng = _rng(seed, sid, test)
        col = protocol.TESTS[test].measured
        true_y = r["F_sensor"] if blocked else r["x_sensor"] * 1e3
        kw = {"displacement_mm": None, "force_N": None}
        kw[col] = SENSORS[col].measure(true_y, rng)
        tests[test] = TimeSeries(test=test, file=Path(sid) / f"{test}.csv", time_s=t, voltage_V=V,
                                 current_A=CURRENT.measure(r["I"], rng), field_T=FIELDS_T[test],
                                 gap_mm=gap, frequency_hz=protocol.TESTS[test].frequency_hz, **kw)
    return sid, p, dict(sorted(tests.items()))


def _run_job(args):
    params, t, V, simulator = args
    return simulator(params, t, V)


def generate_dataset(out_dir, seed: int = 0, samples=ALL_SAMPLES, fmu_path=None, effects=None,
                     workers: int = 2, progress: bool = True, overwrite: bool = False):
    """Generate a synthetic dataset (format mpc-actuator-data/1) into out_dir; returns the Dataset.

    Same seed, same bytes. ``effects`` maps effect names (``fmu_src.effects.EFFECTS``) to
    magnitudes (see ``EFFECT_MAGNITUDES``); they are hidden in the data and recorded in
    the manifest's rig.effects, their parameters in rig.true_parameters.
    """
    from tqdm import tqdm
    effects = check_effects(effects)   # fail before any simulation
    samples = list(samples)
    truth = {}
    out_samples = []
    with (process_pool(workers) if workers and workers > 1 else contextlib.nullcontext()) as pool:
        it = tqdm(samples, desc="virtual rig", unit="sample", disable=not progress)
        for w, d in it:
            sid, p, tests = generate_sample(w, d, seed=seed, simulator=FMUSimulator(fmu_path), pool=pool, effects=effects)
            truth[sid] = p
            out_samples.append(Sample(id=sid, wt_pct=float(w), diameter_mm=float(d),
                                      thickness_mm=THICKNESS_MM, tests=tests))
    rig = rig_description(effects)
    rig["true_parameters"] = {sid: params_to_json(p) for sid, p in truth.items()}
    rig["effects"] = dict(effects)
    rig["seed"] = int(seed)
    ds = Dataset(root=Path(out_dir), synthetic=True,
                 description=("SYNTHETIC data from the mpc-actuator virtual test rig (not the paper's "
                              "measurements): mpc_actuator.fmu run through fmpy with smooth 'true' parameters "
                              "per sample, plus sensor noise and quantization."
                              + (f" Hidden effects (rig.effects): {', '.join(f'{k}={v:g}' for k, v in effects.items())}."
                                 if effects else "")),
                 rig=rig, samples=out_samples)
    write_dataset(ds, out_dir, overwrite=overwrite)
    return ds
