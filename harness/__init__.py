"""Test harness: data format, virtual rig, fmpy protocol runner, metrics, identification, diagnosis, CLI, plots."""
