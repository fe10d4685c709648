"""Means over seeds of a ``benchmarks/bench_sampling.py`` result: the numbers its ``report.md`` tables quote.

``python reproductions/lib/parvi_means.py DIR`` reads ``DIR/results.json.gz`` (or ``results.json``) and writes
``DIR/means.json``: one row per (target, M, method) with the mean over seeds of the energy distance
(``energy_mean``), the mean of its ratio to the i.i.d. row of the same target, M and seed (``over_iid_mean``: the
report's "relative to i.i.d." table since 2026-12-02), the ratio of the means (``over_iid_of_means``: the
tables of the quick and M = 2000 runs of 2026-12-01), and the number of seeds. Read by the registry (``reproductions/_fragments/parvi.toml``).

``python reproductions/lib/parvi_means.py FILE.json`` (rows of the SPH-only runners: ``run_sph``, the variants'
``run.py``) writes ``FILE_means.json`` next to it: per (target, M, variant, tag) the mean over seeds of
``ratio_to_iid``, its maximum and the seeds.
"""
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.results_io import read_json as load_json  # noqa: E402


def means(rows):
    """Rows of (target, m, method): ``energy_mean``, ``over_iid_mean`` (None without an i.i.d. row), ``seeds``."""
    iid = {(r["target"], r["m"], r["seed"]): r["energy"] for r in rows if r["method"] == "iid" and "energy" in r}
    groups = defaultdict(list)
    for r in rows:
        if isinstance(r.get("energy"), (int, float)):
            groups[(r["target"], r["m"], r["method"])].append(r)
    out = []
    iid_mean = {(t, m): np.mean([r["energy"] for r in group]) for (t, m, method), group in groups.items()
                if method == "iid"}
    for (target, m, method), group in groups.items():
        ratios = [r["energy"] / iid[(target, m, r["seed"])] for r in group if (target, m, r["seed"]) in iid]
        out.append(dict(target=target, m=m, method=method, seeds=len(group),
                        energy_mean=float(np.mean([r["energy"] for r in group])),
                        over_iid_mean=float(np.mean(ratios)) if len(ratios) == len(group) else None,
                        over_iid_of_means=(float(np.mean([r["energy"] for r in group]) / iid_mean[(target, m)])
                                           if (target, m) in iid_mean else None)))
    return out


def variant_means(rows):
    """Rows of (target, m, variant, tag): ``ratio_mean``, ``ratio_max`` over the seeds, ``seeds``."""
    groups = defaultdict(list)
    for r in rows:
        if isinstance(r.get("ratio_to_iid"), (int, float)):
            groups[(r["target"], r["m"], r["variant"], r.get("tag", ""))].append(r["ratio_to_iid"])
    return [dict(target=t, m=m, variant=v, tag=tag, seeds=len(x), ratio_mean=float(np.mean(x)), ratio_max=float(max(x)))
            for (t, m, v, tag), x in groups.items()]


def main(folder):
    if str(folder).endswith(".json"):
        path = Path(folder)
        data = dict(source=path.name, rows=variant_means(load_json(path)["rows"]))
        path.with_name(path.stem + "_means.json").write_text(json.dumps(data, indent=1))
        return
    folder = Path(folder)
    path = folder / "results.json.gz" if (folder / "results.json.gz").exists() else folder / "results.json"
    data = dict(source=path.name, rows=means(load_json(path)["rows"]))
    (folder / "means.json").write_text(json.dumps(data, indent=1))


if __name__ == "__main__":
    for arg in sys.argv[1:]:
        main(arg)
