"""Reference checks in the FMI cross-check style.

For each test of one reference sample (W20-D45, the rig's true parameters) a
folder holds ``<test>_in.csv`` (time_s, V), ``<test>_ref.csv`` (time_s and the
reference outputs), ``<test>_ref.opt`` (StartTime, StopTime, StepSize) and
``<test>_params.json`` (start values with units in the keys). Sweeps (T1, T7)
store one steady-state row per gap. ``check_references`` runs any FMU build
through fmpy with the stored inputs and compares with fmpy's own
``validate_signal`` tolerance tube.

Tube widths, chosen per signal (fmpy sizes the tube from the reference's own range):
* x, F, I: dy = 1e-3 of the reference range, dx = 3 samples. The model's
  integration error is below 1e-7 of the range, so two correct builds agree
  10,000 times more tightly than the tube; a 1 % change of Em, K2 or R moves
  these signals by about 1 % of their range and fails.
* sweeps: |y - y_ref| <= 1e-3 of the sweep's range at every gap, for the same reason.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fmu_src.specs import Params
from harness.sim import fmurun
from harness.data import paramsjson, protocol, rig

REFERENCE_SAMPLE = (20, 45)
TUBE = {"x": dict(dx=3, dy=1e-3), "F": dict(dx=3, dy=1e-3), "I": dict(dx=3, dy=1e-3)}
SWEEP_RTOL = 1e-3
SERIES = {"T2": (0.06, False), "T3": (0.11, False), "T4": (0.16, False), "T5": (0.23, False),
          "T6": (0.23, False), "T8": (0.23, True)}


def _write_csv(path: Path, cols: dict):
    names = list(cols)
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        for row in zip(*cols.values()):
            f.write(",".join(repr(float(v)) for v in row) + "\n")


def read_reference_csv(path: Path) -> dict:
    """The columns of a cross-check CSV (`<test>_in.csv` or `_ref.csv`) as float arrays, by header name."""
    try:
        data = np.genfromtxt(path, delimiter=",", names=True, dtype=float)
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: cannot read reference CSV: {e}") from None
    return {n: np.atleast_1d(data[n]) for n in data.dtype.names}


def load_reference_params(ref_dir: Path, test: str, params_scale: dict | None) -> Params:
    """The stored parameters of a test (with its gap "r0_m"), scaled by ``params_scale``."""
    path = ref_dir / f"{test}_params.json"
    p = paramsjson.params_from_json(json.loads(path.read_text()), path, required=paramsjson.PAPER + ("r0",))
    if params_scale:
        p = p.with_(**{k: getattr(p, k) * f for k, f in params_scale.items()})
    return p


def reference_cases(gap_mm: float = 5.0):
    """(test, params, t, V) for the time-series references of the reference sample."""
    p = rig.true_params(*REFERENCE_SAMPLE)
    cases = []
    for test, (b, blocked) in SERIES.items():
        V0 = b / p.kB * p.R
        gap = protocol.T8_GAP_MM if blocked else gap_mm + (1.0 if test == "T6" else 0.0)
        if test == "T6":
            t = protocol.time_grid(protocol.PRE_STEP_S + 2.0)
            V = protocol.sine_voltage(t, V0)
        else:
            t = protocol.time_grid(protocol.PRE_STEP_S + 1.0)
            V = protocol.step_voltage(t, V0)
        cases.append((test, p.with_(r0=gap / 1000.0, blocked=blocked), t, V))
    return cases


def make_references(out: Path, fmu_path=None) -> list[Path]:
    """Write the references of the reference sample into ``out`` (the FMU at fmu_path, default: the
    repository's, run through fmpy); returns the written paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for test, p, t, V in reference_cases():
        r = fmurun.run(p, t, V, fmu_path=fmu_path)
        _write_csv(out / f"{test}_in.csv", {"time": t, "V": V})
        _write_csv(out / f"{test}_ref.csv", {"time": t, "x": r["x"], "F": r["F"], "I": r["I"]})
        (out / f"{test}_ref.opt").write_text(
            f"StartTime, {t[0]!r}\nStopTime, {t[-1]!r}\nStepSize, {t[1] - t[0]!r}\n")
        (out / f"{test}_params.json").write_text(json.dumps(paramsjson.params_to_json(p, gap=True), indent=2)
                                                 + "\n")
        written += [out / f"{test}_{s}" for s in ("in.csv", "ref.csv", "ref.opt", "params.json")]
    p = rig.true_params(*REFERENCE_SAMPLE)
    for test, blocked, col in (("T1", False, "x"), ("T7", True, "F")):
        gaps = np.arange(0.0, 11.0, 2.0)
        V0 = 0.23 / p.kB * p.R
        vals = []
        for g in gaps:
            t = protocol.time_grid(protocol.SWEEP_HOLD_S)
            r = fmurun.run(p.with_(r0=g / 1000.0, blocked=blocked), t, np.full(t.shape, V0), fmu_path=fmu_path)
            vals.append(r[col][-1])
        _write_csv(out / f"{test}_sweep_ref.csv", {"gap_mm": gaps, "V": np.full(gaps.shape, V0), col: np.array(vals)})
        params = paramsjson.params_to_json(p.with_(blocked=blocked), gap=True)
        (out / f"{test}_params.json").write_text(json.dumps(params, indent=2) + "\n")
        written += [out / f"{test}_sweep_ref.csv", out / f"{test}_params.json"]
    return written


@dataclass
class Report:
    """Outcome of :func:`check_references`: results [(test, signal, samples outside the tube, samples)]."""
    results: list = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """True when there are results and every signal stayed inside its tube."""
        return bool(self.results) and all(n == 0 for _, _, n, _ in self.results)

    def lines(self):
        """One line per test and signal, then the verdict."""
        for test, sig, n, tot in self.results:
            yield f"{test} {sig}: {'passed' if n == 0 else 'FAILED'} ({n} of {tot} samples outside the tube)"
        yield "all passed" if self.passed else "cross-check FAILED"


def check_references(ref_dir: Path, fmu_path=None, params_scale: dict | None = None) -> Report:
    """Run the FMU on every stored input and compare with the references (fmpy's tolerance tube).

    ``params_scale`` multiplies stored parameters (e.g. {"Em": 1.01}); tests use it to show a check can fail.
    """
    from fmpy.util import validate_signal
    ref_dir = Path(ref_dir)
    if not ref_dir.is_dir():
        raise FileNotFoundError(f"reference folder {ref_dir} not found")
    rep = Report()
    for ref in sorted(ref_dir.glob("*_ref.csv")):
        if ref.name.endswith("_sweep_ref.csv"):
            continue
        test = ref.name.split("_")[0]
        p = load_reference_params(ref_dir, test, params_scale)
        inp = read_reference_csv(ref_dir / f"{test}_in.csv")
        want = read_reference_csv(ref)
        r = fmurun.run(p, inp["time"], inp["V"], fmu_path=fmu_path)
        for sig, tube in TUBE.items():
            _, _, _, i_out = validate_signal(r["time"], np.asarray(r[sig], float), want["time"], want[sig],
                                             num=len(want["time"]), **tube)
            rep.results.append((test, sig, int(np.sum(i_out)), len(i_out)))
    for ref in sorted(ref_dir.glob("*_sweep_ref.csv")):
        test = ref.name.split("_")[0]
        p = load_reference_params(ref_dir, test, params_scale)
        want = read_reference_csv(ref)
        sig = "F" if "F" in want else "x"
        got = []
        for g, V in zip(want["gap_mm"], want["V"]):
            t = protocol.time_grid(protocol.SWEEP_HOLD_S)
            got.append(fmurun.run(p.with_(r0=g / 1000.0), t, np.full(t.shape, V), fmu_path=fmu_path)[sig][-1])
        tol = SWEEP_RTOL * max(np.ptp(want[sig]), np.max(np.abs(want[sig])) * 1e-3)
        rep.results.append((test, sig, int(np.sum(np.abs(np.array(got) - want[sig]) > tol)), len(got)))
    if not rep.results:
        raise FileNotFoundError(f"no *_ref.csv files in {ref_dir}")
    return rep
