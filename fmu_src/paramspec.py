"""``ParamSpec``: one model parameter (name, SI unit, default, description, sign rule).

The very bottom of ``fmu_src`` (imports only dataclasses): ``fmu_src.specs`` (the paper's and the effects'
parameters) and ``fmu_src.terms`` (the generic term set's coefficients and time constants) both build on it.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ParamSpec:
    """One model parameter: its name (as in ``Params`` and the FMU), SI unit string (as in the
    modelDescription), default value, description and sign rule.

    Parameters
    ----------
    name : str
        The name in ``Params`` and the FMU.
    unit : str
        SI unit string as the modelDescription writes it (``"N.m/T2"``, ``"1"`` for none).
    default : float
        The FMU's start value [unit].
    description : str
        The FMU variable's description.
    positive : bool
        The value must be > 0.
    nonnegative : bool
        The value must be >= 0 (when ``positive`` is False).

    Examples
    --------
    >>> from fmu_src.specs import SPEC_BY_NAME
    >>> SPEC_BY_NAME["Em"].unit, SPEC_BY_NAME["Em"].default
    ('N.m/T2', 0.0423)
    """
    name: str
    unit: str            # SI unit string as used in the modelDescription
    default: float
    description: str
    positive: bool = True      # must be > 0
    nonnegative: bool = False  # must be >= 0 (used when positive is False)
