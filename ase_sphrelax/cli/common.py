"""The habits every ``sphrelax`` command shares: output folder, progress bar, ``--h`` rules, sizes, summary.

* ``--out`` (its default shown in ``--help``) is refused when it holds files, unless ``--overwrite``;
* ``--progress/--no-progress``: default a bar when stderr is a terminal, none in a log or a pipe;
* ``--h`` (support radius in units of dx): refused at or below :data:`H_MIN`, a warning below
  :data:`H_TABLE`, unless a method documents another range;
* ``--max-particles``: a fill estimated past it is refused before any work
  (:func:`ase_sphrelax.build.estimate_fill`), and every fill prints its estimate first;
* ``summary.json`` records every parameter, the seed, the package version, the git commit (when
  the package runs from a git checkout) and ``converged`` with its reason (:func:`provenance`);
* exit :data:`EXIT_NOT_CONVERGED` when a run of the default length ends unconverged or degenerate
  (a fixed length the user asked for exits 0, warns and records ``converged: false``).

Only the standard library is imported at module level (``sphrelax --help`` stays light).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from .usage import UsageError, positive

__all__ = ["add_output_arguments", "add_progress_argument", "add_size_argument", "output_folder", "show_progress",
           "check_h_ratio", "check_fill_size", "provenance", "git_commit", "EXIT_NOT_CONVERGED", "H_MIN", "H_TABLE"]

#: exit status of a run that ended without reaching its own stopping rule (or degenerate)
EXIT_NOT_CONVERGED = 3
#: h/dx at or below this: the kernel support reaches no neighbour of the initial mesh (refused)
H_MIN = 1.0
#: h/dx below this: fewer than about 6 neighbours, large kernel-sum errors (Fan's Table 2 starts here; a warning)
H_TABLE = 1.5


def add_output_arguments(parser, default, products):
    """``--out`` (default ``default``, shown in ``--help``) and ``--overwrite``."""
    parser.add_argument("--out", default=default, help=f"output folder ({products}; default {default})")
    parser.add_argument("--overwrite", action="store_true",
                        help="write into --out even when it already holds files (default: refuse)")


def add_progress_argument(parser):
    """``--progress/--no-progress`` (default: a bar when stderr is a terminal, none in a log)."""
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="show a progress bar (default: on a terminal yes, in a log or pipe no)")


def add_size_argument(parser):
    """``--max-particles``: refuse a fill estimated beyond it (default 2e7)."""
    from_build = 20_000_000  # ase_sphrelax.build.MAX_PARTICLES (not imported: the parser stays light)
    parser.add_argument("--max-particles", type=positive(float), default=from_build,
                        help=f"refuse a fill estimated at more particles than this (default {from_build:.0e})")


def show_progress(args):
    """True when a bar is wanted: ``--progress``/``--no-progress``, else whether stderr is a terminal."""
    choice = getattr(args, "progress", None)
    if choice is not None:
        return bool(choice)
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


def output_folder(args):
    """``Path(args.out)``; a UsageError when it is a file, or a folder with files and no ``--overwrite``."""
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {args.out!r} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not getattr(args, "overwrite", False):
        raise UsageError(f"--out {args.out!r} already holds files: pass --overwrite to write into it, or choose "
                         "another folder")
    return out


def check_h_ratio(ratio, label=None, low=H_MIN, table=H_TABLE):
    """Refuse a support radius ``ratio <= low`` (in units of dx; UsageError); return warnings (strings) for
    ``ratio < table``.

    Parameters
    ----------
    ratio : float
        The kernel support radius in units of dx.
    label : str or None
        How the user gave it, for the messages (default ``"--h RATIO"``); a command with two conventions
        names both (``"--h-paper 0.5 (= --h 1)"``) so that they are not confused.
    low, table : float
        The refusal and warning limits (a method with another documented range passes its own).
    """
    label = f"--h {ratio:g}" if label is None else label
    if ratio <= low:
        raise UsageError(f"{label}: the kernel support radius is h = {ratio:g} dx, and h must be at least dx, more "
                         f"than {low:g} dx: at h <= {low:g} dx the support reaches no neighbour")
    if ratio < table:
        return [f"{label}: a support radius of h = {ratio:g} dx holds fewer than about 6 neighbours per particle; "
                f"kernel sums and their gradients have large errors (Fan's Table 2 starts at {table:g} dx)"]
    return []


def check_fill_size(domain, dx, max_particles, what="fill"):
    """Print the estimate of a fill (:func:`ase_sphrelax.build.estimate_fill`); ValueError past ``max_particles``."""
    from ..build import check_particle_count, describe_estimate, estimate_fill

    n, n_bytes = estimate_fill(domain, dx)
    print(f"{what}: {describe_estimate(n, n_bytes)} at dx = {dx:g}", flush=True)
    check_particle_count(n, n_bytes, max_particles, name="--max-particles")
    return n


def git_commit():
    """The git commit of the package's checkout, or None (an installed package, or no git)."""
    here = Path(__file__).resolve().parent
    try:
        done = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    commit = done.stdout.strip()
    return commit if done.returncode == 0 and len(commit) == 40 else None


def _plain(value):
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    return repr(value)


def provenance(args, command):
    """``summary.json``'s record of the run: ``arguments`` (every command-line parameter), the seed, the package
    version and the git commit."""
    from .. import __version__

    parameters = {k: _plain(v) for k, v in vars(args).items() if not k.startswith("_")}
    return dict(command=command, arguments=parameters, seed=parameters.get("seed"), version=__version__,
                git_commit=git_commit())
