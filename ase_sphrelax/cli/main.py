"""The ``sphrelax`` entry point: one sub-parser per registered command, usage errors as one line."""
from __future__ import annotations

import argparse
import sys
import warnings

from . import registry
from .usage import UsageError

__all__ = ["build_parser", "main"]

PROG = "sphrelax"


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (``sphrelax CMD: error: ... (see sphrelax CMD --help)``),
    exit status 2, like every other usage error of ``sphrelax``; its sub-parsers are of this class too."""

    def error(self, message):
        text = " ".join(str(message).split())
        self.exit(2, f"{self.prog}: error: {text} (see {self.prog} --help)\n")


def build_parser(commands=None):
    """The ``sphrelax`` parser; each sub-parser carries its command object as ``args._command``.

    Parameters
    ----------
    commands : dict, optional
        ``{name: command}`` (default :func:`registry.commands`): objects with
        ``add_arguments(parser)`` and ``run(args)``.
    """
    from .. import __version__

    commands = registry.commands() if commands is None else commands
    parser = OneLineParser(prog=PROG, description="SPH particle relaxation (ase_sphrelax)")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, command in commands.items():
        short, long = registry.help_texts(command)
        parser_c = sub.add_parser(name, help=short, description=long,
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
        command.add_arguments(parser_c)
        parser_c.set_defaults(_command=command)
    return parser


def one_line_warnings(command):
    """A ``warnings.formatwarning`` that prints ``sphrelax COMMAND: warning: MESSAGE`` (one line, no file path)."""
    prefix = PROG if command is None else f"{PROG} {command}"

    def formatwarning(message, category, filename, lineno, line=None):
        return f"{prefix}: warning: {' '.join(str(message).split())}\n"

    return formatwarning


def main(argv=None):
    """Run ``sphrelax`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    A :class:`~ase_sphrelax.cli.usage.UsageError` is printed as one line and gives
    code 2; any other exception propagates with its traceback. Warnings (every one of the
    package is a :class:`~ase_sphrelax.checks.SphrelaxWarning`) print as one line,
    ``sphrelax COMMAND: warning: MESSAGE``, through ``warnings.formatwarning`` (so that a caller
    recording warnings, e.g. ``pytest.warns``, still receives them).
    """
    words = sys.argv[1:] if argv is None else list(argv)
    command = next((w for w in words if not w.startswith("-")), None)
    previous = warnings.formatwarning
    warnings.formatwarning = one_line_warnings(command)
    try:
        args = build_parser().parse_args(argv)
        try:
            code = args._command.run(args)
        except UsageError as error:
            message = " ".join(str(error).split())
            print(f"{PROG} {args.command}: error: {message}", file=sys.stderr)
            return 2
        return 0 if code is None else int(code)
    finally:
        warnings.formatwarning = previous
