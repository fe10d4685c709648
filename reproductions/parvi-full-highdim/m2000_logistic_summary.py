"""Per-seed rows of the logistic posterior at M = 2000 (``m2000_logistic_seed*/results.json``).

    python reproductions/parvi-full-highdim/m2000_logistic_summary.py > \
        reproductions/parvi-full-highdim/results/m2000_logistic_summary.txt
"""
import glob
import gzip
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent / "results"  # this entry's results
FIELDS = ("energy", "mean_err_sd_max", "mean_err_sd_median", "sd_ratio_min", "sd_ratio_max", "sd_within_10pct",
          "energy_at_sph_wall", "wall", "evaluations")

for f in sorted(glob.glob(str(HERE / "m2000_logistic_seed*" / "results.json.gz"))):
    d = json.loads(gzip.open(f, "rt").read())
    meta = d["meta"]
    print(Path(f).parent.name, meta["git"], "load", [round(x, 1) for x in meta["load_average_start"]],
          [round(x, 1) for x in meta["load_average"]], round(meta["wall_so_far"] / 60, 1), "min")
    for r in d["rows"]:
        cells = " ".join(f"{k}={r[k]:.4g}" for k in FIELDS if isinstance(r.get(k), (int, float)))
        print("  ", r["method"], cells, r.get("sph_wall_method", ""), (r.get("error") or "")[:60])
