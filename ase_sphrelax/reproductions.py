"""The registry of reproductions: every paper result an entry with its command, files and headline numbers.

``reproductions/manifest.toml`` (at the repository root, not in the installed package) holds one
``[[entry]]`` per paper table or figure and per study that explains a difference; each headline number is a
key into a JSON, CSV or npz result file, with the value *as quoted in prose*. :meth:`Registry.check` verifies,
without running anything, that every number equals its file at the quoted precision and that every result file
exists. ``reproductions/README.md`` describes the format; ``sphrelax reproduce`` is the command line.

Examples
--------
From the repository root (the registry is not part of the installed package)::

    from ase_sphrelax.reproductions import Registry
    reg = Registry.load()
    reg.number("alaric-fig13:wall_ratio").value    # '8.4', as the prose quotes it
    reg.check()                                     # [] when every number equals its file
"""
from __future__ import annotations

import csv
import gzip
import io
import json
import math
import os
import re
import subprocess
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["STATUSES", "PAPERS", "Number", "Entry", "Registry", "find_root", "parse_key", "lookup",
           "read_data", "matches", "RegistryError"]

#: the statuses an entry or a number may have
STATUSES = ("reproduced", "qualitatively", "differs", "not done")
#: paper keys, in the order the results page lists them, with their titles
PAPERS = {
    "fan": "Fan et al.: particle relaxation (Eq. 3.8, Eq. 4.4)",
    "lattice": "Fan et al.: lattice patterns (Tables 1, 2)",
    "bipi": "BIPI: boundary-integral particle initialisation",
    "alaric": "ALARIC: initial conditions for any target density",
    "parvi": "SPH-ParVI: SPH as a sampler (our evaluation; the paper has none)",
    "speed": "Speed",
}
MANIFEST = Path("reproductions") / "manifest.toml"
_ID = re.compile(r"^[a-z0-9]+(-[a-z0-9.]+)+$")
_NAME = re.compile(r"^[A-Za-z0-9_.]+$")


class RegistryError(ValueError):
    """A malformed manifest, key or file (one-line message)."""


@dataclass(frozen=True)
class Number:
    """A headline number: ``value`` is the text prose quotes; the file's value at ``key`` must round to it."""

    entry_id: str
    name: str
    file: str
    key: str
    value: str
    paper: str = ""
    status: str = ""
    scale: float = 1.0

    @property
    def ref(self):
        """``"ENTRY:NAME"``, the reference syntax of prose."""
        return f"{self.entry_id}:{self.name}"


@dataclass(frozen=True)
class Entry:
    """One paper item or explaining study (see ``reproductions/README.md`` for the fields)."""

    id: str
    paper: str
    item: str
    title: str
    command: str
    status: str
    reason: str
    results: tuple = ()
    quick: str = ""
    numbers: tuple = field(default_factory=tuple)

    @property
    def folder(self):
        """``reproductions/<id>``, repository-relative."""
        return f"reproductions/{self.id}"


def find_root(start=None):
    """The repository root: the nearest folder at or above ``start`` (default: the working directory) that
    holds ``reproductions/manifest.toml``."""
    here = Path(start or os.getcwd()).resolve()
    for folder in (here, *here.parents):
        if (folder / MANIFEST).is_file():
            return folder
    raise RegistryError(f"no {MANIFEST} at or above {here}: run from the repository (or pass --root)")


def _text(raw, key, where, required=True):
    value = raw.get(key, "")
    if not isinstance(value, str):
        raise RegistryError(f"{where}: '{key}' must be a string, got {type(value).__name__}")
    if required and not value.strip():
        raise RegistryError(f"{where}: '{key}' is missing")
    return value


def _status(value, where):
    if value not in STATUSES:
        raise RegistryError(f"{where}: status {value!r} is not one of {', '.join(STATUSES)}")
    return value


def _entry(raw, index):
    where = f"entry {index + 1}"
    entry_id = _text(raw, "id", where)
    where = f"entry {entry_id!r}"
    known = {"id", "paper", "item", "title", "command", "quick", "results", "status", "reason", "number"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise RegistryError(f"{where}: unknown field(s) {', '.join(unknown)}; accepted: {', '.join(sorted(known))}")
    if not _ID.match(entry_id):
        raise RegistryError(f"{where}: id must look like paper-item (lower case, digits, '-', '.')")
    paper = _text(raw, "paper", where)
    if paper not in PAPERS:
        raise RegistryError(f"{where}: paper {paper!r} is not one of {', '.join(PAPERS)}")
    if not entry_id.startswith(paper + "-"):
        raise RegistryError(f"{where}: id must start with its paper, '{paper}-'")
    command = _text(raw, "command", where)
    if "\n" in command.strip():
        raise RegistryError(f"{where}: command must be one line")
    status = _status(_text(raw, "status", where), where)
    results = raw.get("results", [])
    if not isinstance(results, list) or not all(isinstance(r, str) for r in results):
        raise RegistryError(f"{where}: results must be a list of repository-relative paths")
    numbers = []
    for raw_n in raw.get("number", []):
        name = _text(raw_n, "name", f"{where} number")
        where_n = f"{entry_id}:{name}"
        if not _NAME.match(name):
            raise RegistryError(f"{where_n}: a number's name takes letters, digits, '_' and '.'")
        value = raw_n.get("value")
        if not isinstance(value, str):
            raise RegistryError(f"{where_n}: value must be the quoted text, a string (e.g. value = \"8.4\")")
        scale = raw_n.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale == 0:
            raise RegistryError(f"{where_n}: scale must be a finite non-zero number")
        n_status = raw_n.get("status", status)
        numbers.append(Number(entry_id, name, _text(raw_n, "file", where_n), _text(raw_n, "key", where_n),
                              value.strip(), _text(raw_n, "paper", where_n, required=False),
                              _status(n_status, where_n), float(scale)))
    names = [n.name for n in numbers]
    if len(set(names)) != len(names):
        raise RegistryError(f"{where}: a number name is used twice")
    return Entry(entry_id, paper, _text(raw, "item", where), _text(raw, "title", where), command.strip(), status,
                 _text(raw, "reason", where), tuple(results), _text(raw, "quick", where, required=False).strip(),
                 tuple(numbers))


# --------------------------------------------------------------------------------------------------- keys


def parse_key(key):
    """Split a key into segments: ``str`` (dict key), ``int`` (index) or ``dict`` (row selector).

    Segments are separated by ``.``; ``'a.b'`` (or ``"a.b"``) is one literal dict key; ``name[a=1,b=x]`` is
    ``name`` followed by a selector of the one row whose fields equal the values.
    """
    if not isinstance(key, str) or not key.strip():
        raise RegistryError("key must be a non-empty string")
    segments, i, n = [], 0, len(key)
    while i < n:
        ch = key[i]
        if ch == ".":
            i += 1
            continue
        if ch in "'\"":
            end = key.find(ch, i + 1)
            if end < 0:
                raise RegistryError(f"key {key!r}: unclosed quote")
            segments.append(key[i + 1:end])
            i = end + 1
        elif ch == "[":
            end = key.find("]", i)
            if end < 0:
                raise RegistryError(f"key {key!r}: unclosed '['")
            body = key[i + 1:end].strip()
            if re.fullmatch(r"-?\d+", body):
                segments.append(int(body))
            else:
                selector = {}
                for part in body.split(","):
                    name, eq, value = part.partition("=")
                    if not eq or not name.strip():
                        raise RegistryError(f"key {key!r}: a selector is [field=value,...], got [{body}]")
                    selector[name.strip()] = value.strip()
                segments.append(selector)
            i = end + 1
        else:
            match = re.match(r"[^.\[]+", key[i:])
            token = match.group(0)
            segments.append(int(token) if re.fullmatch(r"-?\d+", token) else token)
            i += len(token)
    return segments


def _same(a, b):
    if str(a) == b:
        return True
    try:
        return float(a) == float(b)
    except (TypeError, ValueError):
        return False


def lookup(data, key):
    """The value at ``key`` (a string or :func:`parse_key`'s segments) in nested dicts / lists / arrays."""
    segments = parse_key(key) if isinstance(key, str) else key
    value, path = data, []
    for seg in segments:
        path.append(seg)
        where = ".".join(str(p) for p in path)
        if isinstance(seg, dict):
            rows = value if isinstance(value, list) else None
            if rows is None:
                raise RegistryError(f"at {where}: a selector needs a list of rows, got {type(value).__name__}")
            hits = [r for r in rows if isinstance(r, dict) and all(k in r and _same(r[k], v) for k, v in seg.items())]
            if len(hits) != 1:
                raise RegistryError(f"at {where}: {len(hits)} rows match (need exactly one)")
            value = hits[0]
        elif isinstance(value, dict):
            if str(seg) in value:
                value = value[str(seg)]
            elif seg in value:
                value = value[seg]
            else:
                shown = ", ".join(list(map(str, value))[:8])
                raise RegistryError(f"at {where}: no key {seg!r} (has {shown}{', ...' if len(value) > 8 else ''})")
        elif isinstance(seg, int) and hasattr(value, "__getitem__") and not isinstance(value, str):
            try:
                value = value[seg]
            except IndexError:
                raise RegistryError(f"at {where}: index {seg} out of range") from None
        else:
            raise RegistryError(f"at {where}: cannot index a {type(value).__name__} with {seg!r}")
    if hasattr(value, "shape") and getattr(value, "shape", None) == ():
        value = value.item()
    return value


def read_data(path):
    """A result file as data: JSON (``.json``, ``.json.gz``), CSV (``.csv``, ``.csv.gz``: a list of row dicts)
    or ``.npz`` (a dict of arrays)."""
    path = Path(path)
    name = path.name
    if name.endswith(".npz"):
        import numpy as np

        with np.load(path, allow_pickle=False) as archive:
            return {k: archive[k] for k in archive.files}
    opener = gzip.open if name.endswith(".gz") else open
    stem = name[:-3] if name.endswith(".gz") else name
    if stem.endswith(".json"):
        with opener(path, "rt", encoding="utf-8") as fh:
            return json.load(fh)
    if stem.endswith(".csv"):
        with opener(path, "rt", encoding="utf-8", newline="") as fh:
            return list(csv.DictReader(io.StringIO(fh.read())))
    raise RegistryError(f"{path}: headline numbers read JSON, CSV or npz files, not {path.suffix or name}")


def matches(quoted, actual, scale=1.0):
    """Whether the file's ``actual`` rounds to the ``quoted`` text (at the precision quoted).

    ``"8.4"`` rounds to one decimal, ``"7.6e-9"`` to two significant figures, ``"1861"`` to an integer;
    ``true``/``false`` and other text compare exactly.
    """
    text = quoted.strip()
    if text.lower() in ("true", "false"):
        return isinstance(actual, bool) and actual == (text.lower() == "true") or str(actual).lower() == text.lower()
    try:
        target = float(text)
    except ValueError:
        return str(actual) == text
    if isinstance(actual, bool):
        return False
    try:
        value = float(actual) * scale
    except (TypeError, ValueError):
        return False
    if not math.isfinite(value) or not math.isfinite(target):
        return str(value) == str(target) or (math.isnan(value) and math.isnan(target))
    mantissa, _, exponent = text.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    if exponent:
        return float(f"{value:.{decimals}e}") == float(f"{target:.{decimals}e}")
    return float(f"{value:.{decimals}f}") == target


# --------------------------------------------------------------------------------------------------- registry


class Registry:
    """The entries of a manifest, with the repository root their paths are relative to."""

    def __init__(self, entries, root):
        self.entries = list(entries)
        self.root = Path(root)
        ids = [e.id for e in self.entries]
        dupes = sorted({i for i in ids if ids.count(i) > 1})
        if dupes:
            raise RegistryError(f"entry id(s) used twice: {', '.join(dupes)}")
        self._by_id = {e.id: e for e in self.entries}

    @classmethod
    def load(cls, root=None, manifest=None):
        """Read ``root/reproductions/manifest.toml`` (``root`` found by :func:`find_root` when omitted), or the
        manifest file ``manifest`` (paths in it stay relative to ``root``)."""
        root = Path(root).resolve() if root else (find_root(Path(manifest).parent) if manifest else find_root())
        path = Path(manifest) if manifest else root / MANIFEST
        try:
            raw = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise RegistryError(f"no manifest at {path}") from None
        except tomllib.TOMLDecodeError as error:
            raise RegistryError(f"{path}: {error}") from None
        unknown = sorted(set(raw) - {"entry"})
        if unknown:
            raise RegistryError(f"{path}: only [[entry]] tables are allowed, found {', '.join(unknown)}")
        return cls([_entry(e, i) for i, e in enumerate(raw.get("entry", []))], root)

    def entry(self, entry_id):
        """The entry ``entry_id``; ``KeyError`` with a one-line message if there is none."""
        try:
            return self._by_id[entry_id]
        except KeyError:
            raise KeyError(f"no registry entry {entry_id!r} (see sphrelax reproduce --list)") from None

    def number(self, ref):
        """The headline number ``"ENTRY:NAME"``; ``KeyError`` with a one-line message if there is none."""
        entry_id, sep, name = str(ref).partition(":")
        if not sep:
            raise KeyError(f"a registry reference is ENTRY:NAME, got {ref!r}")
        entry = self.entry(entry_id)
        for number in entry.numbers:
            if number.name == name:
                return number
        names = ", ".join(n.name for n in entry.numbers) or "none"
        raise KeyError(f"entry {entry_id!r} has no number {name!r} (it has {names})")

    def numbers(self):
        """Every headline number, in manifest order."""
        return [n for e in self.entries for n in e.numbers]

    def actual(self, number, _cache=None):
        """The value the number's file holds at its key (raises :class:`RegistryError`)."""
        path = self.root / number.file
        cache = {} if _cache is None else _cache
        if path not in cache:
            if not path.is_file():
                raise RegistryError(f"{number.file} does not exist")
            try:
                cache[path] = read_data(path)
            except (OSError, ValueError, EOFError) as error:
                if isinstance(error, RegistryError):
                    raise
                raise RegistryError(f"{number.file}: cannot be read ({' '.join(str(error).split())})") from None
        return lookup(cache[path], number.key)

    def check(self):
        """Every problem, one line each: a result file that does not exist, a key that does not resolve, a
        number that differs from its file at the quoted precision. An empty list means the registry is clean."""
        problems, cache = [], {}
        for entry in self.entries:
            for result in entry.results:
                if not (self.root / result).exists():
                    problems.append(f"{entry.id}: result file {result} does not exist")
            for number in entry.numbers:
                try:
                    actual = self.actual(number, cache)
                except RegistryError as error:
                    problems.append(f"{number.ref}: {error}")
                    continue
                if not matches(number.value, actual, number.scale):
                    scaled = f" (x{number.scale:g})" if number.scale != 1 else ""
                    problems.append(f"{number.ref}: quoted {number.value}, {number.file} holds {actual!r}{scaled}")
        return problems

    # ----------------------------------------------------------------------------------------------- output

    def table(self):
        """One row per entry: ``(id, paper, item, status, title)``."""
        return [(e.id, e.paper, e.item, e.status, e.title) for e in self.entries]

    def run(self, entry_id, quick=False, check=True):
        """Run an entry's command (``quick`` for its reduced size) from the root; the interpreter's folder goes
        first on ``PATH`` so ``python`` and ``sh run.sh`` use this environment. Returns the exit code."""
        entry = self.entry(entry_id)
        if quick and not entry.quick:
            raise RegistryError(f"entry {entry_id!r} defines no quick command (run it without --quick)")
        command = entry.quick if quick else entry.command
        env = dict(os.environ)
        env["PATH"] = os.path.dirname(sys.executable) + os.pathsep + env.get("PATH", "")
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(self.root), env.get("PYTHONPATH", "")]))
        print(f"$ {command}", flush=True)
        code = subprocess.call(command, shell=True, cwd=self.root, env=env)
        if code == 0 and check and not quick:
            sub = Registry([entry], self.root).check()
            for line in sub:
                print(f"check: {line}")
            return 1 if sub else 0
        return code

    def markdown(self):
        """``docs/results.md``: per paper, its items with ours and the paper's number side by side, the status
        and the command; a target ``(rep-ID)=`` per entry for the ``{rep}`` role's links."""
        lines = ["# Results: every paper result, its command and its files", "",
                 "Generated from `reproductions/manifest.toml` by `sphrelax reproduce --markdown docs/results.md`;",
                 "do not edit by hand. `sphrelax reproduce --check` verifies every number below against its result",
                 "file; `sphrelax reproduce ID` runs an entry. Each entry's folder `reproductions/ID/` holds its",
                 "script, its results and a README whose first sentence is the verdict.", ""]
        counts = {s: sum(e.status == s for e in self.entries) for s in STATUSES}
        lines += ["| status | entries |", "| --- | --- |"]
        lines += [f"| {s} | {counts[s]} |" for s in STATUSES] + [""]
        for paper, title in PAPERS.items():
            entries = [e for e in self.entries if e.paper == paper]
            if not entries:
                continue
            lines += [f"## {title}", "", "| entry | item | status | why |", "| --- | --- | --- | --- |"]
            lines += [f"| {{ref}}`{e.id} <rep-{e.id}>` | {_cell(e.item)} | {e.status} | {_cell(e.reason)} |"
                      for e in entries]
            lines.append("")
            for e in entries:
                lines += [f"(rep-{e.id})=", f"### {e.id}: {_cell(e.title)}", "",
                          f"**{e.status}**: {_cell(e.reason)}", "", f"- command: `{e.command}`"]
                if e.quick:
                    lines.append(f"- quick: `{e.quick}`")
                lines.append(f"- folder: `{e.folder}/` (README, script, results)")
                lines.append("")
                if e.numbers:
                    lines += ["| number | ours | paper | status | file and key |", "| --- | --- | --- | --- | --- |"]
                    lines += [f"| {n.name} | {_cell(n.value)} | {_cell(n.paper) or '-'} | {n.status} | "
                              f"`{n.file}` `{_cell(n.key)}` |" for n in e.numbers]
                    lines.append("")
        return "\n".join(lines).rstrip() + "\n"


def _cell(text):
    return " ".join(str(text).split()).replace("|", "\\|")
