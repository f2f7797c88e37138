"""SIGTERM ends a command as Ctrl-C does: one handler for the console script (:mod:`harness.entry`, from its first
instant) and the command line (:func:`harness.cli.main`)."""
from __future__ import annotations

import signal

__all__ = ["TERMINATED", "on_sigterm", "interrupt_word", "interrupt_exit_code"]

TERMINATED: list = []      # the SIGTERM received, if any (then KeyboardInterrupt unwinds the command)


def on_sigterm(signum, frame):
    """Signal handler: record SIGTERM and raise KeyboardInterrupt, so that every ``finally`` runs (worker processes
    and clusters closed, output folders left as they were)."""
    TERMINATED.append(signum)
    raise KeyboardInterrupt


def interrupt_word() -> str:
    """"terminated" after SIGTERM, else "interrupted" (Ctrl-C)."""
    return "terminated" if TERMINATED else "interrupted"


def interrupt_exit_code() -> int:
    """143 (128 + SIGTERM) after SIGTERM, else 130 (128 + SIGINT)."""
    return 128 + int(signal.SIGTERM) if TERMINATED else 130
