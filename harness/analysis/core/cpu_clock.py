"""The CPU clock of the fits' time budgets: CPU seconds along the critical path of a computation whose parallel
branches run in forked worker processes.

A wall-time budget makes a verdict depend on the machine's load: on a loaded machine the fits stop on the budget
earlier in their iterations (seen: a 20 kHz dataset's verdict changed between two runs at load 6). This clock
counts the CPU time of the process (``time.process_time``: user + system time of all its threads) and carries it
across ``fork``: a forked child starts from its parent's reading at the fork, and the parent, once it has the
results of its children, advances to the latest of their readings (:func:`advance_to`). Its reading is thus the
wall time the computation would have taken on idle cores, whatever else runs on the machine; a budget on it
stops the same fit at the same iteration on a loaded and on an idle machine (up to the small jitter of CPU
accounting).

Only the ``fork`` start method carries the reading; a child started by ``spawn`` counts from 0 (its budget check
is then generous, never early).
"""
from __future__ import annotations

import os
import time

_offset_s = 0.0          # [s] added to this process's CPU time: the parent's reading at the fork
_at_fork_s = 0.0         # [s] the reading of the process that is forking


def now() -> float:
    """[s] the CPU clock's reading: this process's CPU time plus its ancestors' at the forks that made it, plus
    the advances of :func:`advance_to`."""
    return _offset_s + time.process_time()


def advance_to(reading_s: float) -> None:
    """Advance the clock to ``reading_s`` [s] (a child's :func:`now` at the end of its work) if it is ahead: the
    parent's reading after waiting for parallel branches is the latest branch's."""
    global _offset_s
    lag = float(reading_s) - now()
    if lag > 0:
        _offset_s += lag


def _before_fork() -> None:
    global _at_fork_s
    _at_fork_s = now()


def _after_fork_in_child() -> None:
    global _offset_s
    # the child's own CPU time starts at (about) 0: carry the parent's reading
    _offset_s = _at_fork_s - time.process_time()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_before_fork, after_in_child=_after_fork_in_child)
