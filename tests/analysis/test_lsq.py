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


class FakeClock:
    """A CPU clock that only the residual functions advance (``spend``): the budget tests are exact, whatever the
    machine does beside them."""

    def __init__(self):
        self.t = 1000.0

    def now(self):
        return self.t

    def spend(self, s):
        self.t += s


@pytest.fixture
def clock(monkeypatch):
    from harness.analysis.core import cpu_clock
    c = FakeClock()
    monkeypatch.setattr(cpu_clock, "now", c.now)
    return c


def costly(clock, s_per_point):
    """A linear residual function whose every evaluation costs ``s_per_point`` of the fake clock."""
    def f(x):
        clock.spend(s_per_point)
        return A_LIN[:, :1] @ x[:1] + 0.0 * x.sum() - B_LIN
    return f


def test_a_budget_cut_inside_a_large_batch_overruns_by_at_most_one_point(clock):
    """The deadline is checked between batches, and the batches shrink as it nears: 40 problems of 10 parameters
    (440 points to start), each point costing 2 ms of CPU, with 0.15 s of budget left, stop at their start points,
    marked time_budget, at most one point's cost (2 ms) past the deadline. A batch of BUDGET_CHUNK = 64 points
    after the start would have passed it by 58 ms (the 123 CPU-s diagnosis of a 1539 Hz dataset, session 19)."""
    from harness.analysis.core import lsq
    res, calls = per_problem([costly(clock, 0.002)] * 40)
    c0 = clock.now()
    out = levenberg_marquardt([box(np.full(10, 0.3)) for _ in range(40)], res, LMSettings(deadline_s=c0 + 0.15))
    assert all(r.stop == "time_budget" and r.iterations == 0 and r.jacobian is None for r in out)
    np.testing.assert_array_equal(out[0].x, np.full(10, 0.3))
    assert calls[0] == 40 and max(calls[1:]) <= lsq.BUDGET_CHUNK and sum(calls) < 440
    assert calls[-1] == 1                          # the last batches before the deadline: a point each
    assert clock.now() - (c0 + 0.15) <= 0.002 + 1e-9, clock.now() - (c0 + 0.15)


def test_batches_far_from_the_deadline_keep_their_full_size(clock):
    """Far from the deadline the batches are BUDGET_CHUNK points (the simulator's batches stay efficient); a
    fit with no deadline evaluates each iteration's points in one batch."""
    from harness.analysis.core import lsq
    res, calls = per_problem([costly(clock, 0.002)] * 40)
    out = levenberg_marquardt([box(np.full(10, 0.3)) for _ in range(40)], res,
                              LMSettings(max_iter=1, deadline_s=clock.now() + 1000.0))
    assert calls[:8] == [40] + [lsq.BUDGET_CHUNK] * 6 + [400 - 6 * lsq.BUDGET_CHUNK]
    assert all(r.stop != "time_budget" for r in out)
    res, calls = per_problem([costly(clock, 0.002)] * 40)
    levenberg_marquardt([box(np.full(10, 0.3)) for _ in range(40)], res, LMSettings(max_iter=1))
    assert calls[0] == 440


def test_a_fit_whose_start_cost_nothing_measurable_starts_with_a_small_batch(clock):
    """Start points that cost nothing (e.g. cached) say nothing of a point's cost: the first timed batch is
    BUDGET_FIRST_CHUNK points, then the batches are sized from its cost."""
    from harness.analysis.core import lsq
    dear = costly(clock, 0.5)

    def f(x):                                        # the start point is free, every other point 0.5 s
        if tuple(np.round(x, 12)) == tuple(np.full(10, 0.3)):
            return A_LIN[:, :1] @ x[:1] - B_LIN
        return dear(x)
    res, calls = per_problem([f] * 4)
    c0 = clock.now()
    levenberg_marquardt([box(np.full(10, 0.3)) for _ in range(4)], res, LMSettings(deadline_s=c0 + 20.0))
    assert calls[0] == 4 and calls[1] == lsq.BUDGET_FIRST_CHUNK
    # 20 s left less the first batch's 4 s: a quarter of it at 0.5 s a point is 8 points
    assert calls[2] == 8
    assert clock.now() - (c0 + 20.0) <= 0.5 + 1e-9
