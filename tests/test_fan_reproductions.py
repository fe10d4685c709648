"""The Fan entries' result writers: Table 2 against the printed table, the bounded circle's summary parser."""
import json

import pytest
from examples_loader import ROOT, load_script


def test_table2_comparison_counts_the_printed_digits(tmp_path):
    lattice = load_script("reproductions/lattice-table2/run.py")
    csv_path = ROOT / "reproductions/lattice-table2/results/table2_2d.csv"
    record = lattice.compare_with_paper(csv_path, tmp_path / "cmp.json")
    assert record == json.loads((tmp_path / "cmp.json").read_text())
    assert record["rows"] == 41 and record["pattern_rows_matching"] == 41
    assert [d["h"] for d in record["columns"]["diamond"]["differ"]] == [2.1, 2.15, 2.2, 3.15, 3.25]
    # one changed value in the CSV is one more differing row
    text = csv_path.read_text().replace("0.87802804", "0.87812804", 1)
    (tmp_path / "t.csv").write_text(text)
    changed = lattice.compare_with_paper(tmp_path / "t.csv", tmp_path / "cmp2.json")
    assert changed["columns"]["hexagonal"]["rows_matching"] == 40
    assert lattice.paper_pattern(2.0) == "square" and lattice.paper_pattern(2.08) is None


def test_bounded_summary_json_keeps_the_last_line_per_h(tmp_path):
    bounded = load_script("reproductions/fan-bounded-circle/run.py")
    lines = (ROOT / "reproductions/fan-bounded-circle/results/summary.txt").read_text().splitlines()
    later = lines[0].replace("steps=4500", "steps=6000")
    (tmp_path / "s.txt").write_text("\n".join(lines + [later]) + "\n")
    bounded.write_summary_json(tmp_path / "s.txt", tmp_path / "s.json")
    cases = json.loads((tmp_path / "s.json").read_text())["cases"]
    assert [c["h"] for c in cases] == [2.25, 2.75, 3.3, 2.0, 2.05, 2.15]
    assert cases[0]["steps"] == 6000 and cases[3]["pattern"] == "square" and cases[3]["fractions"]["square"] == 0.88
    (tmp_path / "bad.txt").write_text("not a summary line\n")
    with pytest.raises(ValueError, match="summary_txt"):
        bounded.write_summary_json(tmp_path / "bad.txt", tmp_path / "bad.json")
