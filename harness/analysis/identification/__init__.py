"""Parameter identification (paper section 3; ``mpc-actuator identify``): from the measured tests of a
sample to R, L, kB, Em, K1, K2 (analytic) and C, m (NSGA-II), with their uncertainty, and the
generalization surfaces over filler fraction and diameter (paper section 6.3).

=========================  ==================================================================================
``conventions``            the rig's conventions read from a dataset (sample periods, step instants, noise
                           floors, drive hold, coil radius)
``prepared``               the prepared dataset (frozen ``PreparedData``, derived once from the conventions:
                           coil, kB, sensor noise, step instants), which every later step reads
``analytic``               the paper's analytic steps (R, L, kB, Em, K1, K2), shared with the diagnosis
``objectives``             objectives of the C/m search (settling-time error and RMSE of simulated steps)
``selection``              the paper's Eq. 6 choice on the Pareto front and its residual check
``cm_profile``             covariance and profile-likelihood intervals of C and m
``cm_joint``               the identified (C, m) and the joint covariance of all seven parameters
``parameter_uncertainty``  covariance, intervals and random draws of the identified parameters
``settings``               ``IdentifySettings``: NSGA-II size, Eq. 6 weights, search space, which (C, m) is
                           handed downstream
``identify_results``       result types and their JSON / CSV form
``identify``               the entry points: ``identify_sample``, ``identify_dataset``, ``identify_and_write``
``generalize``             surface fits of Em, K1, K2, C, m over (wt%, D) and the unseen samples' parameters
=========================  ==================================================================================
"""
