"""The registry of reproductions: key look-up, quoted precision, one-line errors, the CLI, and the repository's
own registry clean (every headline number equals its file, every result file exists, every prose reference
resolves, docs/results.md is its regeneration)."""
import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from ase_sphrelax.cli.main import main
from ase_sphrelax.reproductions import (Registry, RegistryError, lookup, matches, parse_key, read_data)

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------------------ keys


def test_parse_key_segments():
    assert parse_key("rows.3.eps") == ["rows", 3, "eps"]
    assert parse_key("runs[form=log,boundaries=mirror].wall_ratio") == [
        "runs", {"form": "log", "boundaries": "mirror"}, "wall_ratio"]
    assert parse_key("'dx=0.01'.eps") == ["dx=0.01", "eps"]
    assert parse_key('a."b.c"[2]') == ["a", "b.c", 2]
    for bad in ("", "a['x", "a[b"):
        with pytest.raises(RegistryError):
            parse_key(bad)


def test_lookup_json_dicts_lists_and_selectors():
    data = {"runs": [{"form": "log", "n": 2000, "ratio": 8.4}, {"form": "paper", "n": 2000, "ratio": 1.5}],
            "dx=0.01": {"eps": 1e-6}, "m": [[1, 2], [3, 4]]}
    assert lookup(data, "runs[form=paper].ratio") == 1.5
    assert lookup(data, "runs[n=2000.0,form=log].ratio") == 8.4       # numbers compare as numbers
    assert lookup(data, "'dx=0.01'.eps") == 1e-6
    assert lookup(data, "m.1.0") == 3
    with pytest.raises(RegistryError, match="2 rows match"):
        lookup(data, "runs[n=2000].ratio")
    with pytest.raises(RegistryError, match="no key 'nope'"):
        lookup(data, "nope")
    with pytest.raises(RegistryError, match="out of range"):
        lookup(data, "m.5")


def test_read_data_json_gz_csv_npz(tmp_path):
    import gzip

    (tmp_path / "a.json").write_text(json.dumps({"x": 1.25}))
    with gzip.open(tmp_path / "b.json.gz", "wt") as fh:
        json.dump({"y": [1, 2]}, fh)
    (tmp_path / "c.csv").write_text("delta,eps\n1,7.6e-9\n0.5,1.1e-8\n")
    np.savez(tmp_path / "d.npz", a=np.arange(6.0).reshape(2, 3), s=np.float64(2.5))
    assert lookup(read_data(tmp_path / "a.json"), "x") == 1.25
    assert lookup(read_data(tmp_path / "b.json.gz"), "y.1") == 2
    assert float(lookup(read_data(tmp_path / "c.csv"), "[delta=0.5].eps")) == 1.1e-8
    d = read_data(tmp_path / "d.npz")
    assert lookup(d, "a.1.2") == 5.0 and lookup(d, "s") == 2.5
    (tmp_path / "e.md").write_text("8.4")
    with pytest.raises(RegistryError, match="JSON, CSV or npz"):
        read_data(tmp_path / "e.md")


# ------------------------------------------------------------------------------------------------ precision


@pytest.mark.parametrize("quoted, actual, ok", [
    ("8.4", 8.43, True), ("8.4", 8.46, False), ("8.40", 8.404, True), ("8.40", 8.41, False),
    ("7.6e-9", 7.57e-9, True), ("7.6e-9", 7.4e-9, False), ("1861", 1861.2, True), ("1861", 1862, False),
    ("0.76", "0.7649", True), ("true", True, True), ("false", True, False), ("log", "log", True),
    ("3", True, False), ("55.8", 55.83, True), ("30", 55.8, False),
])
def test_matches_at_quoted_precision(quoted, actual, ok):
    assert matches(quoted, actual) is ok


def test_matches_scale_for_percentages():
    assert matches("0.76", 0.0076, scale=100)
    assert not matches("0.76", 0.0077, scale=100)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=-1e12, max_value=1e12, allow_nan=False, allow_subnormal=False),
       st.integers(min_value=0, max_value=6))
def test_any_number_matches_its_own_rounding(x, decimals):
    """The number as printed at any precision (fixed or scientific) matches the number it was printed from."""
    assert matches(f"{x:.{decimals}f}", x)
    assert matches(f"{x:.{decimals}e}", x)


# ------------------------------------------------------------------------------------------------ manifest


def write_manifest(root, text):
    (root / "reproductions").mkdir(exist_ok=True)
    (root / "reproductions" / "manifest.toml").write_text(text)
    return root


ENTRY = """
[[entry]]
id = "alaric-fig13"
paper = "alaric"
item = "Fig. 13"
title = "a square"
command = "python -c 'import json; json.dump({{\\"r\\": 8.43}}, open(\\"out.json\\", \\"w\\"))'"
quick = "python -c 'print(1)'"
results = ["out.json"]
status = "differs"
reason = "why"

[[entry.number]]
name = "wall_ratio"
file = "out.json"
key = "r"
value = "{value}"
paper = "~1"
"""


@pytest.fixture
def repo(tmp_path):
    (tmp_path / "out.json").write_text(json.dumps({"r": 8.43}))
    return write_manifest(tmp_path, ENTRY.format(value="8.4"))


def test_clean_registry_and_number(repo):
    reg = Registry.load(repo)
    assert reg.check() == []
    n = reg.number("alaric-fig13:wall_ratio")
    assert (n.value, n.paper, n.status, n.ref) == ("8.4", "~1", "differs", "alaric-fig13:wall_ratio")
    with pytest.raises(KeyError, match="no number 'x'"):
        reg.number("alaric-fig13:x")
    with pytest.raises(KeyError, match="no registry entry"):
        reg.number("nope-1:x")


def test_check_finds_drift_and_missing_files(repo):
    write_manifest(repo, ENTRY.format(value="14"))
    (repo / "out.json").unlink()
    problems = Registry.load(repo).check()
    assert any("result file out.json does not exist" in p for p in problems)
    (repo / "out.json").write_text(json.dumps({"r": 8.43}))
    assert Registry.load(repo).check() == ["alaric-fig13:wall_ratio: quoted 14, out.json holds 8.43"]


@pytest.mark.parametrize("edit, message", [
    (("status = \"differs\"", "status = \"fine\""), "status 'fine' is not one of"),
    (("paper = \"alaric\"", "paper = \"fan\""), "id must start with its paper"),
    (("reason = \"why\"", "reason = \"why\"\ncolour = 1"), "unknown field"),
    (("value = \"8.4\"", "value = 8.4"), "value must be the quoted text"),
    (("command = ", "commandx = "), "unknown field"),
])
def test_bad_manifest_one_line_errors(repo, edit, message):
    write_manifest(repo, ENTRY.format(value="8.4").replace(*edit))
    with pytest.raises(RegistryError, match=message) as info:
        Registry.load(repo)
    assert "\n" not in str(info.value)


def test_duplicate_ids_rejected(repo):
    write_manifest(repo, ENTRY.format(value="8.4") * 2)
    with pytest.raises(RegistryError, match="used twice"):
        Registry.load(repo)


# ------------------------------------------------------------------------------------------------ CLI


def test_cli_list_check_markdown_run(repo, capsys, monkeypatch):
    monkeypatch.chdir(repo)
    assert main(["reproduce", "--list"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()
    assert len(rows) == 1 and rows[0].startswith("alaric-fig13")
    assert main(["reproduce", "--check"]) == 0
    assert "1 entries, 1 headline numbers, 0 problems" in capsys.readouterr().out
    assert main(["reproduce", "--markdown", "results.md"]) == 0
    page = (repo / "results.md").read_text()
    assert "(rep-alaric-fig13)=" in page and "| wall_ratio | 8.4 | ~1 | differs |" in page
    (repo / "out.json").unlink()
    assert main(["reproduce", "alaric-fig13"]) == 0                 # the command writes out.json again
    assert json.loads((repo / "out.json").read_text()) == {"r": 8.43}
    assert main(["reproduce", "alaric-fig13", "--quick"]) == 0
    write_manifest(repo, ENTRY.format(value="9.9"))
    assert main(["reproduce", "--check"]) == 1


def test_cli_usage_errors_are_one_line(repo, capsys, monkeypatch):
    monkeypatch.chdir(repo)
    assert main(["reproduce"]) == 2
    assert main(["reproduce", "nope-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("sphrelax reproduce: error: give exactly one of")
    assert "no registry entry 'nope-1'" in err[1]
    monkeypatch.chdir(repo.parent)
    assert main(["reproduce", "--list", "--root", str(repo / "nowhere")]) == 2


# ------------------------------------------------------------------------------------------------ this repository


@pytest.fixture(scope="module")
def registry():
    return Registry.load(ROOT)


def test_repository_registry_is_clean(registry):
    assert registry.check() == []


def test_every_entry_has_its_folder(registry):
    for entry in registry.entries:
        if entry.paper == "speed":        # speed entries keep their scripts and results in benchmarks/
            assert (ROOT / entry.folder / "README.md").is_file(), entry.id
            continue
        folder = ROOT / entry.folder
        assert (folder / "README.md").is_file(), entry.id
        scripts = [p for p in ("run.py", "run.sh") if (folder / p).is_file()]
        assert scripts or "reproductions/lib/" in entry.command or entry.command.startswith(("sphrelax", "make")), \
            f"{entry.id}: no run.py / run.sh and its command runs nothing of the registry"


def test_results_page_is_the_regeneration(registry):
    assert (ROOT / "docs" / "results.md").read_text(encoding="utf-8") == registry.markdown(), \
        "docs/results.md is stale: sphrelax reproduce --markdown docs/results.md"


PROSE = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "reproductions").glob("*/README.md"))]
ROLE = re.compile(r"\{rep\}`([^`]+)`")
MARKER = re.compile(r"<!--\s*rep\s+(\S+)\s*-->")
NUMBER_BEFORE = re.compile(r"(-?[0-9][0-9.,]*(?:e-?[0-9]+)?|\btrue|\bfalse)\s*(?:%|x|s|×)?\s*\**\)?\s*$")


def test_every_prose_reference_resolves(registry):
    missing = []
    for path in PROSE:
        text = path.read_text(encoding="utf-8")
        for ref in ROLE.findall(text) + MARKER.findall(text):
            try:
                registry.number(ref)
            except KeyError as error:
                missing.append(f"{path.relative_to(ROOT)}: {error}")
    assert not missing, "\n".join(missing)


def test_numbers_before_markers_equal_the_registry(registry):
    """``8.4x <!-- rep alaric-fig13:wall_ratio -->`` in a Markdown file GitHub shows: the number before the
    marker is the registry's value."""
    wrong = []
    for path in PROSE:
        text = path.read_text(encoding="utf-8")
        for match in MARKER.finditer(text):
            before = NUMBER_BEFORE.search(text[max(0, match.start() - 40):match.start()])
            value = registry.number(match.group(1)).value
            if before is None or before.group(1).replace(",", "") != value:
                wrong.append(f"{path.relative_to(ROOT)}: {match.group(1)} is {value}, the text says "
                             f"{before.group(1) if before else 'no number'}")
    assert not wrong, "\n".join(wrong)
