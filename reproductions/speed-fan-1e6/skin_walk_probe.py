"""Pairs per particle and one warm evaluation (list reused) of the bench's sphere at 1e6 for Verlet skins given as
fractions of h (the median of 8 evaluations after a displacement of 1e-9 h; the skin 0 list is rebuilt at each):

    NUMBA_NUM_THREADS=1 python reproductions/speed-fan-1e6/skin_walk_probe.py 3 0.1,0.04,0.0,0.1,0.04 \
        > reproductions/speed-fan-1e6/results/skin_walk_probe_3d.txt
"""
import sys, time
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2] / "benchmarks"))
import numpy as np
import bench_fan_1e6 as bf
from ase_sphrelax import FanCalculator
dim = int(sys.argv[1])
bf.warm_up(dim)
domain, dx, atoms = bf.scene(dim, 1e6)
h = bf.RATIO * dx
rng = np.random.default_rng(1)
for frac in [float(s) for s in sys.argv[2].split(",")]:
    calc = atoms.calc = FanCalculator(h=h, dx=dx, domain=domain, skin=frac * h)
    atoms.get_forces(); atoms.positions[:, :dim] += 1e-9 * h; atoms.get_forces()  # build
    ts = []
    for k in range(8):
        atoms.positions[:, :dim] += 1e-9 * h
        t = time.perf_counter(); calc.forces_view(atoms, moved=True); ts.append(time.perf_counter() - t)
    print(f"skin {frac}h pairs {calc.nlist.pair_j.shape[0]/len(atoms):.1f}/pt  eval median {1000*np.median(ts):.1f} ms builds {calc.nlist.builds}")
