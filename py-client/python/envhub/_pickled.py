"""Python objects through the data plane's text fields (reset options, info values).

The data plane carries an env's info as JSON of numbers, flags and text, and reset options
as JSON: enough for `make_vec`, lossy for a drop-in replacement of Gymnasium's
`AsyncVectorEnv`, whose infos and options are any picklable object. There the worker and the
client wrap the whole object in one text value, `{KEY: base64(pickle)}`, so it arrives as it
left (types, nesting, numpy dtypes). Both ends are the same user's processes, as with
Gymnasium's own pipes.
"""

from __future__ import annotations

import binascii
import pickle
from typing import Any

#: The key of a wrapped object.
KEY = "__envhub_pickle__"


def wrap(obj: Any) -> dict[str, str]:
    """`obj` as a JSON-safe one-key dict."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    return {KEY: binascii.b2a_base64(data, newline=False).decode("ascii")}


def unwrap(value: Any) -> Any:
    """The object `wrap` wrapped; anything else is returned as it is."""
    if isinstance(value, dict) and KEY in value:
        return pickle.loads(binascii.a2b_base64(value[KEY]))
    return value
