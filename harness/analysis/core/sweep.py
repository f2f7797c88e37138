"""Sweeps and Monte-Carlo runs on Dask (``dask.distributed``): one code path for a local cluster and an
existing one.

    settings = ClusterSettings(workers=2)                       # a LocalCluster of 2 worker processes
    settings = ClusterSettings(scheduler="tcp://10.0.0.5:8786")  # an existing cluster (dask-scheduler,
                                                                 # dask-worker, dask-kubernetes, ...)
    results = run_tasks(fn, [args0, args1, ...], settings, desc="design")

``fn(args)`` must be a module-level (picklable) function; every task is submitted with ``pure=False``
and the results come back in the order of the arguments, whatever worker ran which task and in which
order they finished. Randomness never comes from the worker: a task that needs random numbers gets
its own ``numpy.random.SeedSequence`` from :func:`task_seeds` (spawned from the user's seed by task
index), so the results are identical for 1, 2 or N workers with the same seed. Tasks should be sized
to take at least ~10 ms each (the scheduler's overhead is about 1 ms per task); the callers batch
their work accordingly. A tqdm bar counts finished tasks.

Local workers are processes (``processes=True``) with one thread each: the numerical kernels are
numpy code that holds the GIL between calls.
"""
from __future__ import annotations

import contextlib
import logging
import threading
from dataclasses import dataclass

import numpy as np

from harness import scratch
from harness.parallel import sigint_blocked

__all__ = ["ClusterSettings", "SweepError", "task_seeds", "cluster_client", "run_tasks"]


class SweepError(RuntimeError):
    """The cluster cannot be started or reached, or a task failed (the message names which)."""


@dataclass(frozen=True)
class ClusterSettings:
    """Where the tasks run.

    Attributes
    ----------
    workers : int
        Worker processes of the local cluster (>= 1); ignored with ``scheduler``.
    scheduler : str or None
        Address of an existing Dask scheduler (e.g. ``tcp://host:8786``); None: a LocalCluster.
    progress : bool
        Show a progress bar.
    connect_timeout_s : float
        Time [s] allowed to reach the scheduler.
    """
    workers: int = 2
    scheduler: str | None = None
    progress: bool = True
    connect_timeout_s: float = 20.0

    def __post_init__(self):
        if not (isinstance(self.workers, int) and self.workers >= 1):
            raise SweepError(f"workers must be a whole number >= 1, got {self.workers!r}")
        if self.scheduler is not None and not str(self.scheduler).strip():
            raise SweepError("--scheduler: empty address")


def task_seeds(seed: int, n: int) -> list:
    """n independent ``SeedSequence`` children of ``seed``, by task index (reproducible, worker-independent)."""
    return np.random.SeedSequence(int(seed)).spawn(int(n))


@contextlib.contextmanager
def cluster_client(settings: ClusterSettings):
    """A ``dask.distributed.Client`` on a new LocalCluster of processes, or on ``settings.scheduler``; closed on
    every exit path (Ctrl-C included: a local cluster's processes never see it, this process closes them)."""
    from dask.distributed import Client
    cluster = client = None
    interrupted = False
    before = _child_pids()
    start: dict = {}
    try:
        if settings.scheduler:
            try:
                client = Client(settings.scheduler, timeout=f"{settings.connect_timeout_s}s")
            except (OSError, TimeoutError, ValueError) as e:
                raise SweepError(f"--scheduler {settings.scheduler}: cannot connect to a Dask scheduler there "
                                 f"({type(e).__name__}: {e})") from None
        else:
            cluster, client = _start_local_cluster(settings, start, before)
        yield client
    except BaseException as e:
        # Ctrl-C, SIGTERM (harness.signals) or an exit: no graceful close (it waits up to seconds per worker
        # for tasks that will never be collected); the cluster's processes are killed first
        interrupted = not isinstance(e, Exception)
        raise
    finally:
        if start.get("abandoned"):         # interrupted while it started: its starting thread closes it when up
            _kill(_child_pids() - before)
        else:                              # (a cluster that came up as the interrupt arrived is closed here)
            cluster, client = start.get("cluster", cluster), start.get("client", client)
            with _dask_quiet():
                if interrupted and cluster is not None:
                    _no_restarts(cluster)
                    _kill(_child_pids() - before)
                _close_quietly(client, cluster, timeout_s=0.3 if interrupted else 5.0)


def _start_local_cluster(settings: ClusterSettings, state: dict, before: set):
    """Start a LocalCluster of processes and a Client on it; return (cluster, client).

    They are started by a thread of their own, with SIGINT blocked: every thread and process the cluster starts
    inherits the blocked signal, so that Ctrl-C reaches this process alone, which closes them. The calling thread
    waits for it with SIGINT deliverable: Python runs signal handlers in the main thread only, and a main thread
    that blocked SIGINT itself while the cluster started (as before) kept a Ctrl-C pending until the cluster was
    up, 1-3 s on a loaded machine (issue 24: uncertainty ended up to 3.4 s after Ctrl-C). Interrupted while the
    cluster starts, the wait ends at once; ``state["abandoned"]`` is then set and the starting thread closes the
    cluster as soon as it is up, and kills the processes left but those of ``before`` (``state`` also receives
    "cluster" and "client" when they exist)."""
    import dask
    from dask.distributed import Client, LocalCluster
    lock, ready = threading.Lock(), threading.Event()
    # the workers' folders under the command's scratch folder (harness.scratch), removed however it ends; in
    # Dask's default place, <tmp>/dask-scratch-space, an interrupted run left them
    local_directory = str(scratch.new_dir("dask-"))

    def start():
        made: dict = {}
        try:
            # no dashboard; the scheduler's HTTP server (health routes) on a free loopback port: on its default,
            # 8787, Dask warned "Port 8787 is already in use" whenever another cluster ran
            # (the scheduler's and the nannies' folders too: Dask's temporary-directory)
            with dask.config.set({"temporary-directory": local_directory}):
                made["cluster"] = LocalCluster(n_workers=settings.workers, threads_per_worker=1, processes=True,
                                               dashboard_address=None, silence_logs=logging.CRITICAL,
                                               scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                               local_directory=local_directory)
                made["client"] = Client(made["cluster"])
        except BaseException as e:         # handed to the waiting thread
            made["error"] = e
        with lock:
            state.update(made)
            state["done"] = True
            late = state.get("abandoned", False)
        ready.set()
        if late:     # nobody waits for it: a full close (the nannies end their workers), then what is left killed
            _close_quietly(made.get("client"), made.get("cluster"), timeout_s=5.0)
            _kill(_child_pids() - before)

    try:
        # the starting thread inherits the blocked SIGINT, and passes it on. A SIGINT that came while it was
        # blocked here is raised as the block ends, the thread started: inside this try (before, it was raised
        # outside: nobody marked the start abandoned nor closed the cluster, whose worker lived on)
        with sigint_blocked():
            thread = threading.Thread(target=start, name="dask cluster start", daemon=True)
            thread.start()
        ready.wait()       # not thread.join(): interrupted, it marks a running thread as ended (Python 3.11)
    except BaseException:
        with lock:
            if not state.get("done"):
                state["abandoned"] = True
        raise
    if "error" in state:
        raise state["error"]
    return state["cluster"], state["client"]


def _child_pids() -> set:
    """The pids of this process's descendants but multiprocessing's resource tracker (psutil: a dependency of
    dask.distributed). The tracker is known by its command (``-c "from multiprocessing.resource_tracker import
    main; ..."``), not by the word alone: every spawned process (the Dask workers) carries the ``-W`` option of
    :func:`harness.parallel.start_resource_tracker` that names it too, and no worker was ever killed."""
    import psutil
    with contextlib.suppress(psutil.Error):
        return {p.pid for p in psutil.Process().children(recursive=True)
                if not any(a.startswith(_TRACKER_COMMAND) for a in _cmdline(p))}
    return set()


_TRACKER_COMMAND = "from multiprocessing.resource_tracker import"


def _cmdline(proc) -> list:
    import psutil
    try:
        return proc.cmdline()
    except psutil.Error:     # gone meanwhile (or a zombie): nothing to kill
        return [_TRACKER_COMMAND]


def _kill(pids, grace_s: float = 0.5) -> None:
    """SIGTERM every process of ``pids`` still there (the processes a local cluster started: a Dask worker
    closes on it at once, unregistering what it holds), SIGKILL the ones still there after ``grace_s`` [s], and
    reap them all."""
    import psutil
    procs = []
    for pid in pids:
        with contextlib.suppress(psutil.Error):
            p = psutil.Process(pid)
            p.terminate()
            procs.append(p)
    _, alive = psutil.wait_procs(procs, timeout=grace_s)
    for p in alive:
        with contextlib.suppress(psutil.Error):
            p.kill()
    # reaped (psutil waits on a child with waitpid): a process killed but never waited for stays a zombie of
    # this process as long as it runs (a library user's or a host's), counted among its children
    psutil.wait_procs(alive, timeout=1.0)


def _no_restarts(cluster) -> None:
    """Tell the local cluster's nannies (objects of this process) not to restart their worker processes when
    these end: ``Nanny.close_gracefully``, Dask's own signal for a cluster's shutdown. Without it the nannies
    started new workers within the 0.3 s of the closes after :func:`_kill`, and these ran on for 2 s after the
    command had ended, until they noticed that their parent was gone."""
    for nanny in list(getattr(cluster, "workers", {}).values()):
        with contextlib.suppress(Exception):
            nanny.close_gracefully(reason="interrupted")


@contextlib.contextmanager
def _dask_quiet():
    """Dask's loggers silenced (a cluster closed mid-task logs cancelled tasks and ended workers)."""
    quiet = [logging.getLogger(n) for n in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in quiet]
    for lg in quiet:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, lv in zip(quiet, levels):
            lg.setLevel(lv)


def _close_quietly(client, cluster, timeout_s: float = 5.0) -> None:
    """Close the client and the local cluster (every exit path, Ctrl-C included; each close waits at most
    ``timeout_s`` [s]) without Dask's shutdown chatter (:func:`_dask_quiet`)."""
    with _dask_quiet():
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=timeout_s)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=timeout_s)


def run_tasks(fn, args: list, settings: ClusterSettings = ClusterSettings(), desc: str = "tasks", client=None
              ) -> list:
    """Run ``fn(a)`` for every a in ``args`` on the cluster; the results in the order of ``args``.

    client: an existing ``dask.distributed.Client`` to use (e.g. to time several runs on one cluster);
    None: one is made from ``settings`` for this call. A failed task raises :class:`SweepError` naming
    its index (the original exception is chained).
    """
    from dask.distributed import as_completed
    from tqdm import tqdm
    args = list(args)
    if not args:
        return []
    if client is None:
        with cluster_client(settings) as c:
            return run_tasks(fn, args, settings, desc, client=c)
    futures = client.map(fn, args, pure=False)
    where = {f.key: i for i, f in enumerate(futures)}
    out: list = [None] * len(args)
    with tqdm(total=len(args), desc=desc, unit="task", disable=not settings.progress, mininterval=0.5) as bar:
        for f in as_completed(futures):
            i = where[f.key]
            try:
                out[i] = f.result()
            except Exception as e:
                for g in futures:
                    g.cancel()
                raise SweepError(f"{desc}: task {i} failed: {type(e).__name__}: {e}") from e
            bar.update(1)
    return out
