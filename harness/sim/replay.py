"""Protocol replay: fmpy drives mpc_actuator.fmu through a sample's tests T1-T8 with the measured inputs.

For each test the measured voltage is replayed as the FMU input (one fmpy run per time-series test;
one run per gap for the sweeps T1/T7, energized from rest at the voltage the measured current needs
and averaged as the protocol says, spread over the cores); the gap and blocked mode come from the
manifest (:func:`params_for_test`). :func:`simulate_sample` returns the outputs;
:mod:`harness.analysis.validation.run` compares them with the measured data.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fmu_src.specs import Params
from harness.data import protocol
from harness.data.dataset import GapSweep, Sample, TimeSeries
from harness.sim import fmurun

SERIES_OUTPUTS = ("x_sensor", "F_sensor", "I", "contact")
SWEEP_OUTPUTS = ("x_sensor", "F_sensor", "I")


@dataclass
class SampleSims:
    """FMU outputs of one sample's tests.

    series: {test: {"time", "x_sensor" [m], "F_sensor" [N], "I" [A], "contact"}} on the measured grid;
    sweeps: {test: [{"x_mm" [mm], "F_N" [N], "I_A" [A]} steady values, one per measured gap]}.
    """
    series: dict = field(default_factory=dict)
    sweeps: dict = field(default_factory=dict)


def _sim_series(args):
    params, t, V, fmu_path = args
    return fmurun.run(params, t, V, fmu_path=fmu_path, outputs=SERIES_OUTPUTS)


def _sim_sweep_point(args):
    params, V, timing, fmu_path = args
    t = protocol.time_grid(timing.hold_s, timing.sample_period_s)
    r = fmurun.run(params, t, np.full(t.shape, V), fmu_path=fmu_path, outputs=SWEEP_OUTPUTS)
    sel = protocol.sweep_average_mask(t, timing.average_s)
    return {"x_mm": float(np.mean(r["x_sensor"][sel]) * 1e3), "F_N": float(np.mean(r["F_sensor"][sel])),
            "I_A": float(np.mean(r["I"][sel]))}


def params_for_test(params: Params, test) -> Params:
    """The sample's parameters with the gap and blocked mode of one test."""
    blocked = protocol.TESTS[test.test].blocked
    gap_mm = float(test.gap_mm) if isinstance(test, TimeSeries) else 0.0
    return params.with_(r0=gap_mm / 1000.0, blocked=blocked)


def simulate_sample(sample: Sample, params: Params, rig: dict | None = None, fmu_path=None,
                    pool=None, tests=None) -> SampleSims:
    """Run the sample's tests (all, or those named in ``tests``) through the FMU with ``params``.

    Parameters
    ----------
    sample : Sample
        Measured tests (their voltage, gap, blocked mode; sweeps: their gaps and currents).
    params : Params
        The sample's model parameters (SI).
    rig : dict, optional
        The manifest's rig object (sweep timing: :func:`harness.data.protocol.sweep_timing`).
    fmu_path : path, optional
        The FMU (default: :func:`harness.sim.fmurun.default_fmu_path`).
    pool : executor, optional
        Its ``map`` spreads the runs (e.g. a ProcessPoolExecutor); None: in this process.
    tests : iterable of str, optional
        Test names to run.
    """
    mapper = pool.map if pool is not None else map
    names = [n for n in sorted(sample.tests) if tests is None or n in tests]
    out = SampleSims()
    series = [n for n in names if isinstance(sample.tests[n], TimeSeries)]
    jobs = []
    for n in series:
        ts = sample.tests[n]
        jobs.append((params_for_test(params, ts), ts.time_s, ts.voltage_V, fmu_path))
    out.series = dict(zip(series, mapper(_sim_series, jobs)))

    timing = protocol.sweep_timing(rig or {})
    for n in (n for n in names if isinstance(sample.tests[n], GapSweep)):
        sw = sample.tests[n]
        blocked = protocol.TESTS[n].blocked
        sjobs = [(params.with_(r0=g / 1000.0, blocked=blocked), float(i) * params.R, timing, fmu_path)
                 for g, i in zip(sw.gap_mm, sw.current_A)]
        out.sweeps[n] = list(mapper(_sim_sweep_point, sjobs))
    return out
