"""The `envhub` command of an installed wheel (its console-script entry point).

The command line is the Rust `envhub` binary, bundled in the package's `bin/` beside the
workers it starts; this only runs it (exec, so signals and the exit status are its own),
after naming this interpreter as the one workers ask about installed packages (Gymnasium's
MJCF assets, the `mujoco` wheel's libmujoco) and that runs Python-hosted adapters.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

BINARY = Path(__file__).resolve().parent / "bin" / "envhub"


def main() -> None:
    if not BINARY.is_file():
        sys.exit(
            f"envhub: error: the bundled command line `{BINARY}` is missing\n"
            "hint: reinstall the envhub wheel; in the repository, `make py-install` puts it there"
        )
    env = dict(os.environ)
    env.setdefault("ENVHUB_PYTHON", sys.executable)
    os.execve(BINARY, [str(BINARY), *sys.argv[1:]], env)


if __name__ == "__main__":
    main()
