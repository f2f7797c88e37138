"""Inverse design (``mpc-actuator design``): from targets (stroke, blocked force, settling time, current,
power) to the feasible region of (wt%, D, gap, voltage) over the generalization surfaces, with the
probability of meeting the spec from the parameter uncertainty.

=============  =============================================================================
``space``      targets (:class:`Targets`), the design grid (:class:`DesignSpace`), :class:`DesignError`
``evaluate``   the evaluation kernel: static operating point, blocked force, current, power and a short
               step response of a block of designs sharing D and the gap
``advice``     ranking by the objective, refinement off the grid (SLSQP inside the hull), linearised
               probabilities, trade-off front, the robust (tightened) spec, what a design misses
``run``        surfaces, hull check, the nominal sweep, advice and the probabilities as Dask tasks
=============  =============================================================================
"""
