"""What counts as a usage error, and argparse types that reject bad numbers while parsing.

A command's ``run(args)`` has two phases:

* **set-up** -- reading files, building the scene, constructing calculators and
  drivers, i.e. everything where our constructors validate their input. Wrap it in
  ``with usage_errors():`` so that a ValueError, TypeError or FileNotFoundError
  there becomes a :class:`UsageError`;
* **run** -- the work itself. Exceptions there are internal errors and keep their
  traceback.

``sphrelax`` prints a :class:`UsageError` as one line, ``sphrelax CMD: error: ...``,
and exits with code 2 (as argparse does for bad options).
"""
from __future__ import annotations

import argparse
import math
from contextlib import contextmanager

__all__ = ["UsageError", "usage_errors", "positive", "non_negative_int", "non_negative_float"]

#: exceptions of the set-up phase that are the user's input, not our bug
SETUP_ERRORS = (ValueError, TypeError, FileNotFoundError)


class UsageError(Exception):
    """Bad command-line input: printed as one line, exit code 2."""


@contextmanager
def usage_errors():
    """Turn ValueError, TypeError and FileNotFoundError raised inside the block into :class:`UsageError`."""
    try:
        yield
    except UsageError:
        raise
    except SETUP_ERRORS as error:
        raise UsageError(str(error)) from error


def positive(kind):
    """argparse ``type``: a finite number > 0 of type ``kind`` (float or int)."""

    def parse(text):
        value = kind(text)
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
        return value

    parse.__name__ = f"positive {kind.__name__}"
    return parse


def non_negative_int(text):
    """argparse ``type``: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return value


def non_negative_float(text):
    """argparse ``type``: a finite number >= 0."""
    value = float(text)
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def unit_interval_open(text):
    """argparse ``type``: a number in [0, 1) (e.g. a heavy-ball momentum)."""
    value = float(text)
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1), got {text!r}")
    return value
