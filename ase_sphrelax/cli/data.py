"""copy a data file shipped with the package (the documentation's boundaries) to a path

``sphrelax data --list`` lists the files; ``sphrelax data tank.edges`` writes ./tank.edges,
``--out PATH`` elsewhere (a folder or a file name). The files and their sources are described
in :mod:`ase_sphrelax.data`.
"""
from __future__ import annotations

__all__ = ["add_arguments", "run"]


def add_arguments(parser):
    parser.add_argument("name", nargs="?", default=None, metavar="NAME",
                        help="the file to copy (see --list), e.g. tank.edges")
    parser.add_argument("--list", action="store_true", help="list the data files and exit")
    parser.add_argument("--out", default=None, metavar="PATH",
                        help="where to write it: a file name, or an existing folder (default ./NAME)")
    parser.add_argument("--overwrite", action="store_true", help="replace PATH if it exists")


def run(args):
    from .. import data
    from .usage import UsageError, usage_errors

    if args.list:
        for name in data.names():
            print(name)
        return 0
    if args.name is None:
        raise UsageError(f"NAME is required (one of {', '.join(data.names())}), or --list")
    with usage_errors():
        try:
            target = data.copy(args.name, args.out, overwrite=args.overwrite)
        except FileExistsError:
            raise UsageError(f"--out {args.out or args.name!r} exists (pass --overwrite)") from None
    print(f"wrote {target}")
    return 0
