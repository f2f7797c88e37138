"""Protocol runner: fmpy drives mpc_actuator.fmu through T1-T8 and compares with measured data.

For each sample and test the measured voltage is replayed as the FMU input (one
fmpy run per time-series test; one run per gap for the sweeps T1/T7, spread
over the cores), the gap and blocked mode are set from the manifest, and the
outputs are compared with the measured ones (``harness.analysis.metrics``):

* T2-T5 (displacement steps), T8 (blocked-force step): RMSE, 2 % settling times and their error;
* T6 (1 Hz sine): amplitude ratio and phase shift at the drive frequency, RMSE;
* T1/T7 (gap sweeps): RMSE over the gaps.

Current RMSE is reported for every time-series test.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmu_src.params import Params
from harness.sim import fmurun
from harness.analysis import metrics
from harness.data import protocol
from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries


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


def _sim_series(args):
    params, t, V, fmu_path = args
    return fmurun.run(params, t, V, fmu_path=fmu_path, outputs=("x_sensor", "F_sensor", "I", "contact"))


def _sim_sweep_point(args):
    params, V, timing, fmu_path = args
    t = protocol.time_grid(timing.hold_s, timing.sample_period_s)
    r = fmurun.run(params, t, np.full(t.shape, V), fmu_path=fmu_path, outputs=("x_sensor", "F_sensor", "I"))
    sel = protocol.sweep_average_mask(t, timing.average_s)
    return {"x_mm": float(np.mean(r["x_sensor"][sel]) * 1e3), "F_N": float(np.mean(r["F_sensor"][sel])),
            "I_A": float(np.mean(r["I"][sel]))}


def params_for_test(params: Params, test) -> Params:
    """The sample's parameters with the gap and blocked mode of one test."""
    blocked = protocol.TESTS[test.test].blocked
    gap_mm = float(test.gap_mm) if isinstance(test, TimeSeries) else 0.0
    return params.with_(r0=gap_mm / 1000.0, blocked=blocked)


def run_sample(sample: Sample, params: Params, rig: dict | None = None, fmu_path=None,
               pool=None, tests=None) -> SampleRun:
    """Run every available test of a sample through the FMU with the given parameters."""
    rig = rig or {}
    mapper = pool.map if pool is not None else map
    names = [n for n in sorted(sample.tests) if tests is None or n in tests]
    out = SampleRun(sample.id)
    base = {"sample": sample.id, "wt_pct": sample.wt_pct, "diameter_mm": sample.diameter_mm}

    series = [n for n in names if isinstance(sample.tests[n], TimeSeries)]
    jobs = []
    for n in series:
        ts = sample.tests[n]
        jobs.append((params_for_test(params, ts), ts.time_s, ts.voltage_V, fmu_path))
    sims = dict(zip(series, mapper(_sim_series, jobs)))

    sweeps = [n for n in names if isinstance(sample.tests[n], GapSweep)]
    timing = protocol.sweep_timing(rig)
    sweep_sims = {}
    for n in sweeps:
        sw = sample.tests[n]
        blocked = protocol.TESTS[n].blocked
        sjobs = [(params.with_(r0=g / 1000.0, blocked=blocked), float(i) * params.R, timing, fmu_path)
                 for g, i in zip(sw.gap_mm, sw.current_A)]
        sweep_sims[n] = list(mapper(_sim_sweep_point, sjobs))

    for n in names:
        test = sample.tests[n]
        rec = dict(base, test=n)
        if isinstance(test, TimeSeries):
            sim = sims[n]
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
            y_sim = np.array([s["F_N"] if blocked else s["x_mm"] for s in sweep_sims[n]])
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
    pool = ProcessPoolExecutor(max_workers=workers) if workers and workers > 1 else None
    try:
        runs = []
        for s in tqdm(chosen, desc="protocols T1-T8 via FMU", unit="sample", disable=not progress):
            runs.append(run_sample(s, params_by_sample[s.id], rig=ds.rig, fmu_path=fmu_path, pool=pool, tests=tests))
        return runs
    finally:
        if pool is not None:
            pool.shutdown()


def write_outputs(runs: list[SampleRun], out_dir, synthetic: bool, stem: str = "protocols") -> list[Path]:
    """Tables (CSV + Markdown, paper layout) and the per-sample figure set."""
    from harness.report import figures, tables
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    records = [r for run in runs for r in run.records]
    written = list(tables.write_tables(records, out_dir, stem))
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    for run in runs:
        path = fig_dir / f"{run.sample}.png"
        figures.plot_sample_figure(path, run.sample, run.traces, synthetic=synthetic)
        written.append(path)
    return written
