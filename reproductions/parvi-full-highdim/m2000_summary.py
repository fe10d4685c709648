import glob, gzip, json
for f in sorted(glob.glob("reproductions/parvi-full-highdim/results/m2000_gaussian10d_seed*/results.json.gz")):
    d = json.load(gzip.open(f, "rt")); rows = d["rows"]
    print(f.split("/")[-2], d["meta"]["git"], "load", [round(x, 1) for x in d["meta"]["load_average_start"]], [round(x, 1) for x in d["meta"]["load_average"]], round(d["meta"]["wall_so_far"]/60, 1), "min")
    for r in rows:
        print("  ", r["method"], "ratio", round(r.get("energy_over_iid", float("nan")), 2), "wall", round(r["wall"], 1),
              "eq-wall", round(r["energy_at_sph_wall"] / next(q["energy"] for q in rows if q["method"] == "iid"), 2) if "energy_at_sph_wall" in r else "", r.get("sph_wall_method", ""),
              "sd", round(r.get("sd_ratio_min", 0), 3), round(r.get("sd_ratio_max", 0), 3), r.get("error", "")[:40])
