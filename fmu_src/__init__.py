"""Physics of the MPC diaphragm actuator: what the FMU ships (no I/O), in layers that import only downward.

specs (parameter and effect specs, ``Params``, validation, the compiled block layout; pure Python)
-> equations (``coil``, ``field`` with the force kernel, ``diaphragm``, ``effects``: functions on floats
and numpy arrays) -> ``integrator`` (numba-compiled DP5 with contact events) -> ``model`` (Python API:
``Dynamics``, ``EffectDynamics``, ``ActuatorModel``, ``simulate``) -> ``statics`` (steady states, static
inverse, pull-in) -> the pythonfmu slaves ``mpc_actuator`` (the actuator) and ``mpc_controller`` (the controller).
``params`` is a transition alias of ``specs``. All quantities are SI.
"""
