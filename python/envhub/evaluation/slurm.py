"""`envhub eval ... --shards N --slurm-script FILE`: an `sbatch` job array whose task I runs
shard I into `OUT/shards/shard-I`, and whose task 0 submits the merge into `OUT` as a job
that starts once every task of the array has ended (`--dependency=afterany`: a shard whose
episodes failed still ends its slice, and the merge refuses a shard that did not)."""

from __future__ import annotations

import os
import shlex
import sys
from typing import Sequence

from .distribute import shard_folders
from .shards import ShardError

__all__ = ["slurm_script", "write_slurm_script"]


def slurm_script(
    benchmark: str, argv: Sequence[str], out: str, shards: int, options: Sequence[str] = (), report: bool = True
) -> str:
    """The script's text. `argv`: the shard's own `envhub eval` arguments (without `--out`,
    `--shard`, `--resume`); `options`: more `#SBATCH` lines (`--partition=gpu`, `--time=2:00:00`)."""
    if shards < 1:
        raise ShardError(f"--shards must be at least 1, not {shards}")
    for o in options:
        if not o.startswith("--") or "\n" in o:
            raise ShardError(f"--slurm-option `{o}`: give one sbatch option as --name=value (e.g. --partition=gpu)")
    out = os.path.abspath(out)
    args = shlex.join(argv)
    folders = " ".join(shlex.quote(f) for f in shard_folders(out, shards))
    merge = f'"$ENVHUB" eval merge {shlex.quote(out)} {folders}' + (" --report" if report else "")
    wrap = merge.replace('"', '\\"')  # inside the double quotes of `--wrap "..."`
    sbatch = "\n".join(f"#SBATCH {o}" for o in options)
    return f"""#!/bin/bash
# `envhub eval {benchmark}` as a Slurm job array: task I runs shard I of {shards} into
# {shlex.quote(out)}/shards/shard-I; task 0 also submits the merge into {shlex.quote(out)}, a job that
# starts once every task has ended. Submit with `sbatch THIS_FILE`. A task that is requeued or
# run again goes on from its last finished episode (--resume).
# Written by: envhub eval {args} --shards {shards} --out {shlex.quote(out)} --slurm-script ...
#SBATCH --job-name=envhub-eval-{benchmark}
#SBATCH --array=0-{shards - 1}
#SBATCH --output={out}/slurm/shard-%a.log
#SBATCH --chdir={os.getcwd()}
{sbatch}
set -euo pipefail
# The envhub command on the nodes (set ENVHUB to override: a path, or `python -m envhub`).
ENVHUB="${{ENVHUB:-envhub}}"
I="${{SLURM_ARRAY_TASK_ID:?run this script with sbatch (it is a job array), or set SLURM_ARRAY_TASK_ID}}"
mkdir -p {shlex.quote(out)}/slurm
if [ "$I" = 0 ] && [ "${{SLURM_RESTART_COUNT:-0}}" = 0 ]; then
    sbatch --dependency="afterany:${{SLURM_ARRAY_JOB_ID:?}}" --job-name=envhub-eval-{benchmark}-merge \\
        --output={shlex.quote(out)}/slurm/merge.log --chdir={shlex.quote(os.getcwd())} --wrap "{wrap}"
fi
exec "$ENVHUB" eval {args} --shard "$I/{shards}" --out {shlex.quote(out)}/shards/shard-"$I" --resume --quiet
"""


def write_slurm_script(path: str, text: str) -> str:
    """Writes the script (executable) and returns its path; says how to submit it on stderr."""
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(path, 0o755)
    print(f"wrote {path}: submit it with `sbatch {path}`", file=sys.stderr)
    return path
