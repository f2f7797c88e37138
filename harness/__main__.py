"""``python -m harness ...``: the ``mpc-actuator`` command line (:mod:`harness.entry`)."""
import sys

from harness.entry import main

sys.exit(main())
