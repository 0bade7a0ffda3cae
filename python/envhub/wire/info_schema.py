"""Typed info columns in the batch slot: the worker's writer and the client's reader.

A session that asks for them (`info_row_bytes`, the drop-in's) gives every env a row of the
slot's column block. The worker learns a schema from its envs' infos (each key's dtype and
shape) and writes an info that fits it as that row, in one `struct.pack_into`: the schema's
id (a `u64`), the values, and one presence byte per key — Gymnasium's vector-info layout
(`key` and `_key`) once the rows are viewed as columns. The client views each key as a
strided array over the rows, in place, when every env of a step wrote its row with one
schema; otherwise it rebuilds each env's info and batches them as Gymnasium does. An info
that does not fit (a new key, text, a nested dict, a dtype the schema does not have) travels
as JSON, as before, for that env and step; its row's id is 0.

A value goes into a column only where Gymnasium batches it into a typed array of the same
dtype: a Python `bool`/`int`/`float` (as `bool`/`int64`/`float64`), a numpy number scalar of
a fixed-size real dtype, an array of such a dtype. (A `np.bool_` becomes an object array in
Gymnasium, so it stays on the JSON path.) The schema travels once, as JSON text under
`SCHEMA_KEY` in the info of the first env that uses it, with an id that is the hash of
the layout (so workers that learn the same layout write the same id, and a batch over
several workers is still viewed as one set of columns); the client checks it in Rust
(`envhub._envhub.info_schema`) before laying views over the slot with it.
"""


from __future__ import annotations

#: The info key that announces a schema (`envhub_protocol::info_columns::SCHEMA_KEY`).
SCHEMA_KEY = "__envhub_schema__"

#: Bytes per env of typed info columns in the batch slots of a Python-hosted session: room
#: for about a hundred scalar keys; a larger info takes the JSON path.
INFO_ROW_BYTES = 1024
