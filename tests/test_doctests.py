"""The ``>>>`` examples of the public API's docstrings run as doctests (issue 23 part 3), so that the examples the
API reference shows cannot rot. They check hand-computable values: the RL step's 1 - 1/e at one time constant L/R,
the single-loop field kB I a^3/(a^2 + r0^2)^(3/2), the steady current V/R, the parameter rules' messages.
"""
from __future__ import annotations

import doctest
import importlib

import pytest

# module -> the least number of examples it must hold (a docstring that loses its examples fails too)
MODULES = {"harness.api": 6, "fmu_src.specs": 12, "fmu_src.model": 12, "fmu_src.terms": 1, "harness.analysis.design.space": 1}


@pytest.mark.parametrize("name", list(MODULES))
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS, report=True, verbose=False)
    assert result.failed == 0, f"{result.failed} docstring example(s) of {name} failed (printed above)"
    assert result.attempted >= MODULES[name]
