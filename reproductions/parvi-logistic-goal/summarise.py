"""Print the tables of README.md from results.json (python reproductions/parvi-logistic-goal/summarise.py)."""
import json
from pathlib import Path

data = json.loads((Path(__file__).parent / "results" / "results.json").read_text())


def cells(r):
    return (f"{r['mean_err_max']:.3f} / {r['mean_err_median']:.3f} | {r['sd_ratio_min']:.3f}-{r['sd_ratio_max']:.3f} | "
            f"{r['sd_within_10pct']} | {r['energy']:.4f} | {r['log_precision_sd_ratio']:.2f} | "
            f"{100 * r['share_beyond_nuts_max']:.1f} %")


for goal_key in ("goal_main", "goal_m2000", "goal_m2000_r3", "goal_mala_only"):
    print(f"## {goal_key}")
    for r in data.get(goal_key, {}).get("rows", []):
        f = r["finish"]
        print(f"| {r['m']} | {r['seed']} | fluid ({r['steps']} steps) | {cells(r['fluid'])} | | |")
        print(f"| {r['m']} | {r['seed']} | + MALA {f['steps']} | {cells(r)} | {r['evaluations_per_particle']:.0f} | "
              f"{f['eps_max']:.3f}, {f['acceptance']:.2f}, {f['stuck_share']:.4f} | {r['wall']:.0f} |")
for g_key in ("gauss10d_main", "gauss10d_seeds3"):
    print(f"## {g_key}")
    for r in data.get(g_key, {}).get("rows", []):
        print(f"| {r['seed']} | {r['fluid_ratio_to_iid']:.2f} | {r['ratio_to_iid']:.2f} | {r['energy']:.5f} | {r['iid_energy']:.5f} | "
              f"{r['var_ratio_min']:.3f}-{r['var_ratio_max']:.3f} | {r['evaluations_per_particle']:.0f} | {r['wall']:.0f} |")
for key in ("rest", "k", "m"):
    print(f"## {key}")
    for r in data.get(key, {}).get("rows", []):
        fin = r["finishes"]
        label = f"M = {r['m']}, k = {r['options'].get('k', 20)}, {r['steps']} steps"
        print(f"| {label} | fluid | {cells(r)} | {r['kinetic_final']:.4f} / {r['kinetic_last_half_mean']:.4f} | "
              f"{r['converged']} | {r['radius_in_frame'][0]:.2f} ± {r['radius_in_frame'][1]:.3f} | {r['virial']:.2f} | {r['wall']:.0f} |")
        for name in ("radial", "mala200", "radial_on_nuts", "nuts_subset"):
            extra = ""
            if "radius_after" in fin[name]:
                extra = f"{fin[name]['radius_before'][0]:.2f} ± {fin[name]['radius_before'][1]:.3f} -> " \
                        f"{fin[name]['radius_after'][0]:.2f} ± {fin[name]['radius_after'][1]:.3f}"
            print(f"| {label} | {name} | {cells(fin[name])} | | | {extra} | | |")
print("## gauss32")
for r in data.get("gauss32", {}).get("rows", []):
    print(r)
print("## iid")
print(json.dumps(data.get("iid"), indent=1))
