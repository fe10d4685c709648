"""Import a script of ``examples/`` or ``reproductions/`` as a module (they are scripts, not a package)."""
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
REPRODUCTIONS = ROOT / "reproductions"


def load_script(path, name=None):
    """The module at ``path`` (repository-relative, e.g. ``"reproductions/bipi-sph/run.py"``), executed once
    per call (its ``main`` is not run). ``reproductions/`` is put on ``sys.path`` so ``from lib import x``
    works inside registry scripts."""
    path = ROOT / path
    if str(REPRODUCTIONS) not in sys.path:
        sys.path.insert(0, str(REPRODUCTIONS))
    name = name or "script_" + "_".join(path.relative_to(ROOT).with_suffix("").parts).replace("-", "_")
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def load_example(name):
    """The module ``examples/<name>.py``, executed once per call (its ``main`` is not run)."""
    return load_script(f"examples/{name}.py", name=name)
