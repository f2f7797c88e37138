"""SIGTERM ends a command as Ctrl-C does: one handler for the console script (:mod:`harness.entry`, from its first
instant) and the command line (:func:`harness.cli.main`).

The handler raises KeyboardInterrupt in the main thread, so that every ``finally`` runs (worker processes and
clusters closed, output folders left as they were). A signal can arrive while the main thread runs code whose
exceptions Python ignores (an at-fork handler of ``logging`` while a process pool forks its workers, a ctypes
callback of llvmlite while numba compiles: "Exception ignored in ...") and the interrupt is then lost. So the
first signal also starts a watchdog thread: it interrupts the main thread again as soon as Python reports the
interrupt lost (``sys.unraisablehook``), and, if the command line has not caught the interrupt
(:func:`mark_handled`) after ``REDELIVER_S`` (swallowed where nothing reports it), once more; after ``LAST_RESORT_S``
it prints the one line and ends the process (``os._exit``; pool workers and Dask workers end with their parent:
:mod:`harness.parallel`). Found by the 20-signal profile of tests/test_interrupts.py (2 of 400 runs hung).

Once the command has done its work (:func:`finish`: its outputs written or its error reported, the exit code
decided) a signal changes nothing: it is ignored while the interpreter ends, and from the last exit handler on
SIGINT and SIGTERM are ignored outright (Python restores their default action before it tears down its modules,
and a Ctrl-C then killed the process: exit status -2 instead of 0, 1 in 20 runs of ``design`` signalled as it
ended).
"""
from __future__ import annotations

import _thread
import atexit
import os
import signal
import sys
import threading
import time

from harness import scratch

__all__ = ["TERMINATED", "on_sigterm", "on_signal", "install", "mark_handled", "finish", "interrupt_word",
           "interrupt_exit_code", "from_interrupt", "WHERE"]

TERMINATED: list = []      # the SIGTERM received, if any (then KeyboardInterrupt unwinds the command)
RECEIVED: list = []        # every SIGINT/SIGTERM received
HANDLED: list = []         # non-empty once the command line has caught the interrupt
FINISHED: list = []        # non-empty once the command has done its work (finish): a signal then changes nothing
LOST = threading.Event()   # set when a KeyboardInterrupt of ours was lost in a callback (sys.unraisablehook)
WHERE: list = [None]       # the output folder, for the last-resort line
REDELIVER_S = 3.0          # [s] after the first signal: interrupt the main thread again if the interrupt was lost
LAST_RESORT_S = 8.0        # [s] after the first signal: print the line and end the process


def on_signal(signum, frame):
    """Signal handler (SIGINT, SIGTERM): record the signal, start the watchdog on the first, raise
    KeyboardInterrupt; nothing once the command has finished (:func:`finish`)."""
    if FINISHED:
        return
    if signum == signal.SIGTERM and not TERMINATED:
        TERMINATED.append(signum)
    first = not RECEIVED
    RECEIVED.append(signum)
    if first:
        threading.Thread(target=_watchdog, name="interrupt watchdog", daemon=True).start()
    raise KeyboardInterrupt


on_sigterm = on_signal


def install() -> None:
    """Handle SIGTERM, and SIGINT unless the process was started with it ignored (``nohup``, a background job of
    a shell): that choice of the caller stays; a KeyboardInterrupt that Python cannot raise (it came in a callback,
    "Exception ignored in ...") is not printed: the watchdog delivers it again. Main thread only."""
    if sys.unraisablehook is not _quiet_lost_interrupt:
        _DEFAULT_UNRAISABLE[0] = sys.unraisablehook
        sys.unraisablehook = _quiet_lost_interrupt
    signal.signal(signal.SIGTERM, on_signal)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, on_signal)
    if not _AT_EXIT:
        _AT_EXIT.append(True)
        atexit.register(_ignore_signals_at_exit)      # registered first, so it runs last


_AT_EXIT: list = []


def _ignore_signals_at_exit() -> None:
    """The last exit handler: the interpreter is ending (the command's outcome is decided, or it failed before
    deciding it); after the exit handlers Python restores the default action of the signals it handles, and
    SIGINT then killed the process while it tore down its modules. Ignored instead, the process ends with the
    exit code it has."""
    for s in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(s) not in (signal.SIG_IGN, signal.SIG_DFL, signal.default_int_handler, None):
            signal.signal(s, signal.SIG_IGN)


_DEFAULT_UNRAISABLE: list = [sys.unraisablehook]


def _quiet_lost_interrupt(unraisable) -> None:
    """A KeyboardInterrupt from our handler that Python could not raise (it came in a callback: "Exception
    ignored in ..."): not printed, and delivered again at once by the watchdog thread, so that it takes effect
    as soon as the main thread is out of the callback (before, the watchdog redelivered it after
    ``REDELIVER_S``: design and diagnose ended 3.5-6 s after one Ctrl-C now and then, probably thus)."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and RECEIVED:
        LOST.set()          # the watchdog delivers it again (here, it would interrupt this hook: lost again)
        return
    _DEFAULT_UNRAISABLE[0](unraisable)


def mark_handled() -> None:
    """The command line has caught the interrupt (it cleans up and reports it): the watchdog stands down."""
    HANDLED.append(True)


def from_interrupt(exc: BaseException) -> bool:
    """True if ``exc`` is an error made of our KeyboardInterrupt: a signal was received and a KeyboardInterrupt
    is among its causes. Python 3.11 turns a KeyboardInterrupt raised in a ``__set_name__`` (matplotlib's
    classes, while they are imported) into ``RuntimeError: Error calling __set_name__``: a SIGTERM during an
    import ended with that traceback (deep profile, uncertainty)."""
    seen = set()
    while exc is not None and id(exc) not in seen and RECEIVED:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def finish() -> None:
    """The command has done its work, or failed and said why: its exit code is decided, what is left is the
    interpreter's own end. A SIGINT or SIGTERM from now on changes nothing (no KeyboardInterrupt in the middle of
    the exit, no "interrupted" line after the outputs were written): the process ends with its own code."""
    FINISHED.append(True)


def _watchdog() -> None:
    t0 = time.monotonic()
    timed = False
    while True:
        lost = LOST.wait(max(0.0, (LAST_RESORT_S if timed else REDELIVER_S) - (time.monotonic() - t0)))
        if HANDLED or FINISHED:
            return
        if lost:                      # lost in a callback (the hook says so): delivered again at once
            LOST.clear()
            _thread.interrupt_main()
        elif not timed:               # lost where nothing tells (swallowed): once more after REDELIVER_S
            timed = True
            _thread.interrupt_main()
        else:
            break
    word = interrupt_word()
    line = f"{word}: {WHERE[0]} left as it was\n" if WHERE[0] else f"{word}\n"
    try:
        os.write(2, line.encode())
        scratch.remove()              # the extracted FMUs (exit handlers do not run)
    finally:
        os._exit(interrupt_exit_code())


def interrupt_word() -> str:
    """"terminated" after SIGTERM, else "interrupted" (Ctrl-C)."""
    return "terminated" if TERMINATED else "interrupted"


def interrupt_exit_code() -> int:
    """143 (128 + SIGTERM) after SIGTERM, else 130 (128 + SIGINT)."""
    return 128 + int(signal.SIGTERM) if TERMINATED else 130
