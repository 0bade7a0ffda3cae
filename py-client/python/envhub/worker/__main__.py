"""`python -m envhub.worker`: the Python worker's entry point (see `envhub.worker`)."""

import sys

from .entry import main

sys.exit(main())
