"""Analysis, one subpackage per concern; each imports only from the ones listed before it
(``tests/test_architecture.py`` checks it):

==================  =====================================================================================
``core``            shared numerics that know no concern: checked signals (``signals``), settling times
                    and step metrics (``settling``, ``metrics``), the batched Levenberg-Marquardt solver
                    (``lsq``), NSGA-II by ask/tell (``nsga``), Dask task runs (``sweep``)
``identification``  the paper's identification (section 3): rig conventions inferred from the data
                    (``conventions``), the analytic steps (``analytic``), the C/m search (``objectives``,
                    ``selection``, ``identify``), the uncertainty of the identified parameters
                    (``cm_profile``, ``cm_joint``, ``parameter_uncertainty``), results
                    (``identify_results``) and the generalization surfaces (``generalize``)
``validation``      the model against measured data (``run``) and the FMI cross-check references
                    (``crosscheck``)
``uncertainty``     Monte-Carlo prediction bands (``bands``) and a dataset's uncertainty run (``run``)
``diagnosis``       which effect the paper's model leaves out hides in a dataset
``design``          inverse design over the generalization surfaces
==================  =====================================================================================
"""
