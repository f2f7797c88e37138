"""The deep-profile report counts each noise realization once (benchmarks/deep_profile_report.py)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("deep_profile_report", ROOT / "benchmarks" / "deep_profile_report.py")
report = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(report)


def _rec(seed, est, truth=1.0, sd=0.1, rate=100.0):
    return {"desc": f"RigDescription(rates_hz=({rate},) * 6, seed={seed})", "effect": None, "clean": True, "verdict": "none", "errors": {},
            "intervals": [{"sample": "W5-D25", "key": "Em_N_m_per_T2", "estimate": est, "sd": sd,
                           "lo": est - 0.196, "hi": est + 0.196, "truth": truth}]}


def test_near_copies_count_once():
    # two descriptions with the same noise seed and sample (only a rate differs: the same realization, estimates
    # a little apart) and one with another seed: 2 rows, one outside its interval
    recs = [_rec(0, 1.3), _rec(0, 1.31, rate=631.0), _rec(7, 1.05)]
    rows = report.unique_rows(recs)
    assert [r["estimate"] for r in rows] == [1.3, 1.05]
    hits = [r["lo"] <= r["truth"] <= r["hi"] for r in rows]
    assert hits == [False, True]          # 50 %, where counting the copy would give 33 %


def test_identify_only_records_count_for_coverage_not_for_verdicts():
    # the coverage test identifies without diagnosing (verdict None, diagnosed false): its samples are intervals
    # like any other, but no verdict of "None" may be reported for them
    from tests.independent.space import RigDescription
    diag = dict(_rec(1, 1.0), desc=repr(RigDescription(seed=1)))
    ident = dict(_rec(2, 1.5), desc=repr(RigDescription(seed=2)), verdict=None, diagnosed=False)
    text = report.summary([diag, ident])
    assert "verdicts on 1 diagnosed clean datasets: 1 x none; 1 more identified only" in text
    em = next(line for line in text.splitlines() if line.strip().startswith("Em_N_m_per_T2"))
    assert em.split()[1:3] == ["2", "50.0%"]
