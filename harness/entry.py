"""The ``mpc-actuator`` console script (and ``python -m harness``): signals handled from the first instant.

Importing the command line (numpy, scipy, numba, matplotlib, fmpy) takes a second or more; a Ctrl-C or SIGTERM in
that second would otherwise end the program with a traceback from the middle of an import, or silently. Here
SIGTERM is turned into KeyboardInterrupt before anything is imported, and an interrupt during the imports ends the
program with one line (``interrupted`` / ``terminated``, exit code 130 / 143), as ``harness.cli.main`` does later.
"""
from __future__ import annotations

import os
import signal
import sys

from harness.signals import interrupt_exit_code, interrupt_word, on_sigterm


def main(argv=None):
    """Install the SIGTERM handler, import :mod:`harness.cli` and run its ``main``."""
    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        from harness import cli
    except KeyboardInterrupt:
        print(interrupt_word(), file=sys.stderr)
        raise SystemExit(interrupt_exit_code()) from None
    try:
        return cli.main(argv)
    except SystemExit as e:
        if e.code == interrupt_exit_code():
            # interrupted, cleaned up and reported: leave now, without the interpreter's exit-time joins of
            # executor threads and FMU instances, which can block after a pool was stopped mid-task
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(e.code)
        raise
