"""SIGTERM ends a command as Ctrl-C does: one handler for the console script (:mod:`harness.entry`, from its first
instant) and the command line (:func:`harness.cli.main`).

The handler raises KeyboardInterrupt in the main thread, so that every ``finally`` runs (worker processes and
clusters closed, output folders left as they were). A signal can arrive while the main thread runs code whose
exceptions Python ignores (an at-fork handler of ``logging`` while a process pool forks its workers, a ctypes
callback of llvmlite while numba compiles: "Exception ignored in ...") and the interrupt is then lost. So the
first signal also starts a watchdog thread: if the command line has not caught the interrupt
(:func:`mark_handled`) after ``REDELIVER_S`` it interrupts the main thread again, and after ``LAST_RESORT_S``
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

__all__ = ["TERMINATED", "on_sigterm", "on_signal", "install", "mark_handled", "finish", "interrupt_word",
           "interrupt_exit_code", "WHERE"]

TERMINATED: list = []      # the SIGTERM received, if any (then KeyboardInterrupt unwinds the command)
RECEIVED: list = []        # every SIGINT/SIGTERM received
HANDLED: list = []         # non-empty once the command line has caught the interrupt
FINISHED: list = []        # non-empty once the command has done its work (finish): a signal then changes nothing
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
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and RECEIVED:
        return
    _DEFAULT_UNRAISABLE[0](unraisable)


def mark_handled() -> None:
    """The command line has caught the interrupt (it cleans up and reports it): the watchdog stands down."""
    HANDLED.append(True)


def finish() -> None:
    """The command has done its work, or failed and said why: its exit code is decided, what is left is the
    interpreter's own end. A SIGINT or SIGTERM from now on changes nothing (no KeyboardInterrupt in the middle of
    the exit, no "interrupted" line after the outputs were written): the process ends with its own code."""
    FINISHED.append(True)


def _watchdog() -> None:
    time.sleep(REDELIVER_S)
    if HANDLED or FINISHED:
        return
    _thread.interrupt_main()          # the first KeyboardInterrupt was lost: once more
    time.sleep(LAST_RESORT_S - REDELIVER_S)
    if HANDLED or FINISHED:
        return
    word = interrupt_word()
    line = f"{word}: {WHERE[0]} left as it was\n" if WHERE[0] else f"{word}\n"
    try:
        os.write(2, line.encode())
    finally:
        os._exit(interrupt_exit_code())


def interrupt_word() -> str:
    """"terminated" after SIGTERM, else "interrupted" (Ctrl-C)."""
    return "terminated" if TERMINATED else "interrupted"


def interrupt_exit_code() -> int:
    """143 (128 + SIGTERM) after SIGTERM, else 130 (128 + SIGINT)."""
    return 128 + int(signal.SIGTERM) if TERMINATED else 130
