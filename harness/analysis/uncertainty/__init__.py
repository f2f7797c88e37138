"""Uncertainty propagation (``mpc-actuator uncertainty``): the identified parameters' uncertainty
(:mod:`harness.analysis.identification.parameter_uncertainty`) carried to the predictions.

=========  =======================================================================================
``bands``  Monte-Carlo prediction bands on every test of a sample (also of the generalized samples)
``run``    a whole dataset: parameter uncertainty and bands of every sample, as Dask tasks
=========  =======================================================================================
"""
