"""Forces against central differences of the energy on a stored Fig. 8 state (3D, Eq. 46, Delta = 0.01, mirror
ghosts): at the particle with the smallest NN distance, a first-layer particle (r > 0.99) and an interior one (r < 0.5),
each axis, steps 1e-5 and 1e-6. Prints one JSON line per (particle, axis).

    python examples/alaric_fig8_fd_check.py examples/results/alaric/fig8_mirror/3d_n26411 [--smooth-wall L]

With ``--smooth-wall L`` the calculator is ``alaric_fig8_isolate.smooth_wall_calculator(L)``, and the particle
farthest out (r > 1 when any is outside the ball) replaces the interior one.
"""
import numpy as np, sys, json, time
from ase.io import read
from scipy.spatial import cKDTree
from ase_sphrelax.calculators.alaric import ALARICCalculator
from ase_sphrelax.domains import Sphere
from ase_sphrelax.models.alaric import eq46
folder = sys.argv[1]
smooth = float(sys.argv[3]) if len(sys.argv) > 3 and sys.argv[2] == "--smooth-wall" else None
a = read(folder + "/relaxed.extxyz"); a.set_cell(np.zeros((3, 3))); a.pbc = False
a.set_momenta(np.zeros((len(a), 3)))
x = a.positions; d, i = cKDTree(x).query(x, k=2); nn = d[:, 1]; r = np.linalg.norm(x, axis=1)
paired = np.nonzero(nn < 0.5 * nn.mean())[0]
first = np.nonzero(r > 0.99)[0]
inner = np.nonzero(r < 0.5)[0]
picks = [int(np.argmin(nn)), int(first[0]), int(inner[0]) if smooth is None else int(np.argmax(r))]
dens, grad = eq46(0.01)
kwargs = dict(target_density=dens, target_gradient=grad, dim=3, form="log",
                        domain=Sphere((0, 0, 0), 1.0), origin=np.zeros(3), boundary="mirror")
if smooth is None:
    calc = ALARICCalculator(**kwargs)
else:
    sys.path.insert(0, __import__("os").path.dirname(__import__("os").path.abspath(__file__)))
    from alaric_fig8_isolate import smooth_wall_calculator
    calc = smooth_wall_calculator(smooth, **kwargs)
a.calc = calc
f = a.get_forces().copy()
out = []
for p in picks:
    for c in range(3):
        row = {}
        for step in (1e-5, 1e-6):
            e = []
            for s in (1, -1):
                b = a.positions.copy(); b[p, c] += s * step; a.set_positions(b); e.append(a.get_potential_energy())
                b[p, c] -= s * step; a.set_positions(b)
            row[step] = -(e[0] - e[1]) / (2 * step)
        out.append(dict(particle=p, r=float(r[p]), nn_over_mean=float(nn[p] / nn.mean()), axis=c, force=float(f[p, c]),
                        fd_1e5=row[1e-5], fd_1e6=row[1e-6]))
        print(json.dumps(out[-1]), flush=True)
