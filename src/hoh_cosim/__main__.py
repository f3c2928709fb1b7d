"""`python -m hoh_cosim` is the `hoh-cosim` command."""

import sys

from hoh_cosim.cli import main

sys.exit(main())
