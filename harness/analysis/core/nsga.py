"""NSGA-II (pymoo) driven through pymoo's documented ask/tell interface, several runs in lock-step.

A :class:`NSGARun` is one seeded NSGA-II (pymoo's ``NSGA2``: SBX crossover, polynomial mutation,
binary tournament, rank-and-crowding survival) on a box-bounded problem. The caller asks it for a
population of decision vectors, evaluates them however it likes, and tells it the objectives
(``Evaluator().eval(StaticProblem(problem, F=F), pop)``, then ``algorithm.tell(infills=pop)``:
pymoo's "ask and tell" pattern, nothing else is touched). :func:`run_lockstep` drives several runs
together so that one call of the caller's evaluation serves the populations of all of them; each
run keeps its own algorithm and random generator, so its result does not depend on the others.

Duplicate offspring are not eliminated by pymoo (``eliminate_duplicates=False``: pymoo's per-
individual bookkeeping cost about a fifth of an identification's run time and changed neither the
chosen models nor the fronts noticeably); :func:`run_lockstep` looks candidates evaluated before up
in the run's memo instead of evaluating them again.

:func:`non_dominated` filters a set of objective vectors with pymoo's own non-dominated sorting.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

__all__ = ["NSGAConfig", "NSGARun", "RunStats", "run_lockstep", "non_dominated"]


@dataclass(frozen=True)
class NSGAConfig:
    """pop_size: population size (>= 4); n_gen: generations (>= 1); seed: random seed."""
    pop_size: int = 64
    n_gen: int = 60
    seed: int = 1

    def __post_init__(self):
        if int(self.pop_size) != self.pop_size or self.pop_size < 4:
            raise ValueError(f"pop_size must be an integer >= 4, got {self.pop_size!r}")
        if int(self.n_gen) != self.n_gen or self.n_gen < 1:
            raise ValueError(f"n_gen must be an integer >= 1, got {self.n_gen!r}")


@dataclass
class RunStats:
    """Bookkeeping of one run: evaluations (candidates evaluated, memo hits excluded), time_s [s] of the
    generations (this run's share), evaluation_s [s] (its share of the evaluation calls)."""
    evaluations: int = 0
    time_s: float = 0.0
    evaluation_s: float = 0.0
    memo: dict = field(default_factory=dict, repr=False)


def _quiet_pymoo() -> None:
    try:
        from pymoo.config import Config
        Config.warnings["not_compiled"] = False
    except Exception:  # pragma: no cover
        pass


class NSGARun:
    """One NSGA-II run on the box xl <= x <= xu with n_obj objectives (minimized), by ask/tell.

    xl, xu: (n_var,) bounds of the decision vector; config: :class:`NSGAConfig`.
    """

    def __init__(self, xl, xu, n_obj: int, config: NSGAConfig = NSGAConfig()):
        from pymoo.algorithms.moo.nsga2 import NSGA2
        from pymoo.core.problem import Problem
        _quiet_pymoo()
        xl = np.asarray(xl, dtype=float)
        xu = np.asarray(xu, dtype=float)
        if xl.shape != xu.shape or xl.ndim != 1 or not np.all(xl < xu):
            raise ValueError(f"bounds must be 1-D arrays with xl < xu, got {xl!r}, {xu!r}")
        self.config = config
        self.problem = Problem(n_var=xl.size, n_obj=int(n_obj), xl=xl, xu=xu)
        self.algorithm = NSGA2(pop_size=int(config.pop_size), eliminate_duplicates=False)
        self.algorithm.setup(self.problem, termination=("n_gen", int(config.n_gen)), seed=int(config.seed),
                             verbose=False)
        self._pop = None
        self.stats = RunStats()

    def has_next(self) -> bool:
        """True while generations remain."""
        return bool(self.algorithm.has_next())

    def ask(self) -> np.ndarray:
        """Decision vectors (n, n_var) of the next population to evaluate."""
        self._pop = self.algorithm.ask()
        return np.asarray(self._pop.get("X"), dtype=float)

    def tell(self, F) -> None:
        """Objectives (n, n_obj) of the population returned by the last :meth:`ask`."""
        from pymoo.core.evaluator import Evaluator
        from pymoo.problems.static import StaticProblem
        if self._pop is None:
            raise RuntimeError("tell() without a preceding ask()")
        F = np.asarray(F, dtype=float)
        if F.shape != (len(self._pop), self.problem.n_obj):
            raise ValueError(f"F must have shape {(len(self._pop), self.problem.n_obj)}, got {F.shape}")
        Evaluator().eval(StaticProblem(self.problem, F=F), self._pop)
        self.algorithm.tell(infills=self._pop)
        self._pop = None

    def population(self) -> tuple[np.ndarray, np.ndarray]:
        """(X, F) of the current (after the last generation: the final) population."""
        pop = self.algorithm.pop
        return np.asarray(pop.get("X"), dtype=float), np.asarray(pop.get("F"), dtype=float)


def run_lockstep(runs: Sequence[NSGARun], evaluate: Callable[[list, list], list],
                 on_generation: Callable[[int], None] | None = None) -> list[RunStats]:
    """Run several NSGA-II runs to the end, one generation of all at a time.

    evaluate(which, Xs) -> Fs: objectives (n_i, n_obj) of the decision vectors Xs[i] (n_i, n_var)
    of the runs ``runs[which[i]]`` still running, in one call per generation (only candidates not
    evaluated before by that run; the others come from its memo). on_generation(n): called after
    each generation with the number of runs that advanced. Returns each run's :class:`RunStats`.
    """
    while True:
        which = [i for i, r in enumerate(runs) if r.has_next()]
        if not which:
            break
        live = [runs[i] for i in which]
        t0 = time.perf_counter()
        asked, todo = [], []
        for r in live:
            X = r.ask()
            keys = [row.tobytes() for row in X]
            new, seen = [], set()
            for i, key in enumerate(keys):
                if key not in r.stats.memo and key not in seen:
                    new.append(i)
                    seen.add(key)
            asked.append((X, keys))
            todo.append(np.asarray(new, dtype=np.intp))
        te = time.perf_counter()
        Fnew = evaluate(which, [X[t] for (X, _), t in zip(asked, todo)])
        te = time.perf_counter() - te
        n_new = sum(int(t.size) for t in todo)
        for r, (X, keys), t, F in zip(live, asked, todo, Fnew):
            r.stats.evaluation_s += te * t.size / max(n_new, 1)
            for i, f in zip(t, F):
                r.stats.memo[keys[i]] = f
            r.tell(np.array([r.stats.memo[key] for key in keys]))
            r.stats.evaluations += int(t.size)
        dt = (time.perf_counter() - t0) / len(live)
        for r in live:
            r.stats.time_s += dt
        if on_generation is not None:
            on_generation(len(live))
    return [r.stats for r in runs]


def non_dominated(F) -> np.ndarray:
    """Sorted indices of the non-dominated rows of F (n, n_obj) (minimization), exact duplicates kept once
    (the first). Uses pymoo's ``NonDominatedSorting``."""
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting
    F = np.asarray(F, dtype=float)
    if F.ndim != 2:
        raise ValueError(f"F must be a 2-D array, got shape {F.shape}")
    if F.shape[0] == 0:
        return np.zeros(0, dtype=np.intp)
    idx = np.asarray(NonDominatedSorting().do(F, only_non_dominated_front=True), dtype=np.intp)
    _, first = np.unique(F[idx], axis=0, return_index=True)
    return np.sort(idx[first])
