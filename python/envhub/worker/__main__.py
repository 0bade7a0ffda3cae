"""`python -m envhub.worker`: the Python worker's entry point (see `envhub.worker`);
`forkserver` starts a suite's fork server (`envhub.worker.fork_server`)."""

import sys

if sys.argv[1:2] == ["forkserver"]:
    from .fork_server import main
else:
    from .entry import main

sys.exit(main())
