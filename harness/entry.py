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

_TERMINATED = []


def _on_sigterm(signum, frame):
    _TERMINATED.append(signum)
    raise KeyboardInterrupt


def main(argv=None):
    """Install the SIGTERM handler, import :mod:`harness.cli` and run its ``main``."""
    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        from harness import cli
    except KeyboardInterrupt:
        print("terminated" if _TERMINATED else "interrupted", file=sys.stderr)
        raise SystemExit(128 + int(signal.SIGTERM) if _TERMINATED else 130) from None
    try:
        return cli.main(argv)
    except SystemExit as e:
        if e.code in (130, 128 + int(signal.SIGTERM)):
            # interrupted, cleaned up and reported: leave now, without the interpreter's exit-time joins of
            # executor threads and FMU instances, which can block after a pool was stopped mid-task
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(e.code)
        raise
