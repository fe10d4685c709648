"""The ``cli-options`` directive: a command's option table generated from the ``sphrelax`` argparse parser.

In MyST::

    ```{cli-options} pack
    ```

renders one row per argument of ``sphrelax pack`` (options of its methods and engines included): the flags
with their metavar or choices, the default, and the help text as ``sphrelax pack --help`` prints it. The
table is built from :func:`ase_sphrelax.cli.build_parser` at every build, so it cannot drift from the
parser. ``{cli-options}`` with no argument lists the commands and their one-line help.
"""
from __future__ import annotations

import argparse

from docutils import nodes
from docutils.parsers.rst import Directive

__all__ = ["CliOptions", "command_parsers", "option_rows", "setup"]

_SUPPRESS = argparse.SUPPRESS


def command_parsers():
    """``{name: (sub-parser, one-line help)}`` of every ``sphrelax`` command, in ``sphrelax --help`` order."""
    from ase_sphrelax.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {choice.dest: choice.help for choice in sub._choices_actions}
    return {name: (p, helps.get(name, "")) for name, p in sub.choices.items()}


def _flags(action):
    if not action.option_strings:
        return action.metavar or action.dest.upper()
    if action.nargs == 0:
        return ", ".join(action.option_strings)
    if action.choices is not None and action.metavar is None:
        value = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        value = action.metavar or action.dest.upper()
        if isinstance(value, tuple):
            value = " ".join(value)
    if action.nargs in ("*", "+"):
        value = f"{value} ..."
    elif action.nargs == "?":
        value = f"[{value}]"
    elif isinstance(action.nargs, int) and action.nargs > 1:
        value = " ".join([value] * action.nargs)
    return ", ".join(f"{flag} {value}" for flag in action.option_strings)


def _default(action):
    if action.nargs == 0 or action.default in (None, _SUPPRESS) or isinstance(action, argparse._HelpAction):
        return ""
    if isinstance(action.default, (list, tuple)):
        return " ".join(str(v) for v in action.default)
    return str(action.default)


def option_rows(parser):
    """``[(flags, default, help), ...]`` of ``parser``'s arguments (``--help`` and suppressed ones left out)."""
    formatter = parser._get_formatter()
    rows = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or action.help == _SUPPRESS:
            continue
        text = formatter._expand_help(action) if action.help else ""
        rows.append((_flags(action), _default(action), " ".join(text.split())))
    return rows


def _table(header, rows, widths):
    table = nodes.table(classes=["cli-options"])
    group = nodes.tgroup(cols=len(header))
    table += group
    for width in widths:
        group += nodes.colspec(colwidth=width)

    def row(cells, literal_first):
        line = nodes.row()
        for i, text in enumerate(cells):
            entry = nodes.entry()
            para = nodes.paragraph()
            if text:
                para += nodes.literal(text, text) if (i == 0 and literal_first) or (i == 1 and text) else \
                    nodes.Text(text)
            entry += para
            line += entry
        return line

    head = nodes.thead()
    head += row(header, literal_first=False)
    group += head
    body = nodes.tbody()
    for cells in rows:
        body += row(cells, literal_first=True)
    group += body
    return table


class CliOptions(Directive):
    """``{cli-options} COMMAND``: the option table of ``sphrelax COMMAND``; no argument: the command list."""

    optional_arguments = 1
    has_content = False

    def run(self):
        parsers = command_parsers()
        if not self.arguments:
            rows = [(f"sphrelax {name}", "", short) for name, (_, short) in parsers.items()]
            table = _table(("command", "", "what it does"), rows, (30, 1, 69))
            return [table]
        name = self.arguments[0]
        if name not in parsers:
            raise self.error(f"cli-options: unknown command {name!r} (known: {', '.join(parsers)})")
        parser, _ = parsers[name]
        return [_table(("option", "default", "what it does"), option_rows(parser), (30, 12, 58))]


def setup(app):
    app.add_directive("cli-options", CliOptions)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
