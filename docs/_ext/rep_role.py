"""The ``{rep}`` role: a number of the reproductions registry, quoted in prose and linked to its entry.

``{rep}`alaric-fig13:wall_ratio``` (MyST) or ``:rep:`alaric-fig13:wall_ratio``` (reST) renders the
number's value exactly as the registry quotes it (``reproductions/manifest.toml``, read through
:class:`ase_sphrelax.reproductions.Registry`), as a cross-reference to the label ``rep-<id>`` that
``docs/results.md`` (generated from the registry) defines for every entry.

An ``ID:NAME`` the registry does not know is a build error (it fails ``sphinx -W``). For a quick build
of a tree whose registry is not complete yet, ``-D rep_missing=placeholder`` renders unknown numbers as
``ID:NAME`` in plain text with no link and no message; never use it for the site.
"""
from __future__ import annotations

from pathlib import Path

from docutils import nodes
from sphinx import addnodes
from sphinx.util import logging

logger = logging.getLogger(__name__)

__all__ = ["rep_role", "load_registry", "setup"]


def load_registry(root):
    """The registry of the repository at ``root`` (:meth:`ase_sphrelax.reproductions.Registry.load`)."""
    from ase_sphrelax.reproductions import Registry

    return Registry.load(Path(root))


_LOADED = {}  # repository root -> Registry, or the exception that loading it raised; emptied per build


def _registry(env):
    """The registry of ``rep_root`` (default: the folder above the documentation's source), loaded once per build."""
    root = str(Path(env.config.rep_root or Path(env.srcdir).parent).resolve())
    if root not in _LOADED:
        try:
            _LOADED[root] = load_registry(root)
        except Exception as error:  # noqa: BLE001 - reported as the error of every {rep} that needs it
            _LOADED[root] = error
    return _LOADED[root]


def rep_role(name, rawtext, text, lineno, inliner, options=None, content=None):
    """Render ``ID:NAME`` as the registry's quoted value, linked to the label ``rep-ID``."""
    env = inliner.document.settings.env
    key = text.strip()
    entry_id, sep, number_name = key.partition(":")
    registry = _registry(env)
    message = None
    if not sep or not entry_id or not number_name:
        message = f"{{rep}}`{key}`: expected ENTRY-ID:NUMBER-NAME"
    elif isinstance(registry, Exception):
        message = f"{{rep}}`{key}`: the reproductions registry could not be loaded: {registry}"
    else:
        try:
            value = str(registry.number(key).value)
        except KeyError as error:
            message = f"{{rep}}`{key}`: {error.args[0] if error.args else 'unknown number'}"
    if message is not None:
        if env.config.rep_missing == "placeholder":
            return [nodes.literal(rawtext, key, classes=["rep-missing"])], []
        msg = inliner.reporter.error(message, line=lineno)
        problem = inliner.problematic(rawtext, rawtext, msg)
        return [problem], [msg]
    if not hasattr(env, "rep_docs"):
        env.rep_docs = set()
    env.rep_docs.add(env.docname)
    content_node = nodes.inline(value, value, classes=["xref", "std", "std-ref", "rep"])
    xref = addnodes.pending_xref(rawtext, content_node, refdomain="std", reftype="ref",
                                 reftarget=f"rep-{entry_id}".lower(), refexplicit=True, refwarn=True,
                                 refdoc=env.docname)
    return [xref], []


def _forget(app, env, docnames):
    """Reload the registry at the start of every build (it may have changed since the last)."""
    _LOADED.clear()


def _outdated(app, env, added, changed, removed):
    """Read again every page that quotes the registry: its values may have changed with the manifest."""
    return sorted(getattr(env, "rep_docs", set()) - set(removed))


def _purge(app, env, docname):
    getattr(env, "rep_docs", set()).discard(docname)


def _merge(app, env, docnames, other):
    env.rep_docs = getattr(env, "rep_docs", set()) | getattr(other, "rep_docs", set())


def setup(app):
    app.add_config_value("rep_root", None, "env")
    app.add_config_value("rep_missing", "error", "env")
    app.add_role("rep", rep_role)
    app.connect("env-before-read-docs", _forget)
    app.connect("env-get-outdated", _outdated)
    app.connect("env-purge-doc", _purge)
    app.connect("env-merge-info", _merge)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
