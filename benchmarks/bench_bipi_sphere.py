"""CPU and wall time of the BIPI sphere case (reproductions/bipi-table/run.py ``sphere_3d``), this checkout against a baseline.

The sphere of radius 0.5 (``Sphere.to_mesh(3)``, 1280 triangles), dx = 0.05, h_B/dx = 2 (4032 particles),
packed with the case's settings, capped (default 40 iterations of Step 2a, 80 of 2c; ``--full``: the case's own
caps, 5000 and 1000, i.e. the whole case), in fresh processes alternating baseline and current checkout
(``--rounds`` rounds; in each round every thread count of ``--threads`` for both), after an untimed 2 + 2
iteration packing that compiles. Records process (CPU) time and wall time: on the shared 2-vCPU machine the
wall time follows the load, the CPU time much less. Every record carries the load average before and after,
the niceness, the thread count, the final ``|grad C|_avg`` and the boundary layer (mean and minimum distance
``d / dx`` of the particles closer than ``BOUNDARY_LAYER`` dx), so the results can be compared as well as the
times. ``--profile``: CPU time per part (the particle-triangle query, the triangle integrals ``_rows``, the
pair sums, the rest of a step) from wrappers around functions both checkouts have. ``--momentum M``: this
checkout packs with ``BIPIPacker(momentum=M, momentum_stages=...)`` (default Step 2c; not the paper's rule;
the baseline keeps the paper's). ``--step-rules``: Step 2c alone, from the saved end of the case's paper-rule
Step 2a + 2b, once per variant of the step (momentum, J), with ``|grad C|_avg`` per iteration. ``--lead``: the
whole case on this checkout only, four processes: the paper's rule and momentum 0.9 in Step 2c, each on 1 and 2
numba threads (CPU and wall time of each; about 4 minutes on a quiet machine). ``--pair-cost CALLS``: CPU ns per
(particle, triangle) pair of the boundary integrals, baseline and this checkout alternating.

    python benchmarks/bench_bipi_sphere.py --baseline /path/to/old/checkout [--rounds 2] [--caps 40 80]
        [--threads 1 2] [--full] [--profile] [--momentum M [--momentum-stages 2a 2c]] [--only-current] [--out FILE]
    python benchmarks/bench_bipi_sphere.py --lead [--out FILE]
    python benchmarks/bench_bipi_sphere.py --pair-cost 5 --baseline /path/to/old/checkout [--rounds 2]
    python benchmarks/bench_bipi_sphere.py --step-rules '{"momentum": 0.9}' '{"J": 2.0}' [--cap-2c 1000]

Writes benchmarks/results/bench_bipi_sphere.json (one record per process, medians per checkout and thread count).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import collections, json, os, sys, time, warnings
warnings.simplefilter("ignore")
import numpy as np
from ase_sphrelax.boundary import BoundaryTriangles
from ase_sphrelax.domains import Sphere
from ase_sphrelax.drivers import bipi_packer
from ase_sphrelax.drivers.bipi_packer import pack
cap_a, cap_c, profile, momentum = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3] == "1", float(sys.argv[4])
stages = tuple(sys.argv[5].split(","))
extra = dict(momentum=momentum, momentum_stages=stages) if momentum > 0 else {}  # the baseline has no momentum
b = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(3))
pack(b, 0.05, h_over_dx_paper=2.0, progress=False, max_steps_2a=2, max_steps_2c=2)  # compile
parts = collections.defaultdict(float)
if profile:
    from ase_sphrelax.boundary import gamma, query
    from ase_sphrelax.calculators import bipi

    def timed(owner, name, key):
        inner = getattr(owner, name)
        def wrapper(*args, **kwargs):
            c = time.process_time()
            try:
                return inner(*args, **kwargs)
            finally:
                parts[key] += time.process_time() - c
        setattr(owner, name, wrapper)

    timed(query.BoundaryQuery, "pairs", "query")
    timed(gamma, "run_chunks", "integrals (_rows)")
    timed(bipi, "kernel_sums", "pair sums")
    timed(bipi_packer.BIPIPacker, "step", "step (all)")
load0 = os.getloadavg()
c, w = time.process_time(), time.perf_counter()
atoms, packer, start = pack(b, 0.05, h_over_dx_paper=2.0, progress=False, max_steps_2a=cap_a, max_steps_2c=cap_c,
                             **extra)
c, w = time.process_time() - c, time.perf_counter() - w
load1 = os.getloadavg()
from ase_sphrelax.analysis.quality import BOUNDARY_LAYER
d = -b.domain.phi(atoms.positions) / 0.05
layer = d < BOUNDARY_LAYER
out = dict(checkout=os.environ.get("PYTHONPATH"), threads=int(os.environ["NUMBA_NUM_THREADS"]), nice=os.nice(0), momentum=momentum,
           momentum_stages=stages if momentum > 0 else [],
           cpu=c, wall=w, it_2a=packer.stage_iterations["2a"], it_2c=packer.stage_iterations["2c"],
           stopped_by=packer.stopped_by, n_frozen=int(len(packer.frozen)), gradc_final=packer.final_gradc_avg(),
           layer_mean=float(d[layer].mean()), layer_min=float(d.min()), n_layer=int(layer.sum()),
           n_outside=int(np.sum(d <= 0)), load_before=load0, load_after=load1)
if profile:
    n = packer.stage_iterations["2a"] + packer.stage_iterations["2c"]
    parts["rest of a step"] = parts["step (all)"] - parts["query"] - parts["integrals (_rows)"] - parts["pair sums"]
    out["cpu_ms_per_iteration"] = {k: 1e3 * v / n for k, v in parts.items()}
print(json.dumps(out), flush=True)
"""

STEP_RULE = """
import json, os, sys, time, warnings
warnings.simplefilter("ignore")
import numpy as np
from ase.constraints import FixAtoms
from ase_sphrelax.analysis.bipi import pack_summary
from ase_sphrelax.boundary import BoundaryTriangles
from ase_sphrelax.calculators.bipi import BIPICalculator
from ase_sphrelax.domains import Sphere
from ase_sphrelax.drivers import bipi_packer as BP
from ase_sphrelax.models.bipi import support_from_paper
variant, cap, start = json.loads(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
b = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(3))
dx = 0.05
h = support_from_paper(2.0, dx)
if not os.path.exists(start):  # the case's Step 2a and 2b with the paper's rule, once
    atoms, packer, s0 = BP.pack(b, dx, h_over_dx_paper=2.0, progress=False, stages=("2a", "2b"))
    np.savez(start, r=atoms.positions, x0=s0.positions, frozen=packer.frozen, it2a=packer.stage_iterations["2a"])
d = np.load(start)
atoms = BP.initial_fill(b, dx)
atoms.positions = d["r"]
atoms.set_constraint(FixAtoms(indices=d["frozen"]))
calc = BIPICalculator(h=h, dx=dx, boundary=b, J=variant.get("J", 0.5))
packer = BP.BIPIPacker(atoms, calc, stages=("2c",), max_steps_2c=cap, momentum=variant.get("momentum", 0.0))
packer.x0 = d["x0"]
c = time.process_time()
packer.run()
out = dict(variant=variant, cap=cap, cpu=time.process_time() - c, stopped=packer.stopped_by,
           it=packer.stage_iterations["2c"], final=packer.final_gradc_avg(), load=os.getloadavg(),
           gradc=[r["gradc_avg"] for r in packer.history])
sm = pack_summary(atoms, packer)
out.update(layer_mean=sm["boundary_layer_mean"], layer_min=sm["boundary_layer_min"], n_layer=sm["n_boundary_layer"],
           n_outside=sm["n_outside"])
print(json.dumps(out), flush=True)
"""


PAIR_COST = """
import json, os, sys, time, warnings
warnings.simplefilter("ignore")
import numpy as np
from ase_sphrelax.boundary import BoundaryIntegrals, BoundaryTriangles
from ase_sphrelax.domains import Sphere
from ase_sphrelax.drivers.bipi_packer import initial_fill
from ase_sphrelax.neighbors import NeighborList
b = BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(3))
dx, h = 0.05, 0.2
r = initial_fill(b, dx).positions + np.random.default_rng(0).normal(scale=0.003, size=(4032, 3))
nlist = NeighborList(h, skin=0.1 * h)
nlist.update(r, np.zeros((3, 3)), [False] * 3, store=True)
times, query = [], []
for call in range(int(sys.argv[1]) + 1):
    integrals = BoundaryIntegrals(b, h)  # fresh: no particle reused from a previous call
    integrals.query.pairs(nlist, r, h)  # builds the candidates
    c = time.process_time()
    pairs = integrals.query.pairs(nlist, r, h)  # as in compute: from the candidates
    q = time.process_time() - c
    c = time.process_time()
    out = integrals.compute(nlist, r, band=0.025)
    total = time.process_time() - c
    if call:  # the first call compiles
        times.append(total)
        query.append(q)
m = pairs.n_pairs
times, query = np.array(times), np.array(query)
print(json.dumps(dict(checkout=os.environ.get("PYTHONPATH"), threads=int(os.environ["NUMBA_NUM_THREADS"]), n_pairs=int(m),
                      ns_per_pair=float(np.median(times - query)) * 1e9 / m, compute_ms=float(np.median(times)) * 1e3,
                      query_ms=float(np.median(query)) * 1e3, gamma_sum=float(out.gamma_p.sum()),
                      load=os.getloadavg())), flush=True)
"""


def pair_cost(checkouts, rounds, calls, out_path):
    """CPU ns per (particle, triangle) pair of ``BoundaryIntegrals.compute`` minus its query (timed alone, from the
    kept candidates as in compute), on the case's 4032
    Step-1 particles jittered by N(0, 0.003) (fresh instance per call, so no particle is reused), band 0.025,
    one thread, median of ``calls`` calls per process; the checkouts alternate in fresh processes."""
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    records = []
    print(f"load average {os.getloadavg()}", flush=True)
    for _ in range(rounds):
        for checkout in checkouts:
            out = subprocess.run([sys.executable, "-c", PAIR_COST, str(calls)], env=dict(env, PYTHONPATH=checkout),
                                 cwd=checkout, capture_output=True, text=True, check=True).stdout
            records.append(json.loads(out.strip().splitlines()[-1]))
            print(records[-1], flush=True)
    medians = {c: median([r["ns_per_pair"] for r in records if r["checkout"] == c]) for c in checkouts}
    print(f"load average {os.getloadavg()}; ns per pair (medians): {medians}")
    Path(out_path).write_text(json.dumps(dict(records=records, medians_ns_per_pair=medians,
                                              date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                              command="python benchmarks/bench_bipi_sphere.py " + " ".join(sys.argv[1:])),
                                         indent=1))


def step_rules(variants, cap, out_path):
    """Step 2c alone from the saved start of the case's paper-rule Step 2a + 2b, once per variant
    (``{"momentum": beta}`` or ``{"J": J}``), this checkout, one thread: |grad C|_avg per iteration."""
    # the saved start is a cache of this checkout's Step 2a + 2b (not a result): outside the repository
    start = str(Path(tempfile.gettempdir()) / f"bench_bipi_sphere_start2c_{zlib.crc32(str(ROOT).encode())}.npz")
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    records = []
    for variant in variants:
        out = subprocess.run([sys.executable, "-c", STEP_RULE, variant, str(cap), start], env=env, cwd=str(ROOT),
                             capture_output=True, text=True, check=True).stdout
        records.append(json.loads(out.strip().splitlines()[-1]))
        print({k: v for k, v in records[-1].items() if k != "gradc"}, flush=True)
    Path(out_path).write_text(json.dumps(dict(records=records, date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                              command="python benchmarks/bench_bipi_sphere.py --step-rules "
                                              + " ".join(repr(v) for v in variants) + f" --cap-2c {cap}"), indent=1))


def median(values):
    values = sorted(values)
    return values[len(values) // 2] if len(values) % 2 else 0.5 * (values[len(values) // 2 - 1] + values[len(values) // 2])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="an older checkout of the repository (needed unless --only-current)")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--caps", nargs=2, type=int, default=[40, 80], metavar=("CAP_2A", "CAP_2C"))
    parser.add_argument("--full", action="store_true", help="the case's own caps (5000, 1000): the whole case")
    parser.add_argument("--threads", nargs="+", type=int, default=[1], help="numba thread counts, each for both")
    parser.add_argument("--profile", action="store_true", help="CPU time per part of an iteration")
    parser.add_argument("--momentum", type=float, default=0.0,
                        help="BIPIPacker(momentum=...) for this checkout (0: the paper's rule; the baseline always runs 0)")
    parser.add_argument("--momentum-stages", nargs="+", default=["2c"], choices=["2a", "2c"])
    parser.add_argument("--lead", action="store_true",
                        help="the whole case on this checkout: 1-thread CPU and 2-thread wall for the paper's rule and for "
                        "momentum 0.9 in Step 2c (4 processes; with --baseline also the baseline's paper rule)")
    parser.add_argument("--only-current", action="store_true", help="time this checkout only (no baseline runs)")
    parser.add_argument("--step-rules", nargs="+", metavar="JSON",
                        help='instead: Step 2c alone from the saved paper-rule start, per variant, e.g. \'{"momentum": 0.9}\'')
    parser.add_argument("--cap-2c", type=int, default=1000, help="with --step-rules: the 2c cap")
    parser.add_argument("--pair-cost", type=int, metavar="CALLS", default=0,
                        help="instead: CPU ns per (particle, triangle) pair of the integrals, median of CALLS calls "
                        "per process, baseline and this checkout alternating (--rounds rounds)")
    parser.add_argument("--out", default=None, help="result file (default results/bench_bipi_sphere.json, "
                        "results/bench_bipi_sphere_step_rules.json with --step-rules)")
    args = parser.parse_args(argv)
    results = ROOT / "benchmarks" / "results"
    if args.step_rules:
        step_rules(args.step_rules, args.cap_2c, args.out or str(results / "bench_bipi_sphere_step_rules.json"))
        return
    if args.pair_cost:
        checkouts = [str(ROOT)] if args.only_current else [args.baseline, str(ROOT)]
        pair_cost(checkouts, args.rounds, args.pair_cost, args.out or str(results / "bench_bipi_sphere_pair_cost.json"))
        return
    args.out = args.out or str(results / "bench_bipi_sphere.json")
    if args.baseline is None and not args.only_current and not args.lead:
        parser.error("--baseline is needed unless --only-current or --step-rules")
    if args.lead:  # the whole case, this checkout, 1 and 2 threads, the paper's rule and momentum 0.9 in Step 2c
        args.full, args.threads, args.rounds, args.momentum_stages = True, [1, 2], 1, ["2c"]
        args.only_current = args.only_current or args.baseline is None
    caps = [5000, 1000] if args.full else args.caps
    checkouts = [str(ROOT)] if args.only_current else [args.baseline, str(ROOT)]
    momenta = [0.0, 0.9] if args.lead else [args.momentum]
    records = []
    print(f"load average {os.getloadavg()}, nice {os.nice(0)}", flush=True)
    # each child runs in its checkout: ``python -c`` puts the working directory first on sys.path, ahead of PYTHONPATH
    for _ in range(args.rounds):
        for momentum in momenta:
            for threads in args.threads:
                for checkout in checkouts:
                    if momentum > 0 and checkout != str(ROOT):
                        continue  # the baseline runs the paper's rule only
                    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS=str(threads), PYTHONPATH=checkout)
                    m = momentum if checkout == str(ROOT) else 0.0  # the baseline may have no momentum
                    out = subprocess.run([sys.executable, "-c", CHILD, *map(str, caps), "1" if args.profile else "0",
                                          str(m), ",".join(args.momentum_stages)],
                                         env=env, cwd=checkout, capture_output=True, text=True, check=True).stdout
                    records.append(json.loads(out.strip().splitlines()[-1]))
                    print(records[-1], flush=True)
    summary = dict(records=records, caps=caps, date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                   command="python benchmarks/bench_bipi_sphere.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                   medians={})
    for momentum in momenta:
        tag = f" momentum {momentum}" if momentum > 0 else ""
        for threads in args.threads:
            for checkout in checkouts:
                if momentum > 0 and checkout != str(ROOT):
                    continue
                mine = [r for r in records if r["checkout"] == checkout and r["threads"] == threads
                        and r["momentum"] == (momentum if checkout == str(ROOT) else 0.0)]
                summary["medians"][f"{checkout} {threads}t{tag}"] = dict(
                    cpu=median([r["cpu"] for r in mine]), wall=median([r["wall"] for r in mine]),
                    iterations=f"{mine[0]['it_2a']} + {mine[0]['it_2c']}", gradc_final=mine[0]["gradc_final"],
                    layer=f"{mine[0]['layer_mean']:.5f} / {mine[0]['layer_min']:.5f} ({mine[0]['n_layer']})")
            if not args.only_current and momentum == 0.0:
                base, new = (summary["medians"][f"{c} {threads}t"] for c in checkouts)
                summary["medians"][f"ratio {threads}t"] = dict(cpu=base["cpu"] / new["cpu"], wall=base["wall"] / new["wall"])
    for key, value in summary["medians"].items():
        extra = "".join(f", {k} {value[k]}" for k in ("iterations", "gradc_final", "layer") if k in value)
        unit = "" if key.startswith("ratio") else " s"
        print(f"{key}: CPU {value['cpu']:.2f}{unit}, wall {value['wall']:.2f}{unit}{extra}")
    print(f"load average {os.getloadavg()}")
    Path(args.out).write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
