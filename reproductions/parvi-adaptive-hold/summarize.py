"""Every row of this folder's JSON files as one Markdown table (summary.md):
``PYTHONPATH=. .venv/bin/python reproductions/parvi-adaptive-hold/summarize.py``."""
import json
from pathlib import Path

HERE = Path(__file__).parent / "results"  # this entry's results
COLUMNS = ("target", "seed", "variant", "ratio_to_iid", "n_score_per_particle", "evaluations_per_particle", "hold_moved_share",
           "sph_steps", "sim_time_median", "converged", "wall", "load", "git")


def cell(value):
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def main():
    lines = []
    for path in sorted(HERE.glob("*.json")):
        lines += [f"## {path.name}", "", "| " + " | ".join(COLUMNS) + " |", "|" + " --- |" * len(COLUMNS)]
        for row in json.loads(path.read_text())["rows"]:
            lines.append("| " + " | ".join(cell(row.get(name)) for name in COLUMNS) + " |")
        lines.append("")
    (HERE / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
