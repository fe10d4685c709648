"""Provenance recorded in every benchmark's JSON."""
from __future__ import annotations

import subprocess
from pathlib import Path


def git_version():
    """``git describe --always --dirty`` of the checkout (uncommitted core changes show as -dirty)."""
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], cwd=Path(__file__).resolve().parent,
                              capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def write_json(path, data):
    """Write a benchmark's results (creating the folder) and say where."""
    import json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))
    print(f"wrote {path}")
