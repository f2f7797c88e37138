"""The robustness study's cases and its measurement delay (harness.control.robustness, closedloop.LoopSettings):
every catalogue effect unmodelled, the parameters R, L, Em, K1, K2, C, m off by exactly +-20 %, noise 2x and 5x,
delays of 1 and 2 ms; the delayed loop hands the controller the plant's reading of delay_steps base steps before
(compared with the loop's own record of the plant's x). The whole study (about 50 runs) is
benchmarks/control_robustness.py; a reduced study runs under ``-m slow`` (no contact with the margin on)."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_src.specs import EFFECTS, Params
from harness.control.closedloop import ControlLoopError, LoopSettings, Profile, run_loop
from harness.control.robustness import Case, robustness_cases, run_robustness


def test_cases_cover_the_issue():
    base = Params()
    cases = {c.name: c for c in robustness_cases(base)}
    for e in EFFECTS:
        on = cases[f"unmodelled {e}"].plant
        assert getattr(on, EFFECTS[e].switch) > 0 and getattr(base, EFFECTS[e].switch) == 0
    for k in ("R", "L", "Em", "K1", "K2", "C", "m"):
        assert getattr(cases[f"{k} -20 %"].plant, k) == pytest.approx(0.8 * getattr(base, k), rel=1e-15)
        assert getattr(cases[f"{k} +20 %"].plant, k) == pytest.approx(1.2 * getattr(base, k), rel=1e-15)
    assert cases["noise 5x"].noise_factor == 5.0 and cases["delay 2 ms"].delay_steps == 2


class _Recorder:
    def __init__(self):
        self.seen = []

    def start(self, t0, t_end):
        pass

    def command(self, t, refs, measured):
        self.seen.append(measured[1])
        return 8.0 if t < 0.05 else 0.0

    def applied(self, t, h, V):
        pass

    def close(self):
        pass


@pytest.mark.parametrize("delay", [0, 1, 2])
def test_delayed_readings(fmu_path, delay):
    rec = _Recorder()
    run = run_loop(fmu_path, Params(), rec, Profile("staircase", levels_m=(1e-3,), hold_s=0.05),
                   LoopSettings(dt_s=1e-3, delay_steps=delay))
    seen, x = np.array(rec.seen), run["x_m"]
    assert np.all(np.abs(np.diff(x[1:60])) > 0)   # moving: a shifted copy would differ
    assert seen[delay:] == pytest.approx(x[:x.size - delay], abs=1e-15)
    assert np.all(seen[:delay] == x[0])


def test_bad_delay_refused():
    with pytest.raises(ControlLoopError, match="delay_steps"):
        LoopSettings(delay_steps=-1)


@pytest.mark.slow
def test_reduced_study_has_no_contact(fmu_path):
    base = Params()
    cases = [Case("sat", base.with_(ksat=3.0)), Case("Em +20", base.with_(Em=1.2 * base.Em)),
             Case("noise 5x", base, noise_factor=5.0), Case("delay 2 ms", base, delay_steps=2)]
    rows = run_robustness(fmu_path, base, cases=cases)
    assert len(rows) == 2 * (len(cases) + 1)
    assert all(r["contact_events"] == 0 for r in rows)
