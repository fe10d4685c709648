"""JSON result files that may be gzipped (``x.json`` or ``x.json.gz``, the registry reads both): the one reader and
writer of the registry's scripts."""
import gzip
import json
from pathlib import Path

from ase_sphrelax.reproductions import read_data


def read_json(path):
    """The JSON of ``path``; a ``.gz`` suffix is read through gzip (the registry's own reader,
    :func:`ase_sphrelax.reproductions.read_data`)."""
    return read_data(path)


def write_json(path, data):
    """Write ``data`` as indented JSON to ``path`` (gzipped, reproducibly, for a ``.gz`` suffix)."""
    path = Path(path)
    text = json.dumps(data, indent=1)
    if path.suffix == ".gz":
        with open(path, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, compresslevel=9, mtime=0) as out:
            out.write(text.encode())
    else:
        path.write_text(text)


class MergedRuns:
    """Per-start runs of one comparison made by separate processes (``--start NAME``), merged into one
    ``summary{tag}.json`` and ``ke{tag}.json.gz``.

    ``with MergedRuns(out, tag, summary, curves) as (summary, curves):`` holds an exclusive lock, reads
    what the files already hold and adds this process's ``summary["runs"]`` and ``curves`` to it; the caller
    adds what needs every start (ratios), and the files are written when the block ends."""

    def __init__(self, out, tag, summary, curves, merge=True):
        import tempfile

        self.out = Path(out)
        self.tag = tag
        self.summary, self.curves, self.merge = summary, curves, merge
        self._lock = Path(tempfile.gettempdir()) / f"{self.out.resolve().as_posix().replace('/', '_')}{tag}.lock"

    def __enter__(self):
        import fcntl

        self._handle = open(self._lock, "w")
        fcntl.flock(self._handle, fcntl.LOCK_EX)
        path = self.out / f"summary{self.tag}.json"
        if self.merge and path.exists():
            old = read_json(path)
            self.summary = dict(self.summary, runs={**old["runs"], **self.summary["runs"]})
            self.curves = {**read_json(self.out / f"ke{self.tag}.json.gz"), **self.curves}
        return self.summary, self.curves

    def __exit__(self, kind, value, traceback):
        import fcntl

        try:
            if kind is None:
                (self.out / f"summary{self.tag}.json").write_text(json.dumps(self.summary, indent=1) + "\n")
                with gzip.open(self.out / f"ke{self.tag}.json.gz", "wt") as f:
                    json.dump(self.curves, f)
        finally:
            fcntl.flock(self._handle, fcntl.LOCK_UN)
            self._handle.close()
