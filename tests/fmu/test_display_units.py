"""Display units in the modelDescription (issue 23 part 6): an importer shows strokes in mm, forces in mN, the field
in mT, ... while the FMU computes in SI.

Read with fmpy's own parser (``read_model_description(validate=True)``, the schema and fmpy's checks) and checked
against conversion factors written out by hand here (1 m = 1000 mm, 1 N/m = 0.001 N/mm, ...), not against
build_fmu's table; ``fmpy validate`` stays clean (``tests/fmu/test_fmu.py::test_fmpy_validate_cli_clean``).
"""
from __future__ import annotations

import subprocess
import sys

import pytest
from fmpy import read_model_description

# display unit -> (SI unit, factor: display value = factor * SI value), by hand
FACTORS = {"mm": ("m", 1e3), "um": ("m", 1e6), "mm/s": ("m/s", 1e3), "mN": ("N", 1e3), "mA": ("A", 1e3),
           "mT": ("T", 1e3), "mH": ("H", 1e3), "g": ("kg", 1e3), "N/mm": ("N/m", 1e-3), "mT/A": ("T/A", 1e3),
           "ms": ("s", 1e3)}
# the variables a user reads most, and the display unit each must be shown in
SHOWN_IN = {"x": "mm", "x_sensor": "mm", "a": "mm", "r0": "mm", "D": "mm", "v": "mm/s", "F": "mN", "F_sensor": "mN",
            "B": "mT", "L": "mH", "m": "g"}


def _units(md):
    return {u.name: u for u in md.unitDefinitions}


def test_display_units_are_defined_with_the_right_factors(fmu_path):
    md = read_model_description(str(fmu_path), validate=True)
    units = _units(md)
    for u in units.values():
        for d in u.displayUnits:
            assert d.name in FACTORS, f"display unit {d.name} of {u.name} has no hand-written factor here"
            si, factor = FACTORS[d.name]
            assert u.name == si, (d.name, u.name)
            assert float(d.factor) == pytest.approx(factor, rel=1e-15) and float(d.offset or 0.0) == 0.0, d.name
    # every unit a user would want scaled has its display unit
    assert {d.name for u in units.values() for d in u.displayUnits} >= {"mm", "mN", "mT", "mm/s", "mH", "g"}


def test_variables_name_a_display_unit_of_their_own_unit(fmu_path):
    md = read_model_description(str(fmu_path), validate=True)
    units = _units(md)
    by_name = {v.name: v for v in md.modelVariables}
    for v in md.modelVariables:
        if v.displayUnit is not None:
            assert v.displayUnit in {d.name for d in units[v.unit].displayUnits}, (v.name, v.unit, v.displayUnit)
    for name, shown in SHOWN_IN.items():
        assert by_name[name].displayUnit == shown, (name, by_name[name].unit, by_name[name].displayUnit)
    # the input voltage and the current stay in V and A (0.8 A, 12 V: nothing to scale)
    assert by_name["V"].displayUnit is None and by_name["I"].displayUnit is None


def test_controller_fmu_display_units_validate(controller_fmu_path):
    md = read_model_description(str(controller_fmu_path), validate=True)
    by_name = {v.name: v for v in md.modelVariables}
    assert by_name["x_ref"].displayUnit == "mm" and by_name["x_meas"].displayUnit == "mm"
    proc = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(controller_fmu_path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "No problems found" in proc.stdout, proc.stdout + proc.stderr
