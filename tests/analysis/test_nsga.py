"""NSGA-II through pymoo's ask/tell interface (harness.analysis.core.nsga) on toy problems with known fronts."""
import numpy as np
import pytest

from harness.analysis.core import nsga


def schaffer(X):
    """Schaffer's problem N.1 on x in [-5, 5]: Pareto set x in [0, 2], front f2 = (sqrt(f1) - 2)^2."""
    x = X[:, 0]
    return np.column_stack([x ** 2, (x - 2.0) ** 2])


def zdt1(X):
    """ZDT1 with two variables on [0, 1]^2: Pareto set x1 = 0, front f2 = 1 - sqrt(f1), f1 in [0, 1]."""
    g = 1.0 + 9.0 * X[:, 1]
    return np.column_stack([X[:, 0], g * (1.0 - np.sqrt(X[:, 0] / g))])


PROBLEMS = [(schaffer, [-5.0], [5.0]), (zdt1, [0.0, 0.0], [1.0, 1.0])]
CONFIG = nsga.NSGAConfig(pop_size=40, n_gen=60, seed=3)


def _runs(which):
    return [nsga.NSGARun(PROBLEMS[i][1], PROBLEMS[i][2], 2, CONFIG) for i in which]


def _evaluator(problems, calls):
    def evaluate(which, Xs):
        calls.append([X.shape[0] for X in Xs])
        return [problems[i][0](X) for i, X in zip(which, Xs)]
    return evaluate


def test_lockstep_runs_reach_the_known_fronts():
    runs = _runs([0, 1])
    calls, gens = [], []
    stats = nsga.run_lockstep(runs, _evaluator(PROBLEMS, calls), on_generation=gens.append)
    assert len(calls) == CONFIG.n_gen and gens == [2] * CONFIG.n_gen        # one evaluation call per generation
    for (X, F), st in zip((r.population() for r in runs), stats):
        assert 0 < st.evaluations <= CONFIG.pop_size * CONFIG.n_gen
        assert X.shape[0] == CONFIG.pop_size and F.shape == (CONFIG.pop_size, 2)
    X, F = runs[0].population()
    nd = nsga.non_dominated(F)
    assert np.all((X[nd, 0] > -1e-3) & (X[nd, 0] < 2.0 + 1e-3))
    assert np.max(np.abs(F[nd, 1] - (np.sqrt(F[nd, 0]) - 2.0) ** 2)) < 1e-9
    assert F[nd, 0].min() < 0.01 and F[nd, 0].max() > 3.5                # spans the front
    X, F = runs[1].population()
    nd = nsga.non_dominated(F)
    gap = F[nd, 1] - (1.0 - np.sqrt(F[nd, 0]))                             # >= 0, 0 on the front
    # on the front but for at most the f1 = 0 end (weakly dominated points there: f1 = 0, any g)
    assert np.all(gap > -1e-12) and np.median(gap) < 1e-4 and np.sum(gap > 1e-2) <= 1
    assert F[nd, 0].min() < 0.02 and F[nd, 0].max() > 0.9


def test_a_run_does_not_depend_on_its_companions():
    alone = _runs([1])
    nsga.run_lockstep(alone, _evaluator([PROBLEMS[1]], []))
    together = _runs([0, 1])
    nsga.run_lockstep(together, _evaluator(PROBLEMS, []))
    np.testing.assert_array_equal(alone[0].population()[0], together[1].population()[0])
    np.testing.assert_array_equal(alone[0].population()[1], together[1].population()[1])


def test_candidates_seen_before_are_not_evaluated_again():
    run = nsga.NSGARun([0.0], [1.0], 2, nsga.NSGAConfig(pop_size=8, n_gen=30, seed=1))
    seen = []

    def evaluate(which, Xs):
        keys = [x.tobytes() for x in Xs[0]]
        assert len(set(keys)) == len(keys) and not set(keys) & set(seen)
        seen.extend(keys)
        # a coarse grid: offspring often repeat a parent
        return [np.column_stack([np.round(Xs[0][:, 0], 1), 1.0 - np.round(Xs[0][:, 0], 1)])]

    stats = nsga.run_lockstep([run], evaluate)
    assert stats[0].evaluations == len(seen) < 8 * 30          # some were looked up


def test_ask_tell_checks():
    run = nsga.NSGARun([0.0, 0.0], [1.0, 1.0], 2, nsga.NSGAConfig(pop_size=6, n_gen=2))
    with pytest.raises(RuntimeError):
        run.tell(np.zeros((6, 2)))
    X = run.ask()
    assert X.shape == (6, 2) and np.all((X >= 0) & (X <= 1))
    with pytest.raises(ValueError, match="shape"):
        run.tell(np.zeros((5, 2)))
    with pytest.raises(ValueError):
        nsga.NSGAConfig(pop_size=2)
    with pytest.raises(ValueError):
        nsga.NSGARun([1.0], [0.0], 2)


def test_non_dominated_by_hand():
    F = np.array([[1, 2], [2, 1], [1, 2], [3, 3], [0.5, 5], [2, 2]], dtype=float)
    assert nsga.non_dominated(F).tolist() == [0, 1, 4]        # [3, 3] and [2, 2] dominated; duplicate 2 dropped
    assert nsga.non_dominated(np.zeros((0, 2))).tolist() == []
