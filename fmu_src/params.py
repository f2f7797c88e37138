"""Transition alias of ``fmu_src.specs`` (the one home of the parameter specs and ``Params``).

Kept only until the parallel branches of the restructuring are merged; new code imports ``fmu_src.specs``.
The FMU does not ship this module.
"""
from .specs import (EFFECT_FIELDS, MU0, SPEC_BY_NAME, SPECS, ParamSpec, Params,  # noqa: F401
                    param_names, validate)
