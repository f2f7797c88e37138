"""Batched Levenberg-Marquardt (harness.analysis.core.lsq) on problems with known least-squares solutions."""
from __future__ import annotations

import numpy as np
import pytest

from harness.analysis.core.lsq import BoxProblem, LMSettings, LsqError, jacobian, levenberg_marquardt

TIGHT = LMSettings(max_iter=200, ftol=1e-14, atol=0.0)


def box(x0, lo=-1e3, hi=1e3, fd=1e-7):
    x0 = np.asarray(x0, dtype=float)
    return BoxProblem(x0, np.full(x0.size, lo), np.full(x0.size, hi), np.full(x0.size, fd))


def per_problem(funcs):
    """Batch evaluator from one residual function per problem; records the batch sizes."""
    calls = []

    def residuals(points):
        calls.append(len(points))
        return [funcs[i](x) for i, x in points]
    return residuals, calls


# the problems, each with its solution from an independent route
rng = np.random.default_rng(3)
A_LIN = rng.normal(size=(30, 3))
B_LIN = rng.normal(size=30)
X_LIN = np.linalg.lstsq(A_LIN, B_LIN, rcond=None)[0]          # normal equations via numpy


def linear(x):
    return A_LIN @ x - B_LIN


def rosenbrock(x):                                             # minimum 0 at (1, 1)
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


T_EXP = np.linspace(0.0, 3.0, 40)
Y_EXP = 2.5 * np.exp(-1.3 * T_EXP)                             # exact data: solution (2.5, 1.3), cost 0


def exponential(x):
    return x[0] * np.exp(-x[1] * T_EXP) - Y_EXP


def test_linear_model_reaches_the_normal_equations_solution():
    res, calls = per_problem([linear])
    out = levenberg_marquardt([box(np.zeros(3))], res, TIGHT)[0]
    assert np.allclose(out.x, X_LIN, rtol=1e-6, atol=1e-8)
    r = linear(X_LIN)
    assert out.cost == pytest.approx(float(r @ r), rel=1e-9)
    assert np.allclose(out.residual, linear(out.x))


def test_rosenbrock():
    res, _ = per_problem([rosenbrock])
    out = levenberg_marquardt([box([-1.2, 1.0])], res, TIGHT)[0]
    assert np.allclose(out.x, [1.0, 1.0], atol=1e-5)
    assert out.cost < 1e-10


def test_exponential_fit():
    res, _ = per_problem([exponential])
    out = levenberg_marquardt([box([1.0, 0.5])], res, TIGHT)[0]
    assert np.allclose(out.x, [2.5, 1.3], rtol=1e-6)
    assert out.cost < 1e-12


def test_several_problems_in_lock_step_share_each_batch():
    """Three different problems solved together: the same solutions as alone, one evaluator call per
    iteration for all of them (the batch holds points of several problems)."""
    funcs = [linear, rosenbrock, exponential]
    starts = [np.zeros(3), np.array([-1.2, 1.0]), np.array([1.0, 0.5])]
    res, calls = per_problem(funcs)
    out = levenberg_marquardt([box(x) for x in starts], res, TIGHT)
    assert np.allclose(out[0].x, X_LIN, rtol=1e-6, atol=1e-8)
    assert np.allclose(out[1].x, [1.0, 1.0], atol=1e-5)
    assert np.allclose(out[2].x, [2.5, 1.3], rtol=1e-6)
    # first call: every problem's start point and Jacobian columns (3 + (3 + 2 + 2) points)
    assert calls[0] == 3 + 7
    alone = [levenberg_marquardt([box(x)], per_problem([f])[0], TIGHT)[0] for f, x in zip(funcs, starts)]
    for a, b in zip(out, alone):
        assert np.array_equal(a.x, b.x) and a.cost == b.cost


def test_bounds_are_respected():
    """Exponential fit with the rate bounded below its free optimum: the solution sits on the bound, near
    the 1-D least-squares amplitude for that rate (closed form; bounds by projection, so only close)."""
    res, _ = per_problem([exponential])
    p = BoxProblem(np.array([1.0, 0.5]), np.array([0.0, 0.0]), np.array([10.0, 1.0]), np.full(2, 1e-7))
    out = levenberg_marquardt([p], res, TIGHT)[0]
    e = np.exp(-1.0 * T_EXP)
    a_best = float(e @ Y_EXP / (e @ e))
    r_best = exponential(np.array([a_best, 1.0]))
    assert out.x[1] == pytest.approx(1.0, abs=1e-12)
    assert out.x[0] == pytest.approx(a_best, rel=1e-2)
    assert float(r_best @ r_best) <= out.cost <= 1.001 * float(r_best @ r_best)


def test_jacobian_by_forward_differences():
    p = box([2.0, 0.7], fd=1e-7)
    x = np.array([2.0, 0.7])
    J, r = jacobian(p, x, lambda xs: [exponential(xi) for xi in xs])
    e = np.exp(-x[1] * T_EXP)
    want = np.column_stack([e, -x[0] * T_EXP * e])             # analytic derivative
    assert np.allclose(J, want, atol=1e-5)
    assert np.array_equal(r, exponential(x))
    # at the upper bound the step goes backward and stays inside the box
    pb = BoxProblem(x, np.zeros(2), x.copy(), np.full(2, 1e-7))
    seen = []
    jacobian(pb, x, lambda xs: seen.extend(xs) or [exponential(xi) for xi in xs])
    assert all(np.all(xi <= x) for xi in seen)


def test_malformed_problems_raise():
    with pytest.raises(LsqError):
        BoxProblem(np.zeros(2), np.zeros(3), np.ones(2), np.ones(2))
    with pytest.raises(LsqError):
        BoxProblem(np.zeros(2), np.ones(2), np.zeros(2), np.ones(2))
    with pytest.raises(LsqError):
        BoxProblem(np.zeros(2), -np.ones(2), np.ones(2), np.zeros(2))


def test_each_problem_says_why_it_stopped():
    """converged (the cost stopped falling), max_iter (the iteration limit came first), time_budget (the deadline
    had passed before an iteration could start: no iteration, the start point returned, marked cut short)."""
    from harness.analysis.core import cpu_clock
    lin = lambda x: A_LIN @ x - B_LIN                              # noqa: E731
    rosen = lambda x: np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])  # noqa: E731
    res, _ = per_problem([lin, rosen])
    a, b = levenberg_marquardt([box([0, 0, 0]), box([-1.2, 1.0])], res, LMSettings(max_iter=3, ftol=1e-14, atol=0))
    assert a.stop == "converged" and not a.cut_short and a.iterations <= 3
    assert b.stop == "max_iter" and b.cut_short and b.iterations == 3
    res, calls = per_problem([lin, lin])
    c, d = levenberg_marquardt([box([0.5, 0.5, 0.5]), box([0.0, 0.0, 0.0])], res,
                               LMSettings(deadline_s=cpu_clock.now() - 1.0))
    assert c.stop == "time_budget" and c.cut_short and c.iterations == 0
    np.testing.assert_array_equal(c.x, [0.5, 0.5, 0.5])
    # a spent budget costs one evaluation per problem (its start point), no Jacobian columns
    assert calls == [2] and c.jacobian is None
    r = A_LIN @ np.array([0.5, 0.5, 0.5]) - B_LIN
    assert c.cost == float(r @ r) and d.cost == float(B_LIN @ B_LIN)


def test_a_budget_cut_inside_a_large_batch_stops_within_one_chunk():
    """The deadline is checked between batches of BUDGET_CHUNK points, not only before an iteration: 40 problems of
    10 parameters (410 points to start), each point burning about 2 ms of CPU, with 0.15 s of budget left, stop
    after at most a few chunks (the whole batch would take 0.8 s), at their start points, marked time_budget."""
    import time
    from harness.analysis.core import cpu_clock, lsq

    def burn(x):
        t0 = time.process_time()
        while time.process_time() - t0 < 0.002:
            pass
        return A_LIN[:, :1] @ x[:1] + 0.0 * x.sum() - B_LIN
    res, calls = per_problem([burn] * 40)
    c0 = cpu_clock.now()
    out = levenberg_marquardt([box(np.full(10, 0.3)) for _ in range(40)], res, LMSettings(deadline_s=c0 + 0.15))
    spent = cpu_clock.now() - c0
    assert all(r.stop == "time_budget" and r.iterations == 0 and r.jacobian is None for r in out)
    np.testing.assert_array_equal(out[0].x, np.full(10, 0.3))
    assert max(calls) <= lsq.BUDGET_CHUNK and sum(calls) < 410
    assert spent < 0.15 + 3 * lsq.BUDGET_CHUNK * 0.002 + 0.1, spent
