"""`python -m cpas_ocp.cli`, as the `cpas-ocp` script."""

import sys

from cpas_ocp.cli import main

sys.exit(main())
