"""Load a script of another SPH-ParVI entry (``reproductions/<id>/<name>``: the folder names are not importable)."""
import importlib.util
from pathlib import Path

HERE = Path(__file__).resolve().parent


def load(entry_id, name="run.py"):
    """The module of ``reproductions/<entry_id>/<name>``, executed once (cached under a unique module name)."""
    import sys

    key = f"_reproductions_{entry_id.replace('-', '_')}_{Path(name).stem}"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, HERE.parent / entry_id / name)
        module = importlib.util.module_from_spec(spec)
        sys.modules[key] = module
        spec.loader.exec_module(module)
    return sys.modules[key]
