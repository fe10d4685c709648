"""CPU time of the BIPI sphere case (examples/bipi_results.py ``sphere_3d``), this checkout against a baseline.

The sphere of radius 0.5 (``Sphere.to_mesh(3)``, 1280 triangles), dx = 0.05, h_B/dx = 2 (4032 particles),
packed with the case's settings but capped (default 40 iterations of Step 2a, 80 of 2c), in fresh processes
alternating baseline and current checkout (``--rounds`` rounds), one numba thread, after an untimed
2 + 2 iteration packing that compiles. Reports process (CPU) time: on the shared 2-vCPU machine the wall
time follows the load (8x the CPU time at load 16), the CPU time does not. The final |grad C|_avg of both
is printed: the same trajectory to rounding.

    python benchmarks/bench_bipi_sphere.py --baseline /path/to/old/checkout [--rounds 2] [--caps 40 80]

Writes benchmarks/results/bench_bipi_sphere.json (one record per process).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import json, os, sys, time, warnings
warnings.simplefilter("ignore")
from ase_sphrelax.boundary import BoundaryTriangles
from ase_sphrelax.domains import Sphere
from ase_sphrelax.drivers.bipi_packer import pack
cap_a, cap_c = int(sys.argv[1]), int(sys.argv[2])
b = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(3))
pack(b, 0.05, h_over_dx_paper=2.0, progress=False, max_steps_2a=2, max_steps_2c=2)  # compile
load0 = os.getloadavg()
c, w = time.process_time(), time.perf_counter()
atoms, packer, start = pack(b, 0.05, h_over_dx_paper=2.0, progress=False, max_steps_2a=cap_a, max_steps_2c=cap_c)
c, w = time.process_time() - c, time.perf_counter() - w
print(json.dumps(dict(checkout=os.environ.get("PYTHONPATH"), cpu=c, wall=w, it_2a=packer.stage_iterations["2a"],
                      it_2c=packer.stage_iterations["2c"], gradc_final=packer.final_gradc_avg(), load_before=load0,
                      load_after=os.getloadavg())), flush=True)
"""


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", required=True, help="an older checkout of the repository")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--caps", nargs=2, type=int, default=[40, 80], metavar=("CAP_2A", "CAP_2C"))
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_bipi_sphere.json"))
    args = parser.parse_args(argv)
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    records = []
    print(f"load average {os.getloadavg()}", flush=True)
    for _ in range(args.rounds):
        for checkout in (args.baseline, str(ROOT)):
            out = subprocess.run([sys.executable, "-c", CHILD, *map(str, args.caps)], env=dict(env, PYTHONPATH=checkout),
                                 capture_output=True, text=True, check=True).stdout
            records.append(json.loads(out.strip().splitlines()[-1]))
            print(records[-1], flush=True)
    base = sorted(r["cpu"] for r in records if r["checkout"] == args.baseline)
    new = sorted(r["cpu"] for r in records if r["checkout"] == str(ROOT))
    summary = dict(records=records, median_cpu_baseline=base[len(base) // 2], median_cpu_current=new[len(new) // 2],
                   date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
    summary["cpu_ratio_baseline_over_current"] = summary["median_cpu_baseline"] / summary["median_cpu_current"]
    print(f"CPU baseline {summary['median_cpu_baseline']:.1f} s, current {summary['median_cpu_current']:.1f} s, "
          f"ratio {summary['cpu_ratio_baseline_over_current']:.2f}; load average {os.getloadavg()}")
    Path(args.out).write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
