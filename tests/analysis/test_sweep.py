"""Dask task runner (harness.analysis.core.sweep): a LocalCluster of processes, results in argument order and
equal to the sequential ones with the same seed (1 against 2 workers: tests/analysis/design); an unreachable scheduler is one clear error."""
import time

import numpy as np
import pytest

from harness.analysis.core import sweep


def draw_task(args):
    """A task that needs random numbers and takes a little time (uneven, so tasks finish out of order)."""
    i, seq = args
    time.sleep(0.02 * (i % 3))
    rng = np.random.default_rng(seq)
    return i, rng.normal(size=4)


def failing_task(args):
    if args == 2:
        raise ValueError("bad input 2")
    return args


def test_results_on_two_workers_equal_the_sequential_ones_with_the_same_seed():
    seeds = sweep.task_seeds(42, 8)
    args = list(enumerate(seeds))
    one = [draw_task(a) for a in args]                 # in this process, in order
    two = sweep.run_tasks(draw_task, args, sweep.ClusterSettings(workers=2, progress=False))
    assert [r[0] for r in two] == list(range(8))                    # argument order
    np.testing.assert_array_equal(np.array([r[1] for r in one]), np.array([r[1] for r in two]))
    # another seed gives other numbers; the same seed the same seeds
    other = sweep.task_seeds(43, 8)
    assert not np.array_equal(np.random.default_rng(other[0]).normal(size=4), one[0][1])
    assert [s.entropy for s in sweep.task_seeds(42, 8)] == [s.entropy for s in seeds]


def test_a_failing_task_is_named_and_a_bad_scheduler_is_one_clear_error():
    with sweep.cluster_client(sweep.ClusterSettings(workers=1, progress=False)) as client:
        with pytest.raises(sweep.SweepError, match=r"demo: task 2 failed: ValueError: bad input 2"):
            sweep.run_tasks(failing_task, [0, 1, 2, 3], sweep.ClusterSettings(progress=False), "demo", client=client)
        # the same client serves the next call (the benchmark reuses one cluster)
        assert sweep.run_tasks(failing_task, [5, 6], sweep.ClusterSettings(progress=False), client=client) == [5, 6]
    bad = sweep.ClusterSettings(scheduler="tcp://127.0.0.1:9", progress=False, connect_timeout_s=2.0)
    with pytest.raises(sweep.SweepError, match=r"^--scheduler tcp://127.0.0.1:9: cannot connect"):
        sweep.run_tasks(failing_task, [1], bad)
    with pytest.raises(sweep.SweepError, match="workers must be"):
        sweep.ClusterSettings(workers=0)
