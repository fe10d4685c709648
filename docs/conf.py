"""Sphinx configuration of the ase_sphrelax documentation (``make docs``)."""
from __future__ import annotations

import os
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

# autosummary's recursive walk imports every module; ``python -m ase_sphrelax.cli`` would run ``sphrelax``
# with Sphinx's argv and exit: a mock of it is skipped by the walk
_cli_main = types.ModuleType("ase_sphrelax.cli.__main__")
_cli_main.__sphinx_mock__ = True
sys.modules.setdefault("ase_sphrelax.cli.__main__", _cli_main)

import ase_sphrelax  # noqa: E402

project = "ase_sphrelax"
author = "the ase_sphrelax developers"
copyright = "2026, the ase_sphrelax developers"  # noqa: A001
release = ase_sphrelax.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "rep_role",      # {rep}`ID:NAME`: a number of the reproductions registry, linked to its entry
    "cli_options",   # {cli-options} COMMAND: an option table generated from the argparse parser
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "**.ipynb_checkpoints", "gallery/*.md5", "gallery/*.py", "gallery/*.ipynb",
                    "gallery/*.zip", "gallery/*.json"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

autosummary_generate = True
autosummary_imported_members = False
# each object documented once, on the page of the module that defines it (packages re-export names
# in __all__; documenting those again would duplicate every object)
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set = set()

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples" / "gallery"),
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "show_memory": False,
}



def _skip_foreign(app, what, name, obj, skip, options):
    """Document only objects defined in this project (not scipy's cKDTree imported by a module)."""
    module = getattr(obj, "__module__", None)
    if isinstance(module, str) and not module.startswith(("ase_sphrelax", "lammps_io")) and what == "module":
        return True
    return None


def setup(app):
    app.connect("autodoc-skip-member", _skip_foreign)


html_theme = "pydata_sphinx_theme"
html_title = "ase_sphrelax"
html_theme_options = {"navigation_with_keys": False, "show_toc_level": 2}
html_static_path = ["_static"]
html_css_files = ["guides.css"]
suppress_warnings = ["config.cache"]
