"""The native FMU (``python build_fmu.py --native``): the model's equations traced from ``fmu_src`` into C
(``codegen``), the C template ``mpc_native.c`` (FMI 2.0 layer, force-kernel table, the integrator of
``fmu_src/integrator.py``), and the packaging (``package``)."""
