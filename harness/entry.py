"""The ``mpc-actuator`` console script (and ``python -m harness``): signals handled from the first instant.

Importing the command line (numpy, scipy, numba, matplotlib, fmpy) takes a second or more; a Ctrl-C or SIGTERM in
that second would otherwise end the program with a traceback from the middle of an import, or silently. Here
SIGTERM is turned into KeyboardInterrupt before anything is imported, and an interrupt during the imports ends the
program with one line (``interrupted`` / ``terminated``, exit code 130 / 143), as ``harness.cli.main`` does later.
"""
from __future__ import annotations

import os
import sys

from harness import scratch, signals
from harness.signals import interrupt_exit_code, interrupt_word


def main(argv=None):
    """Install the SIGTERM handler, import :mod:`harness.cli` and run its ``main``."""
    signals.install()
    try:
        try:
            from harness import cli
        except Exception as e:          # an error made of the interrupt (signals.from_interrupt) is the interrupt
            if signals.from_interrupt(e):
                raise KeyboardInterrupt from e
            raise
    except KeyboardInterrupt:
        signals.mark_handled()
        print(interrupt_word(), file=sys.stderr)
        _leave(interrupt_exit_code())
    try:
        try:
            code = cli.main(argv)
        except Exception as e:
            if signals.from_interrupt(e):
                raise KeyboardInterrupt from e
            raise
        signals.finish()                # the work is done: a signal from now on changes nothing
        return code
    except KeyboardInterrupt:           # before cli.main's own handler (parsing the arguments): one line too
        signals.mark_handled()
        print(interrupt_word(), file=sys.stderr)
        _leave(interrupt_exit_code())
    except SystemExit as e:
        if e.code == interrupt_exit_code():
            _leave(e.code)
        signals.finish()                # an error reported (or --help, --version): that is the outcome
        raise


def _leave(code: int):
    """End the process now with ``code`` after an interrupt that has been handled and reported: without the
    interpreter's exit-time joins of executor threads and FMU instances, which can block after a pool was stopped
    mid-task, and without its own verdict on the interrupt (a KeyboardInterrupt raised in the middle of an import
    can leave CPython's "unhandled KeyboardInterrupt" flag set, and the interpreter then ends by SIGINT, exit
    status -2, whatever SystemExit said: found by the 20-signal profile of tests/test_interrupts.py)."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:      # a closed pipe, a second interrupt: the code still stands
        pass
    try:
        scratch.remove()       # the extracted FMUs (the exit handler that would remove them does not run)
    except BaseException:
        pass
    os._exit(code)
