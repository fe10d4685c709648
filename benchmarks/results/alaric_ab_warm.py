"""One warm ALARIC evaluation (bench_alaric.alaric_case, 1e5, dim = argv[1]) in a fresh process: CPU ms (median of 9),
the skin and the pair count; run alternately on two checkouts via PYTHONPATH (1 thread)."""
import sys, time, statistics, os, json
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))  # benchmarks/
import numba
from bench_alaric import alaric_case, clocked
dim = int(sys.argv[1])
move, calc = alaric_case(100000, dim)
cpu = [clocked(move)[1] for _ in range(9)]
print(json.dumps(dict(dim=dim, cpu_ms=1e3 * statistics.median(cpu), skin=calc._skin, pairs=int(calc.nlist._pair_count), load=os.getloadavg()[0])))
