"""The README's quick start runs as written (issue 19 item 4: the front page's 20 lines)."""
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"


def _quick_start():
    text = README.read_text()
    section = text.split("## Quick start", 1)[1]
    return re.search(r"```python\n(.*?)```", section, flags=re.S).group(1)


def test_quick_start_is_about_twenty_lines():
    assert 5 <= len(_quick_start().strip().splitlines()) <= 25


def test_quick_start_runs(capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(_quick_start(), str(README), "exec"), namespace)  # noqa: S102
    atoms = namespace["atoms"]
    assert atoms.calc.conservative and len(atoms) > 1000
    printed = capsys.readouterr().out.splitlines()  # the optimisers' logs, E and the quality summary
    summary = next(i for i, line in enumerate(printed) if "kernel_sum_error_mean" in line)
    assert float(printed[summary - 1]) > 0.0  # the total error E, printed just before


def test_front_page_is_short_and_links_exist():
    text = README.read_text()
    assert len(text.splitlines()) <= 160
    for link in re.findall(r"\]\(((?!https?:)[^)#]+)\)", text):
        assert (README.parent / link).exists(), link
