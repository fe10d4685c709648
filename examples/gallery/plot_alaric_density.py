"""
Reach a target density with ALARIC
==================================

ALARIC (Vela Vela et al.) gives equal-mass particles the density of any target ρ*: an
isothermal SPH fluid in an external potential, with friction, viscosity and velocity stops,
comes to rest where ρ_a ∝ ρ*(x_a). Here the paper's Eq. 46 on the periodic interval [−1, 1)
with Δ = 0.1, from 101 equispaced particles.
"""
import matplotlib.pyplot as plt
import numpy as np

import ase_sphrelax as sr
from ase_sphrelax.drivers.alaric_dynamics import start_atoms
from ase_sphrelax.models.alaric import eq46

atoms, origin, _ = start_atoms(101, dim=1)                  # 1D: atoms.info["dim"] = 1
density, gradient = eq46(delta=0.1)                          # Eq. 46
out = sr.relax_density(atoms, density, 1, target_gradient=gradient, origin=origin, max_steps=2000, polish=False,
                       form="log")
relaxed = out["atoms"]
print(f"{len(relaxed)} particles, epsilon (Eq. 45) {out['epsilon']:.2e}, stopped: {out['stop_reason']}")

# %%
# The SPH density of the particles against the target (scaled to the same mass).
calc = out["calculator"]
x_p = relaxed.positions[:, 0] + origin[0]
rho_p = calc.results["density"] if "density" in calc.results else None
grid = np.linspace(-1, 1, 400)
target = density(grid[:, None])
order = np.argsort(x_p)
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(grid, target / target.mean(), "k-", lw=1, label="target ρ* (Eq. 46)")
if rho_p is not None:
    ax.plot(x_p[order], rho_p[order] / rho_p.mean(), ".", ms=4, label="SPH density of the particles")
ax.set_xlabel("x")
ax.set_ylabel("density / mean")
ax.legend()
fig.tight_layout()
plt.show()
