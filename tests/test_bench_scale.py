"""benchmarks/bench_scale.py --quick --methods fan2d runs and writes the JSON the docs read (no timing asserted:
speed goals live in benchmarks/, a timeout only stops a hung run)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_quick_fan2d_writes_the_json(tmp_path):
    out = tmp_path / "scale.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_scale.py"), "--quick", "--methods", "fan2d",
                    "--out", str(out)], env=env, check=True, capture_output=True, text=True, timeout=600)
    result = json.loads(out.read_text())
    for key in ("load_average_start", "load_average_end", "goals", "sizes", "methods", "version", "machine"):
        assert key in result, key
    assert result["sizes"] == [1e3, 3e3, 1e4]
    assert list(result["methods"]) == ["fan2d"]
    entry = result["methods"]["fan2d"]
    assert entry["dim"] == 2 and entry["not_measured"] == []
    rows = entry["rows"]
    assert [r["n_target"] for r in rows] == [1e3, 3e3, 1e4]
    for row in rows:
        assert "error" not in row, row
        assert abs(row["n"] - row["n_target"]) < 0.05 * row["n_target"]  # the fill holds about N particles
        assert row["steps"] >= 3 and row["wall_per_step"] > 0 and row["cpu_per_step"] > 0
        assert row["peak_rss"] >= row["base_rss"] and row["bytes_per_particle"] >= 0
    # the stored exponent is the log-log slope of the rows
    n = np.array([r["n"] for r in rows], float)
    slope = np.polyfit(np.log(n), np.log([r["cpu_per_step"] for r in rows]), 1)[0]
    assert entry["exponent_cpu"] == __import__("pytest").approx(slope)
    assert isinstance(entry["meets_exponent"], bool) and isinstance(entry["meets_memory"], bool)
    quality = entry["quality"][0]
    assert quality["n_target"] == 1e3 and quality["steps"] % 25 == 0 and quality["wall"] > 0
