"""Validation of a model against measured data: the protocols T1-T8 replayed through the FMU and compared.

The FMU runs are :func:`harness.sim.replay.simulate_sample`'s; the outputs are compared with the
measured ones (``harness.analysis.core.metrics``):

* T2-T5 (displacement steps), T8 (blocked-force step): RMSE, 2 % settling times and their error
  (robust settling time with the sensor's noise sigma from the manifest, else estimated);
* T6 (1 Hz sine): amplitude ratio and phase shift at the drive frequency, RMSE;
* T1/T7 (gap sweeps): RMSE over the gaps.

Step tests are replayed with their step at the instant estimated from the current's RL rise
(:func:`with_step_instants`); each test at its own sample period (its time column).

Current RMSE is reported for every time-series test.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import numpy as np

from fmu_src.specs import Params
from harness.analysis.core import metrics
from harness.data import protocol
from harness.data.dataset import Dataset, Sample, TimeSeries
from harness.parallel import process_pool
from harness.sim import replay


@dataclass
class SampleRun:
    """Results of running one sample's tests: metric records and traces for the figures."""
    sample: str
    records: list = field(default_factory=list)
    traces: dict = field(default_factory=dict)


def _noise_sigma(rig: dict, column: str):
    """The sensor's white-noise std [unit of column] from the manifest, else "auto" (estimated by metrics)."""
    v = protocol.noise_floor(rig, column, quantization=False)
    return "auto" if v is None else v


def with_step_instants(sample: Sample) -> Sample:
    """The sample with each pure step's voltage as the FMU (holding each sample's input over its interval)
    must see it for the step instant estimated from the current's RL rise
    (:func:`harness.analysis.identification.conventions.held_step_voltage`); a copy, other tests unchanged."""
    from dataclasses import replace

    from harness.analysis.identification.conventions import held_step_voltage
    tests = {n: (replace(ts, voltage_V=held_step_voltage(n, ts)) if isinstance(ts, TimeSeries) else ts)
             for n, ts in sample.tests.items()}
    return replace(sample, tests=tests)


def run_sample(sample: Sample, params: Params, rig: dict | None = None, fmu_path=None,
               pool=None, tests=None) -> SampleRun:
    """Run every available test of a sample through the FMU with the given parameters and compare.

    Returns the metric records (one per test) and the traces for the figures.
    """
    rig = rig or {}
    names = [n for n in sorted(sample.tests) if tests is None or n in tests]
    out = SampleRun(sample.id)
    base = {"sample": sample.id, "wt_pct": sample.wt_pct, "diameter_mm": sample.diameter_mm}
    sims = replay.simulate_sample(with_step_instants(sample), params, rig=rig, fmu_path=fmu_path, pool=pool,
                                  tests=names)

    for n in names:
        test = sample.tests[n]
        rec = dict(base, test=n)
        if isinstance(test, TimeSeries):
            sim = sims.series[n]
            col = "force_N" if test.force_N is not None else "displacement_mm"
            unit = "N" if col == "force_N" else "mm"
            y_meas = test.force_N if col == "force_N" else test.displacement_mm
            # compare what the sensors see (identical to x and F unless the model has a sensor lag)
            y_sim = sim["F_sensor"] if col == "force_N" else sim["x_sensor"] * 1e3
            rec["current_rmse_A"] = metrics.rmse(test.current_A, sim["I"])
            if protocol.TESTS[n].drive == "sine":
                rec.update(metrics.sine_metrics(test.time_s, y_meas, y_sim, float(test.frequency_hz or 1.0), unit=unit))
            else:
                t_on = protocol.step_onset(test.time_s, test.voltage_V).time_s
                rec.update(metrics.step_metrics(test.time_s, y_meas, y_sim, t_step=t_on,
                                                noise_sigma=_noise_sigma(rig, col), unit=unit))
            rec["contact"] = bool(np.any(sim["contact"]))
            out.traces[n] = {"time_s": test.time_s, "voltage_V": test.voltage_V,
                             "current_A_meas": test.current_A, "current_A_sim": sim["I"],
                             "y_meas": y_meas, "y_sim": y_sim, "quantity": col}
        else:
            blocked = protocol.TESTS[n].blocked
            col = protocol.TESTS[n].measured
            unit = "N" if blocked else "mm"
            y_meas = test.force_N if blocked else test.displacement_mm
            y_sim = np.array([s["F_N"] if blocked else s["x_mm"] for s in sims.sweeps[n]])
            rec[f"rmse_{unit}"] = metrics.sweep_rmse(test.gap_mm, y_meas, test.gap_mm, y_sim)
            out.traces[n] = {"gap_mm": test.gap_mm, "y_meas": y_meas, "y_sim": y_sim, "quantity": col}
        out.records.append(rec)
    return out


def run_dataset(ds: Dataset, params_by_sample: dict, fmu_path=None, workers: int = 2,
                progress: bool = True, tests=None) -> list[SampleRun]:
    """Run the protocols of every sample that has parameters in ``params_by_sample``."""
    from tqdm import tqdm
    missing = [s.id for s in ds.samples if s.id not in params_by_sample]
    chosen = [s for s in ds.samples if s.id in params_by_sample]
    if not chosen:
        raise ValueError(f"no parameters for any sample of {ds.root} (samples without: {missing})")
    with (process_pool(workers) if workers and workers > 1 else contextlib.nullcontext()) as pool:
        runs = []
        for s in tqdm(chosen, desc="protocols T1-T8 via FMU", unit="sample", disable=not progress):
            runs.append(run_sample(s, params_by_sample[s.id], rig=ds.rig, fmu_path=fmu_path, pool=pool, tests=tests))
        return runs
