"""Worker processes that end with their command: on Ctrl-C, SIGTERM, an error, or the death of their parent.

Every process pool of the harness (the virtual rig, the identification, the protocol runs, the diagnosis's
candidate fits) is made by :func:`process_pool`, and the Dask clusters of the sweeps start their processes
inside :func:`sigint_blocked`:

* the workers ignore SIGINT: Ctrl-C in a terminal goes to the whole process group, and a worker that died of it
  in the middle of a task (inside an FMU call, writing a result to its pipe) printed tracebacks and could leave
  the parent waiting forever; the parent alone handles it and ends the pool;
* each worker asks the kernel for SIGKILL when its parent dies (Linux ``prctl(PR_SET_PDEATHSIG)``), so that
  ``kill -9`` or a time limit on the main process leaves no orphan computing on;
* on any exit of the ``with`` block other than its normal end the pool is stopped at once: pending tasks
  cancelled (``Executor.shutdown(cancel_futures=True)``), the worker processes terminated, then killed if they
  have not ended within ``timeout_s``.
"""
from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import signal
from concurrent.futures import ProcessPoolExecutor

from harness import scratch

__all__ = ["process_pool", "stop_pool", "sync_manager", "sigint_blocked", "die_with_parent", "start_resource_tracker"]

_PR_SET_PDEATHSIG = 1          # linux/prctl.h


def die_with_parent(parent_pid: int) -> None:
    """In a child process: ignore SIGINT, end quietly on SIGTERM (the default action, not a handler inherited from
    the parent by fork) and have the kernel send SIGKILL when the parent dies (Linux; elsewhere nothing but the
    signal dispositions). Exits at once if the parent ``parent_pid`` is already gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)     # not a handler inherited from the parent (fork)
    if hasattr(signal, "pthread_sigmask"):            # blocked by the parent while it forked (sigint_blocked):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})     # a SIGTERM meanwhile ends it now
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    except (OSError, AttributeError):      # not Linux: no parent-death signal
        pass
    if os.getppid() != parent_pid:         # the parent died before the request took effect
        os._exit(1)


def _init(parent_pid: int, initializer, initargs) -> None:
    die_with_parent(parent_pid)
    if initializer is not None:
        initializer(*initargs)


def stop_pool(pool: ProcessPoolExecutor, timeout_s: float = 2.0) -> None:
    """End a pool now: cancel what has not started, terminate the workers (SIGTERM), SIGKILL those still alive
    after ``timeout_s``, and reap them all."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout_s)
        if p.is_alive():
            p.kill()
            p.join(1.0)


@contextlib.contextmanager
def process_pool(workers: int, initializer=None, initargs: tuple = (), fork: bool = True):
    """A ``ProcessPoolExecutor`` of ``workers`` processes (fork where the platform has it) whose workers ignore
    SIGINT and die with this process; left normally, it is shut down waiting for its tasks; left by an exception
    (KeyboardInterrupt and SystemExit included), it is stopped at once (:func:`stop_pool`)."""
    ctx = mp.get_context("fork") if fork and "fork" in mp.get_all_start_methods() else mp.get_context()
    scratch.root()      # made (and named in the environment) before the workers: they extract under it
    pool = ProcessPoolExecutor(max_workers=int(workers), mp_context=ctx, initializer=_init,
                               initargs=(os.getpid(), initializer, tuple(initargs)))
    try:
        if ctx.get_start_method() == "fork":
            # the workers forked now (at the first task) keep SIGINT blocked until they ignore it (a Ctrl-C in
            # between raised KeyboardInterrupt in a new worker), SIGTERM until its default action is restored
            with sigint_blocked(sigterm=True):
                pool.submit(int)
        yield pool
        pool.shutdown(wait=True)
    except BaseException:
        stop_pool(pool)
        raise


def sync_manager():
    """A started ``multiprocessing`` SyncManager (e.g. for a progress queue shared with pool workers) whose server
    process ignores SIGINT and dies with this process; use it as a context manager (shut down on exit)."""
    from multiprocessing.managers import SyncManager
    # its socket in the command's scratch folder (harness.scratch), not in a pymp-* folder of the system's
    # temporary folder, which a killed command left (deep interrupt profile, identify, SIGKILL, 13 in 20)
    address = str(scratch.new_dir("manager-") / "socket")
    manager = SyncManager(address=address if len(address.encode()) < 100 else None)   # AF_UNIX: < 108 bytes
    with sigint_blocked(sigterm=True):   # its server process keeps SIGINT blocked until it ignores it
        manager.start(die_with_parent, (os.getpid(),))   # (die_with_parent): a Ctrl-C in between printed "Process
    return manager                                       # SyncManager-1:" and a traceback (deep profile, run)


# The resource tracker's warning about semaphores it cleans up after an interrupted run (the main process leaves
# with os._exit after Ctrl-C: harness.entry): the tracker is a process of its own that prints to our stderr.
_TRACKER_QUIET = "ignore:resource_tracker:UserWarning"


def start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now, outside :func:`sigint_blocked`: started lazily inside it (by
    the first spawned process, e.g. a Dask worker), it unblocks SIGINT in the starting thread when it is up
    (``pthread_sigmask(SIG_UNBLOCK, ...)`` in ``resource_tracker.ensure_running``), so that every Dask worker and
    thread started after it took Ctrl-C and printed tracebacks (found by the 20-signal profile of
    tests/test_interrupts.py). It ignores SIGINT itself, and is told (a ``-W`` option, from ``sys.warnoptions``)
    not to warn about the semaphores of an interrupted run, which it removes."""
    try:
        import sys
        from multiprocessing import resource_tracker
    except ImportError:
        return
    if _TRACKER_QUIET not in sys.warnoptions:
        sys.warnoptions.append(_TRACKER_QUIET)
    with contextlib.suppress(Exception):
        resource_tracker.ensure_running()


@contextlib.contextmanager
def sigint_blocked(sigterm: bool = False):
    """Block SIGINT (and SIGTERM if ``sigterm``) in this thread while the block runs: processes started meanwhile
    (a Dask LocalCluster's workers, a multiprocessing Manager) inherit the blocked signal, so that Ctrl-C reaches
    only this process, which then closes them. A signal that arrives meanwhile is delivered when the block ends.
    (multiprocessing's resource tracker is started first: :func:`start_resource_tracker`.)

    ``sigterm`` for forked workers, which inherit this process's SIGTERM handler (a KeyboardInterrupt): one
    terminated by :func:`stop_pool` before its initializer had set the default action (:func:`die_with_parent`,
    which unblocks SIGTERM) printed "Process ForkProcess-3:" and a traceback (deep interrupt profile, identify,
    SIGTERM, 1 in 20); blocked, the SIGTERM waits for the default action and ends it quietly."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    start_resource_tracker()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM} if sigterm else {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
