"""Which data and video files a commit writes, and when small ones are joined.

LeRobot's loader reads `data/` by globbing every `*/*.parquet` in name order and takes row `i`
of that concatenation as frame `i` (`index` `i`); `aggregate_datasets` reads the data and video
files `meta/episodes` names, whole. So that neither ever sees a row or frame no commit owns, a
file a committed `meta/` refers to is never changed:

- a commit writes its episodes' rows and frames into NEW files, named after every file there
  (so their rows come after the committed ones in the glob), and only the `meta/` swap makes
  them part of the dataset;
- small files are joined (`join`) into a new file holding exactly their rows and frames, in
  order, named after every file there; `meta/` is swapped to refer to it, then the joined files
  are removed, and the new file is linked back to the first joined file's name (another swap),
  so names stay consecutive. At every step the glob's first `total_frames` rows are the
  committed ones, and every file `meta/` names holds exactly its episodes.

The files of a kind since the last full one are its *run*. Joins keep a run to a few files at
any time: the newest files are joined while the newer half weighs at least half of the file
before it (a binary counter: each byte is copied O(log) times) and the join stays under
`JOIN_BYTES`, so a commit writes its episodes plus at most `JOIN_BYTES`; a run is joined whole
when the next commit would take it past the kind's size (LeRobot's roll) and when the dataset
is closed, so a finished dataset has LeRobot's files. A join is an optimisation: one that fails
(a full disk) leaves the run as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ._memory import release

#: A join made between commits copies at most this many bytes (rolls and the close join a
#: whole run, once per file).
JOIN_BYTES = 16 * 2**20
#: How Parquet files are written. Dictionaries are kept small: Arrow's writer builds a column's
#: dictionary before giving up on it, which for a wide float column took five times the rows
#: (66 MiB for 12 MiB); under 64 KiB the index columns keep theirs.
PARQUET = {"compression": "snappy", "dictionary_pagesize_limit": 64 * 2**10}
#: Rows of a Parquet row group, in bytes: files are read and joined a row group at a time.
GROUP_BYTES = 4 * 2**20


def group_rows(table: Any) -> int:
    """Rows per row group for `table`, so that a group holds about `GROUP_BYTES`."""
    return max(1, GROUP_BYTES * max(len(table), 1) // max(table.nbytes, 1))


@dataclass
class Part:
    """One file of a run: where it is, its rows (data) or frames (video), its size in bytes, and
    the episodes it holds (`first`, `first + episodes`)."""

    at: tuple[int, int]
    count: int
    size: int
    first: int
    episodes: int


@dataclass
class Files:
    """A kind of file (`data`, or one camera's videos): its path template, the size it rolls
    at, the run (oldest first) and the index of the last file there."""

    kind: str  # "data" or the camera's key
    template: str
    limit_mb: float
    video: bool
    run: list[Part] = field(default_factory=list)
    last: tuple[int, int] | None = None

    def rel(self, at: tuple[int, int]) -> str:
        return self.template.format(chunk_index=at[0], file_index=at[1])

    def after_last(self, chunks_size: int) -> tuple[int, int]:
        if self.last is None:
            return (0, 0)
        chunk, file = self.last
        return (chunk + 1, 0) if file == chunks_size - 1 else (chunk, file + 1)

    def prefix(self) -> str:
        """The episodes' column prefix for this kind (`data`, `meta/episodes`, `videos/KEY`)."""
        return f"videos/{self.kind}" if self.video else self.kind

    def rolls(self, adding: int) -> bool:
        """Whether `adding` bytes would take the run to the size (LeRobot's rule)."""
        return bool(self.run) and (sum(p.size for p in self.run) + adding) / 2**20 >= self.limit_mb


def to_join(sizes: list[int], cap: int = JOIN_BYTES) -> int:
    """The first of the newest files to join (`len(sizes) - 1`: none): going back from the
    newest, a file joins while the files after it weigh at least half of it and the join stays
    under `cap` bytes."""
    j = len(sizes) - 1
    total = sizes[j] if sizes else 0
    while j > 0 and 2 * total >= sizes[j - 1] and total + sizes[j - 1] <= cap:
        j -= 1
        total += sizes[j]
    return j


class Groups:
    """Writes tables into `writer` in row groups of about `GROUP_BYTES`, whatever the tables'
    sizes: a file joined or rewritten a row group at a time would otherwise keep every row
    group it read, one per commit (a commit's episodes are one), and its row groups, its footer
    and the work of every later join or rewrite of it would grow with the number of commits.
    Holds at most a group's rows and the table given last."""

    def __init__(self, writer: Any) -> None:
        self.writer = writer
        self._tables: list[Any] = []
        self._bytes = 0
        #: Row groups written.
        self.written = 0

    def write(self, table: Any) -> None:
        self._tables.append(table)
        self._bytes += table.nbytes
        if self._bytes >= GROUP_BYTES:
            self.flush()

    def flush(self) -> None:
        """Writes what is held as one row group."""
        import pyarrow as pa

        if not self._tables:
            return
        table = self._tables[0] if len(self._tables) == 1 else pa.concat_tables(self._tables)
        self._tables, self._bytes = [], 0
        if len(table):
            self.writer.write_table(table, row_group_size=len(table))
            self.written += 1
        del table
        release()


def join_parquet(paths: list[Path], out: Path) -> None:
    """The rows of `paths`, in order, into one Parquet file, in row groups of about
    `GROUP_BYTES` (memory bounded by about two groups, not the files, once the allocators give
    each group back)."""
    import pyarrow.parquet as pq

    schema = pq.read_schema(paths[0])
    with pq.ParquetWriter(out, schema, **PARQUET) as writer:
        groups = Groups(writer)
        for path in paths:
            f = pq.ParquetFile(path)
            for i in range(f.num_row_groups):
                groups.write(f.read_row_group(i, use_threads=False).cast(schema))
        groups.flush()
