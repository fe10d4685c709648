"""
Export to LAMMPS and run the fluid at rest
==========================================

Why relax: a periodic box of SPH fluid with zero velocity should stay at rest, but an irregular
particle set makes spurious currents. We relax a jittered box with Fan's total error, export
both sets as LAMMPS ``atom_style sph`` data files, and run weakly compressible SPH in LAMMPS
(``sph/rhosum`` + ``sph/taitwater``) from each. LAMMPS' ``h`` is the kernel support, as ours.
"""
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import ase_sphrelax as sr
import lammps_io

dx, ratio = 1.0, 2.6
start = sr.periodic_box((20, 20), dx=dx, dim=2, lattice="square", jitter=0.25, seed=1)
relaxed = start.copy()
relaxed.calc = sr.FanCalculator(h=ratio * dx, dx=dx)
sr.make_optimizer("lbfgs", relaxed).run(fmax=0, steps=300)
lammps_io.write_data(relaxed, Path(tempfile.mkdtemp()) / "relaxed.data", atom_style="sph")  # what LAMMPS reads

runs = {name: lammps_io.sph_at_rest(atoms, ratio * dx, dx, steps=200, sample_every=10)
        for name, atoms in (("jittered start", start), ("relaxed (Fan)", relaxed))}
for name, run in runs.items():
    print(f"{name:>15}: kinetic energy after 200 steps {run['ke']:.3e}")

# %%
# Spurious kinetic energy against time in LAMMPS.
fig, ax = plt.subplots(figsize=(6, 3.5))
for name, run in runs.items():
    history = np.asarray(run["ke_history"])
    ax.semilogy(history[:, 0], history[:, 1], label=name)
ax.set_xlabel("step")
ax.set_ylabel("kinetic energy")
ax.legend()
fig.tight_layout()
plt.show()
