"""Values of the command line's options, checked where they are parsed.

Every numeric option of ``mpc-actuator`` is given a ``type=`` made by :func:`number`: it converts the text and
checks the option's allowed range. A bad value raises :class:`OptionValueError`, whose message names the option,
the allowed range and the value given (``--workers must be a whole number >= 1 (1 = run in this process), got
0``). It is deliberately *not* a ``ValueError``: argparse turns the ``ValueError``/``ArgumentTypeError`` of a
``type=`` into its usage text and exit code 2; this one passes through ``parse_args`` to ``harness.cli.main``,
which prints the one line ``error: ...`` and exits with code 1, as for any other error a user can fix.

Usage errors that argparse itself detects (an unknown option, a missing required option or argument, a
wrong number of values, a value outside ``choices``) keep argparse's usage text and exit code 2.
"""
from __future__ import annotations

import math
from typing import Callable

__all__ = ["OptionValueError", "number", "choice", "range_text"]


class OptionValueError(Exception):
    """A value of an option that is not a number or outside the option's range; the message names the option."""


def range_text(lo=None, hi=None, lo_open: bool = False, hi_open: bool = False) -> str:
    """">= 1", "> 0", "<= 100", "in (0, 100]": the allowed range in words."""
    def g(v):
        return f"{v:g}" if isinstance(v, float) else str(v)
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{g(lo)}, {g(hi)}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {g(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {g(hi)}"
    return ""


def number(option: str, lo=None, hi=None, *, lo_open: bool = False, hi_open: bool = False,
           integer: bool = False, why: str = "") -> Callable[[str], float | int]:
    """A ``type=`` for ``option``: the text as a finite float (or, with ``integer``, a whole number) in the
    range given by ``lo``/``hi`` (``lo_open``/``hi_open``: the bound itself excluded); ``why`` (e.g. "(1 = run
    in this process)") is added to the message. Raises :class:`OptionValueError` naming the option."""
    kind = "a whole number" if integer else "a finite number"
    rng = range_text(lo, hi, lo_open, hi_open)
    expected = " ".join(s for s in (kind, rng, why) if s)

    def convert(text: str):
        try:
            v = int(text) if integer else float(text)
        except (TypeError, ValueError):
            raise OptionValueError(f"{option} must be {expected}, got {text!r}") from None
        bad = (not math.isfinite(v)
               or (lo is not None and (v <= lo if lo_open else v < lo))
               or (hi is not None and (v >= hi if hi_open else v > hi)))
        if bad:
            raise OptionValueError(f"{option} must be {expected}, got {text}")
        return v

    convert.__name__ = option.lstrip("-").replace("-", "_")
    return convert


def choice(option: str, values) -> Callable[[str], str]:
    """A ``type=`` for an option taking one of ``values`` (words): the text itself, or
    :class:`OptionValueError` naming the option and the allowed words (``--minimise must be one of power,
    current, diameter, filler, got 'mass'``), so that a bad word ends in one line and exit code 1 (argparse's
    ``choices`` would print its usage text and exit with 2)."""
    allowed = tuple(values)

    def convert(text: str) -> str:
        if text not in allowed:
            raise OptionValueError(f"{option} must be one of {', '.join(allowed)}, got {text!r}")
        return text

    convert.__name__ = option.lstrip("-").replace("-", "_")
    return convert
