"""The 95 % profile interval of C or m from a deviance grid (``cm_profile.profile_interval``), against hand
computations: a quadratic deviance, and the same with part of the grid outside the search box (deviance +inf:
not simulated), where a row's minimum lies beside the box's edge. Deep profile, session 19: such a row gave a
NaN profile value (inf / inf in the parabola through the three lowest points), which dropped the row from the
95 % region and could make an interval's end NaN."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.analysis.identification.cm_profile import CHI2_95, profile_interval

AXIS = np.linspace(-3.0, 3.0, 13)          # step 0.5 on both axes


def _dev(shift_b: float = 0.3) -> np.ndarray:
    # rows: the profiled axis a; columns: the other axis b; deviance a^2 + 4 (b - shift_b)^2
    a, b = np.meshgrid(AXIS, AXIS, indexing="ij")
    return a ** 2 + 4.0 * (b - shift_b) ** 2


def _crossing(a0: float, p0: float, a1: float, p1: float) -> float:
    return a0 + (CHI2_95 - p0) / (p1 - p0) * (a1 - a0)


def test_quadratic_deviance_gives_the_hand_computed_interval():
    # each row's parabola through its three lowest points is exact: profile a^2; the region a^2 <= 3.8415 ends
    # between the grid points 1.5 (2.25) and 2.0 (4.0), linearly interpolated
    hi = _crossing(1.5, 2.25, 2.0, 4.0)
    assert hi == pytest.approx(1.9547025, abs=1e-6)
    lo_, hi_ = profile_interval(AXIS, _dev())
    assert lo_ == pytest.approx(-hi, abs=1e-12) and hi_ == pytest.approx(hi, abs=1e-12)


def test_a_row_minimum_beside_the_search_box_edge_is_its_value_there_not_nan():
    # b <= 0 outside the box: every row's minimum is at b = 0.5 (4 x 0.2^2 = 0.16) with +inf beside it; the
    # profile restricted to the box is a^2 + 0.16, whose region ends between 1.5 (2.41) and 2.0 (4.16)
    dev = _dev()
    dev[:, AXIS <= 0.0] = np.inf
    hi = _crossing(1.5, 2.25 + 0.16, 2.0, 4.0 + 0.16)
    assert hi == pytest.approx(1.9089882, abs=1e-6)
    with np.errstate(all="raise"):          # no inf / inf on the way
        lo_, hi_ = profile_interval(AXIS, dev)
    assert math.isfinite(lo_) and math.isfinite(hi_)
    assert lo_ == pytest.approx(-hi, abs=1e-12) and hi_ == pytest.approx(hi, abs=1e-12)


def test_rows_wholly_outside_the_box_end_the_interval_at_the_last_row_inside():
    # a <= -1 wholly outside the box (its rows +inf): the region's lower end is the box's edge, the grid row
    # a = -0.5 (profile 0.25); the upper end as in the quadratic case
    dev = _dev()
    dev[AXIS <= -1.0, :] = np.inf
    lo_, hi_ = profile_interval(AXIS, dev)
    assert lo_ == pytest.approx(-0.5, abs=1e-12)
    assert hi_ == pytest.approx(_crossing(1.5, 2.25, 2.0, 4.0), abs=1e-12)
