"""
Relax a circle with Fan et al.
==============================

Fill Fan's Appendix A circle with particles on a Cartesian grid (with a small random shift),
then relax them with Fan's Eq. 2.4 on the total error E (Eq. 3.8). ``h`` is the kernel
**support** radius, here 2.6 dx. The particles are coloured by their volume 1/ΣW.
"""
import matplotlib.pyplot as plt
import numpy as np

import ase_sphrelax as sr

dx = 1 / 64
domain = sr.domains.Circle((0.5, 0.5), 0.2)
atoms = sr.build.fill(domain, dx, jitter=0.1, seed=0)          # 2D: z = 0
atoms.calc = sr.FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
energies = [atoms.get_potential_energy()]
relaxation = sr.FanRelaxation(atoms, c=0.01, logfile=None)      # Eq. 2.4
relaxation.attach(lambda: energies.append(atoms.get_potential_energy()), interval=10)
relaxation.run(fmax=0, steps=1000)
print(f"{len(atoms)} particles, E {energies[0]:.4e} -> {energies[-1]:.4e}")

quality = sr.analysis.Quality(h=2.6 * dx, dx=dx, domain=domain).compute(atoms)
summary = quality.summary()
print(f"interior mean |sum V W - 1| {summary['kernel_sum_error_mean']:.2e}, "
      f"mean h|sum V grad W| {summary['gradient_error_mean']:.2e}, {summary['n_outside']} outside")

# %%
# The relaxed particles coloured by their volume 1/ΣW (Fan Eq. 3.10), and the total error
# against the iterations.
fig, (left, right) = plt.subplots(1, 2, figsize=(9, 4))
points = left.scatter(*atoms.positions[:, :2].T, c=quality.volume_p / dx**2, s=6, cmap="viridis")
left.add_patch(plt.Circle((0.5, 0.5), 0.2, fill=False, color="k", lw=0.8))
left.set_aspect("equal")
left.set_title("relaxed particles")
fig.colorbar(points, ax=left, label="volume / dx²")
right.semilogy(np.arange(len(energies)) * 10, energies)
right.set_xlabel("Eq. 2.4 iteration")
right.set_ylabel("total error E (Eq. 3.8)")
fig.tight_layout()
plt.show()
