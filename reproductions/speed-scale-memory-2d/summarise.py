"""The rows of ``results/rows_*.json`` (``speed-scale-memory-alaric/run.py``) per method and size: every run, the
max and the min, for each code state (``before``: c5d123d; ``after``: this entry's commit; ``copy_chunk``: the
same with the list copy of ``neighbors._copy_releasing`` chunked for small lists, not committed;
``copy_chunk_glibc``: that with ``sph.MMAP_THRESHOLD = None``, BIPI rows only; ``final``: the lead's commit that
took the chunked copy, with the session's other changes; ``bipi_glibc``: 3b80355, where BIPI's calculator leaves
glibc's mmap threshold alone in 2D, BIPI rows only). Writes
``results/summary.json``.

    python reproductions/speed-scale-memory-2d/summarise.py
"""
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
STATES = ("before", "after", "copy_chunk", "copy_chunk_glibc", "final", "bipi_glibc")


def main():
    out = dict(goal_bytes_per_particle=600, rows=[])
    for state in STATES:
        path = HERE / "results" / f"rows_{state}.json"
        if not path.exists():
            continue
        result = json.loads(path.read_text())
        groups = {}
        for row in result["rows"]:
            if row["n_target"] < 1e4:  # the throw-away row that wrote numba's cache of a fresh tree
                continue
            groups.setdefault((row["method"], f"{row['n_target']:.0e}".replace("+0", "")), []).append(row)
        for (method, size), rows in groups.items():
            b = [r["bytes_per_particle"] for r in rows]
            out["rows"].append(dict(state=state, method=method, size=size, n=rows[0]["n"], runs=len(b),
                                    bytes_per_particle=b, max=max(b), min=min(b), version=result["version"]))
    (HERE / "results" / "summary.json").write_text(json.dumps(out, indent=1) + "\n")
    for r in out["rows"]:
        print(f"{r['state']:10s} {r['method']:9s} {r['size']:4s} max {r['max']:4.0f} min {r['min']:4.0f} ({r['runs']} runs)")


if __name__ == "__main__":
    main()
