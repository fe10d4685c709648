"""list, check and run the registry of paper reproductions

``sphrelax reproduce --list`` prints one row per entry of ``reproductions/manifest.toml``;
``sphrelax reproduce --check`` verifies, without running anything, that every headline number equals its
result file at the precision quoted and that every result file exists (exit 1 otherwise);
``sphrelax reproduce ID [--quick]`` runs one entry's command from the repository root;
``sphrelax reproduce --markdown docs/results.md`` writes the results page.
"""
from __future__ import annotations

import sys

from .usage import UsageError, usage_errors

__all__ = ["add_arguments", "run"]


def add_arguments(parser):
    parser.add_argument("id", nargs="?", default=None, metavar="ID",
                        help="the entry to run (its command, from the repository root)")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--list", action="store_true", help="print one row per entry: id, paper, item, status, title")
    action.add_argument("--check", action="store_true",
                        help="verify every headline number against its file and that every result file exists; "
                             "exit 1 on any problem")
    action.add_argument("--markdown", metavar="PATH", default=None,
                        help="write the results page (docs/results.md) generated from the manifest")
    parser.add_argument("--quick", action="store_true", help="with ID: the entry's reduced-size command")
    parser.add_argument("--root", default=None,
                        help="repository root (default: the nearest folder above the working directory that "
                             "holds reproductions/manifest.toml)")
    parser.add_argument("--manifest", default=None,
                        help="another manifest file (default ROOT/reproductions/manifest.toml); its paths stay "
                             "relative to the root")


def run(args):
    from ..reproductions import Registry, RegistryError

    chosen = sum(bool(x) for x in (args.list, args.check, args.markdown, args.id))
    if chosen != 1:
        raise UsageError("give exactly one of ID, --list, --check or --markdown PATH")
    if args.quick and not args.id:
        raise UsageError("--quick goes with an entry ID")
    with usage_errors():
        try:
            registry = Registry.load(root=args.root, manifest=args.manifest)
            if args.id:
                registry.entry(args.id)
        except (RegistryError, KeyError) as error:
            raise UsageError(str(error).strip("'\"")) from None
    if args.list:
        rows = registry.table()
        widths = [max(len(str(r[i])) for r in rows) if rows else 0 for i in range(4)]
        for row in rows:
            print("  ".join(str(c).ljust(w) for c, w in zip(row[:4], widths)) + "  " + row[4])
        print(f"{len(rows)} entries", file=sys.stderr)
        return 0
    if args.check:
        problems = registry.check()
        for line in problems:
            print(line)
        n_numbers = len(registry.numbers())
        print(f"{len(registry.entries)} entries, {n_numbers} headline numbers, {len(problems)} problems")
        return 1 if problems else 0
    if args.markdown:
        from pathlib import Path

        Path(args.markdown).write_text(registry.markdown(), encoding="utf-8")
        print(f"wrote {args.markdown} ({len(registry.entries)} entries)")
        return 0
    with usage_errors():
        try:
            return registry.run(args.id, quick=args.quick)
        except RegistryError as error:
            raise UsageError(str(error)) from None
