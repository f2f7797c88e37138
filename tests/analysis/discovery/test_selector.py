"""The discovery's selector (harness.analysis.discovery.selector.GreedySelector) on hand-made candidate tables.

The fits are stand-ins (names and chi-square numbers), so the tests check the selection logic alone: greedy
forward selection with the acceptance rule, at most ``max_terms``, and nothing fitted when no structure is left.
"""
from __future__ import annotations

from dataclasses import dataclass

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from harness.analysis.discovery import GreedySelector


@dataclass(frozen=True)
class Fit:
    terms: tuple
    chi2: float


@dataclass(frozen=True)
class Cmp:
    name: str
    accepted: bool
    score: float


def harness_for(gain: dict, floor: float, accept_min: float = 25.0):
    """Callables of a world where term t lowers the chi-square by gain[t] (additive), the noise is at ``floor``."""
    calls = []

    def fit(ref, names):
        calls.append(tuple(names))
        return [Fit(ref.terms + (n,), ref.chi2 - gain[n]) for n in names]

    def compare(ref, f, name):
        d = ref.chi2 - f.chi2
        return Cmp(name, d > accept_min, d)

    def structured(f):
        return f.chi2 > floor
    return fit, compare, structured, calls


def test_clean_data_fits_nothing():
    fit, compare, structured, calls = harness_for({"a": 100.0}, floor=1000.0)
    path = GreedySelector(2).run(Fit((), 900.0), ["a"], fit, compare, structured)
    assert path.chosen == () and path.final == Fit((), 900.0) and calls == []
    assert path.stop == "no structure to explain"


def test_takes_the_best_then_stops_when_no_structure_is_left():
    gain = {"a": 50.0, "b": 400.0, "c": 10.0}
    fit, compare, structured, calls = harness_for(gain, floor=1000.0)
    path = GreedySelector(3).run(Fit((), 1500.0), ["a", "b", "c"], fit, compare, structured)
    # round 1: b (score 400) -> 1100 > floor; round 2: a (50, accepted) -> 1050 > floor; round 3: c (10) refused
    assert [c.name for c in path.chosen] == ["b", "a"]
    assert path.final.terms == ("b", "a") and calls == [("a", "b", "c"), ("a", "c"), ("c",)]
    assert path.stop == "no candidate term accepted"


def test_at_most_max_terms():
    fit, compare, structured, _ = harness_for({"a": 100.0, "b": 90.0, "c": 80.0}, floor=0.0)
    path = GreedySelector(1).run(Fit((), 1e4), ["a", "b", "c"], fit, compare, structured)
    assert [c.name for c in path.chosen] == ["a"] and path.stop == "at most 1 term(s)"
    with pytest.raises(ValueError, match="max_terms"):
        GreedySelector(0)


def test_no_round_starts_once_the_budget_is_spent():
    """exhausted(reference, terms) is asked before each round, with the round's reference and terms: spent before
    the first, nothing is fitted; spent after the first, the first round's accepted term is kept and the path says
    why it stopped."""
    from harness.analysis.discovery.selector import BUDGET_SPENT
    fit, compare, structured, calls = harness_for({"a": 100.0, "b": 90.0}, floor=0.0)
    path = GreedySelector(2).run(Fit((), 1e4), ["a", "b"], fit, compare, structured, exhausted=lambda ref, todo: True)
    assert calls == [] and path.chosen == () and path.stop == BUDGET_SPENT
    fit, compare, structured, calls = harness_for({"a": 100.0, "b": 90.0}, floor=0.0)
    spent, asked = iter([False, True]), []

    def exhausted(ref, todo):
        asked.append((ref.terms, tuple(todo)))     # the round it would pay for: its reference and its terms
        return next(spent)

    path = GreedySelector(2).run(Fit((), 1e4), ["a", "b"], fit, compare, structured, exhausted=exhausted)
    assert calls == [("a", "b")] and [c.name for c in path.chosen] == ["a"] and path.stop == BUDGET_SPENT
    assert asked == [((), ("a", "b")), (("a",), ("b",))]


@settings(max_examples=60, deadline=None)
@given(gains=st.dictionaries(st.sampled_from("abcdefg"), st.floats(0.0, 500.0), min_size=1),
       start=st.floats(0.0, 3000.0), floor=st.floats(0.0, 2000.0), k=st.integers(1, 4))
def test_every_step_is_the_best_accepted_and_the_rule_holds(gains, start, floor, k):
    fit, compare, structured, _ = harness_for(gains, floor)
    names = sorted(gains)
    path = GreedySelector(k).run(Fit((), start), names, fit, compare, structured)
    assert len(path.chosen) <= k
    chi2 = start
    for r, c in zip(path.rounds, path.chosen):
        assert chi2 > floor                       # a round only runs while structure is left
        assert c.accepted and c.score == max(q.score for q in r.comparisons if q.accepted)
        chi2 -= gains[c.name]
    assert path.final.chi2 == pytest.approx(chi2)
    if not path.chosen:
        assert path.final.chi2 == start
    # independent stop reasons
    remaining = [g for n, g in gains.items() if n not in {c.name for c in path.chosen}]
    if path.stop == "no candidate term accepted":
        assert all(g <= 25.0 for g in remaining)
