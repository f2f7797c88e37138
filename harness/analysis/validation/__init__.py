"""Validation: the model against measured data, and the FMU against stored references.

==============  =================================================================================
``run``         the protocols T1-T8 replayed through the FMU and compared with the measured data
``crosscheck``  reference checks in the FMI cross-check style (any FMU build against stored runs)
==============  =================================================================================
"""
