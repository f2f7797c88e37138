"""Data: the dataset format, the test protocol, the virtual rig, parameter files."""
