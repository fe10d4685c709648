"""The documentation runs as written: every ```sh, ```bash and ```python block of README.md and docs/**/*.md.

One test per file: its blocks run in order in one fresh folder (a block may use the files an earlier one
wrote), shell blocks with ``bash -e`` and ``sphrelax``/``python`` on the PATH as this checkout's, Python
blocks as ``python -c``. Skipped: docs/results.md (generated from the registry), the generated folders, and a
block preceded by the comment ``<!-- norun -->`` (e.g. ``make test``, which would run this test again).

Small sizes: with ``SPHRELAX_DOCS_QUICK=1`` (the default here; ``SPHRELAX_DOCS_QUICK=0`` runs the blocks
exactly as written) step counts are capped before running: ``--steps``/``steps=`` at 50,
``--max-steps``/``max_steps=`` at 300, the BIPI stage caps at 50. Nothing else is changed, so every option
and file a block names must exist; the data files come from ``sphrelax data NAME`` (package data).
"""
from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP_FILES = {"docs/results.md"}
SKIP_DIRS = ("docs/_build", "docs/generated", "docs/gallery", "docs/_ext")
LANGUAGES = {"sh": "sh", "bash": "sh", "shell": "sh", "python": "python", "py": "python"}
NORUN = "<!-- norun -->"
TIMEOUT = 900
QUICK = os.environ.get("SPHRELAX_DOCS_QUICK", "1") != "0"

# (pattern, cap): the number in group 2 is replaced by min(number, cap)
CAPS = [
    (r"(--steps[ =])(\d+)", 50),
    (r"(--max-steps[ =])(\d+)", 300),
    (r"(--max-steps-2[ac][ =])(\d+)", 50),
    (r"(\bsteps=)(\d+)", 50),
    (r"(\bmax_steps=)(\d+)", 300),
    (r"(\bmax_steps_2[ac]=)(\d+)", 50),
]


def doc_files():
    """README.md and docs/**/*.md, repository-relative, minus the generated ones."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    out = []
    for path in files:
        rel = path.relative_to(ROOT).as_posix()
        if rel in SKIP_FILES or rel.startswith(SKIP_DIRS):
            continue
        out.append(rel)
    return out


def code_blocks(text):
    """``[(language, code, line), ...]``: the fenced blocks to run (``sh`` or ``python``), in order."""
    blocks = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        match = re.match(r"^(`{3,}|~{3,})\s*([\w+-]*)\s*$", lines[i])
        if not match:
            i += 1
            continue
        fence, info = match.group(1), match.group(2).lower()
        start = i
        body = []
        i += 1
        while i < len(lines) and not lines[i].startswith(fence):
            body.append(lines[i])
            i += 1
        i += 1
        previous = next((line.strip() for line in reversed(lines[:start]) if line.strip()), "")
        if info in LANGUAGES and previous != NORUN:
            blocks.append((LANGUAGES[info], "\n".join(body) + "\n", start + 1))
    return blocks


def quick(code):
    """``code`` with the step counts capped (:data:`CAPS`)."""
    for pattern, cap in CAPS:
        code = re.sub(pattern, lambda m, cap=cap: f"{m.group(1)}{min(int(m.group(2)), cap)}", code)
    return code


def _shims(folder):
    """``sphrelax`` and ``python`` in ``folder``: this interpreter, this checkout."""
    folder.mkdir()
    for name, command in (("sphrelax", f'exec "{sys.executable}" -m ase_sphrelax.cli "$@"'),
                          ("python", f'exec "{sys.executable}" "$@"'), ("python3", f'exec "{sys.executable}" "$@"')):
        path = folder / name
        path.write_text(f"#!/usr/bin/env bash\n{command}\n")
        path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return folder


def test_code_blocks_are_found():
    """The reader finds fenced blocks, honours ``<!-- norun -->`` and caps steps only in the numbers it names."""
    text = "\n".join(["```sh", "sphrelax relax --steps 500", "```", "", NORUN, "```sh", "make test", "```",
                      "```python", "x = run(steps=5, max_steps=20000)", "```", "```text", "not code", "```"])
    blocks = code_blocks(text)
    assert [(lang, code.strip()) for lang, code, _ in blocks] == [
        ("sh", "sphrelax relax --steps 500"), ("python", "x = run(steps=5, max_steps=20000)")]
    assert quick(blocks[0][1]).strip() == "sphrelax relax --steps 50"
    assert quick(blocks[1][1]).strip() == "x = run(steps=5, max_steps=300)"
    assert quick("--max-steps-2a 5000 --max-steps 9600") == "--max-steps-2a 50 --max-steps 300"


def test_every_guide_has_runnable_blocks():
    """Each guide has a Python block and a shell block (its quick start), and none is marked norun."""
    for path in sorted((ROOT / "docs" / "guides").glob("*.md")):
        languages = {lang for lang, _, _ in code_blocks(path.read_text())}
        assert languages == {"sh", "python"}, path.name


@pytest.mark.slow
@pytest.mark.parametrize("doc", doc_files())
def test_doc_runs_as_written(doc, tmp_path):
    blocks = code_blocks((ROOT / doc).read_text())
    if not blocks:
        pytest.skip(f"{doc} has no sh or python block")
    work = tmp_path / "work"
    work.mkdir()
    shims = _shims(tmp_path / "bin")
    env = dict(os.environ, PATH=f"{shims}{os.pathsep}{os.environ.get('PATH', '')}",
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
               MPLBACKEND="Agg", OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    for language, code, line in blocks:
        code = quick(code) if QUICK else code
        if language == "sh":
            command = ["bash", "-e", "-o", "pipefail", "-c", code]
        else:
            command = [sys.executable, "-c", code]
        done = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True, timeout=TIMEOUT)
        assert done.returncode == 0, (f"{doc}:{line}: the {language} block exited {done.returncode}\n{code}\n"
                                      f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}")
