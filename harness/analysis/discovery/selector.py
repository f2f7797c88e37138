"""Which candidate terms to add: the selector (PySINDy's "optimizer" half of the library/optimizer split).

Discovery by simulation, not by derivatives: each candidate term is added to the model the catalogue stage
selected and fitted on whole measured trajectories by the diagnosis's own least squares; the selector only
sees the fits through three callables, so that it is independent of how they are made:

* ``fit(reference, names) -> [fit]``: the reference model extended by each term of ``names``, fitted;
* ``compare(reference, fit, name) -> comparison`` with ``accepted`` (the acceptance rule: BIC on the fit tests
  AND held-out chi-square, as for the catalogue) and ``score`` (held-out chi-square decrease - BIC change);
* ``structured(fit) -> bool``: whether the fit's residuals still show structure beyond the noise;
* ``exhausted(reference, names) -> bool`` (optional): whether the fits' budget left cannot pay for a round fitting
  the terms ``names`` against ``reference`` (at least one iteration of each fit): that round does not start (the
  path then stops with ``stop`` = :data:`BUDGET_SPENT`), so that a diagnosis ends near its budget instead of
  evaluating every remaining term at its start point past it.

:class:`GreedySelector`: greedy forward selection, at most ``max_terms`` terms (the false-discovery control:
every step must pass the same acceptance rule, and the search stops when no structure is left).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable

#: ``Path.stop`` when the fits' budget left could not pay for the next round
BUDGET_SPENT = "fit budget spent: the budget left cannot pay for one iteration of the next round's fits"


@dataclass(frozen=True)
class Step:
    """One round of the selection: the terms of its reference model, the comparisons of the candidates and
    their fits (same order)."""
    reference: tuple
    comparisons: tuple
    fits: tuple = ()


@dataclass(frozen=True, eq=False)
class Path:
    """The selector's outcome: its rounds, the accepted comparisons in order (``chosen``), the final fit
    (the start itself when nothing was accepted) and why it stopped (``stop``)."""
    rounds: tuple
    chosen: tuple
    final: object
    stop: str


class Selector(ABC):
    """Chooses terms of a library to add to a fitted model."""

    @abstractmethod
    def run(self, start, names, fit: Callable, compare: Callable, structured: Callable,
            exhausted: Callable | None = None) -> Path:
        """Select among the terms ``names`` starting from the fitted model ``start``."""


class GreedySelector(Selector):
    """Greedy forward selection: fit every remaining term against the current model, take the accepted one with
    the largest score, repeat while the current model's residuals show structure, at most ``max_terms``."""

    def __init__(self, max_terms: int = 2):
        if max_terms < 1:
            raise ValueError(f"max_terms must be >= 1, got {max_terms!r}")
        self.max_terms = int(max_terms)

    def run(self, start, names, fit, compare, structured, exhausted=None) -> Path:
        current, chosen, rounds, taken = start, [], [], []
        stop = "no structure left"
        while True:
            if not structured(current):
                stop = "no structure left" if chosen else "no structure to explain"
                break
            if len(chosen) >= self.max_terms:
                stop = f"at most {self.max_terms} term(s)"
                break
            todo = [n for n in names if n not in taken]
            if not todo:
                stop = "every candidate term taken"
                break
            if exhausted is not None and exhausted(current, todo):
                stop = BUDGET_SPENT
                break
            fits = fit(current, todo)
            comps = [compare(current, f, n) for n, f in zip(todo, fits)]
            rounds.append(Step(reference=tuple(taken), comparisons=tuple(comps), fits=tuple(fits)))
            acc = sorted((q for q, c in enumerate(comps) if c.accepted), key=lambda q: -comps[q].score)
            if not acc:
                stop = "no candidate term accepted"
                break
            q = acc[0]
            current = fits[q]
            chosen.append(comps[q])
            taken.append(todo[q])
        return Path(rounds=tuple(rounds), chosen=tuple(chosen), final=current, stop=stop)
