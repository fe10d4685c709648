"""JSON result files that may be gzipped (``x.json`` or ``x.json.gz``, the registry reads both): the one reader and
writer of the registry's scripts."""
import gzip
import json
from pathlib import Path


def read_json(path):
    """The JSON of ``path``; a ``.gz`` suffix is read through gzip."""
    path = Path(path)
    with (gzip.open(path, "rt") if path.suffix == ".gz" else open(path)) as handle:
        return json.load(handle)


def write_json(path, data):
    """Write ``data`` as indented JSON to ``path`` (gzipped, reproducibly, for a ``.gz`` suffix)."""
    path = Path(path)
    text = json.dumps(data, indent=1)
    if path.suffix == ".gz":
        with open(path, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, compresslevel=9, mtime=0) as out:
            out.write(text.encode())
    else:
        path.write_text(text)
