"""Shared numerics of the analysis, knowing no concern (imports nothing else from ``harness.analysis``).

============  ===========================================================================================
``signals``   checked signal arrays and the RMSE
``settling``  2 % settling times (also robust to noise, many responses at once), the step metrics
``metrics``   the error metrics of identification, validation and diagnosis (paper sections 3 and 6)
``lsq``       batched Levenberg-Marquardt (several box-bounded least-squares problems in lock-step)
``nsga``      NSGA-II (pymoo) by ask/tell, several runs in lock-step
``sweep``     sweeps and Monte-Carlo runs as Dask tasks (a local cluster or an existing one)
============  ===========================================================================================
"""
