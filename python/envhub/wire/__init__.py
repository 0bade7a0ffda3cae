"""What both sides of a session share: the worker (inside each suite's interpreter) and the
client (the trainer's). Space descriptions and their byte codec, the typed info columns'
layout, the info tree and pickled payloads, the side channel for `call`/`get_attr`,
`EnvConfig`, autoreset mode names, and the error classes.

These modules import the standard library, numpy, Gymnasium's spaces and the compiled
`envhub._envhub` only: no Gymnasium vector code, no client session, nothing of the worker.
`scripts/check_layers.py` checks it.
"""
