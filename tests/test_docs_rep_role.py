"""The ``{rep}`` role (docs/_ext/rep_role.py): a registry number rendered as its quoted value, linked to
the label ``rep-ID``; an unknown ``ID:NAME`` fails a ``-W`` build. Each build is a ``python -m sphinx`` process.

Each test builds a two-page Sphinx project in a temporary folder whose repository root holds a one-entry
``reproductions/manifest.toml`` (the format of reproductions/README.md). Where
``ase_sphrelax.reproductions`` does not exist yet, a stub with its API (``Registry.load(root).number(key)
.value``, KeyError for an unknown key) reads that manifest.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXT = ROOT / "docs" / "_ext"

MANIFEST = """\
[[entry]]
id = "fan-demo"
paper = "fan"
item = "Fig. 1"
title = "Fig. 1: a demonstration"
command = "python reproductions/fan-demo/run.py"
results = ["reproductions/fan-demo/results/table.json"]
status = "reproduced"
reason = "a test entry"

[[entry.number]]
name = "ratio"
file = "reproductions/fan-demo/results/table.json"
key = "ratio"
value = "8.4"
"""


STUB = """\
import tomllib
from pathlib import Path


class Number:
    def __init__(self, value):
        self.value = value


class Registry:
    def __init__(self, numbers):
        self.numbers = numbers

    @classmethod
    def load(cls, root):
        data = tomllib.loads((Path(root) / "reproductions" / "manifest.toml").read_text())
        return cls({f"{e['id']}:{n['name']}": Number(n["value"]) for e in data["entry"]
                    for n in e.get("number", [])})

    def number(self, key):
        if key not in self.numbers:
            raise KeyError(f"no number {key!r} in reproductions/manifest.toml")
        return self.numbers[key]
"""


def _project(tmp_path, body):
    repo = tmp_path / "repo"
    (repo / "reproductions" / "fan-demo" / "results").mkdir(parents=True)
    (repo / "reproductions" / "manifest.toml").write_text(MANIFEST)
    (repo / "reproductions" / "fan-demo" / "results" / "table.json").write_text(json.dumps({"ratio": 8.4}))
    docs = repo / "docs"
    docs.mkdir()
    (docs / "reproductions_stub.py").write_text(STUB)
    (docs / "conf.py").write_text(textwrap.dedent(f"""\
        import sys
        sys.path.insert(0, {str(EXT)!r})
        sys.path.insert(0, {str(docs)!r})
        try:
            import ase_sphrelax.reproductions
        except ImportError:  # before the registry module lands: a stub with its API
            import reproductions_stub
            sys.modules["ase_sphrelax.reproductions"] = reproductions_stub
        extensions = ["myst_parser", "rep_role"]
        rep_root = {str(repo)!r}
        """))
    (docs / "index.md").write_text("# Home\n\n```{toctree}\nresults\n```\n\n" + body + "\n")
    (docs / "results.md").write_text("# Results\n\n(rep-fan-demo)=\n## Fig. 1\n\nThe entry.\n")
    return docs


def _build(docs, out, *options):
    """``python -m sphinx -W --keep-going`` on ``docs``: (return code, stderr)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-E", "-b", "html", *options,
                           str(docs), str(out)], capture_output=True, text=True, env=env, timeout=300)
    return done.returncode, done.stderr


def test_rep_renders_the_value_linked_to_its_entry(tmp_path):
    docs = _project(tmp_path, "The ratio is {rep}`fan-demo:ratio` times.")
    code, errors = _build(docs, tmp_path / "html")
    assert code == 0, errors
    html = (tmp_path / "html" / "index.html").read_text()
    links = [part.split("</a>", 1)[0] for part in html.split('href="results.html#rep-fan-demo"')[1:]]
    assert any(">8.4<" in link for link in links), links  # (the toctree links there too, as "Fig. 1")


def test_unknown_number_fails_the_build(tmp_path):
    docs = _project(tmp_path, "The ratio is {rep}`fan-demo:nope` times.")
    code, errors = _build(docs, tmp_path / "html")
    assert code != 0
    assert "fan-demo:nope" in errors and "ERROR" in errors


@pytest.mark.parametrize("text", ["fan-demo", ":ratio", "fan-demo:"])
def test_malformed_reference_fails_the_build(tmp_path, text):
    docs = _project(tmp_path, f"Bad: {{rep}}`{text}`.")
    code, errors = _build(docs, tmp_path / "html")
    assert code != 0
    assert "ENTRY" in errors or "registry reference" in errors


def test_placeholder_mode_renders_the_key_without_error(tmp_path):
    docs = _project(tmp_path, "Later: {rep}`fan-demo:nope`.")
    code, errors = _build(docs, tmp_path / "html", "-D", "rep_missing=placeholder")
    assert code == 0, errors
    assert "fan-demo:nope" in (tmp_path / "html" / "index.html").read_text()
