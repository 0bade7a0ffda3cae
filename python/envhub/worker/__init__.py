"""The worker side: `python -m envhub.worker describe | serve --job JSON`, started by the hub
for Python-hosted adapters (`envhub.worker.hosted`), inside each suite's own interpreter.

`serve` creates a job's envs and hands them, as one `batch.HostedBatch` (or one
`batch.HostedVectorEnv` for a simulator vectorised inside itself), to the Rust serve loop in
`envhub._envhub`, which calls into Python once per request for the whole batch.

Its contract (docs/design/architecture.md, "The worker side's contract"): it imports `envhub.wire`,
`envhub.worker.hosted`, the standard library, numpy, Gymnasium and the suite's own packages, never
the client or the integrations; it runs on the oldest CPython, numpy and Gymnasium the contract
names (`tests/python/worker/test_contract.py` serves an env on exactly those).
"""

from .batch import HostedBatch, HostedEnv, HostedVectorEnv
from .entry import describe, main, make_batch, render_fps, serve

__all__ = ["HostedBatch", "HostedEnv", "HostedVectorEnv", "describe", "main", "make_batch", "render_fps", "serve"]
