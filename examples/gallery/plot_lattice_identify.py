"""
Identify a lattice
==================

Fan et al. (Sec. 5) predict which lattice relaxed particles form from the ratio h/dx alone:
the pattern whose characteristic volume v_c = 1/ΣW is largest. Here we predict it, relax a
small periodic cell in positions and shape at constant area, and name the result with spglib.
"""
import matplotlib.pyplot as plt
import numpy as np

import ase_sphrelax as sr

for h_over_dx in (2.0, 2.6):
    predicted = sr.analysis.predict_pattern(h_over_dx)
    atoms = sr.analysis.relax_lattice(h_over_dx, n_atoms=16, seed=0, n_starts=2)
    found = sr.analysis.classify_lattice(atoms)
    print(f"h/dx = {h_over_dx}: predicted {predicted}, relaxed and identified: {found}")

# %%
# v_c of each pattern family against h/dx (Fan Table 2), the largest wins.
ratios = np.arange(1.5, 3.51, 0.1)
fig, ax = plt.subplots(figsize=(6, 3.5))
for pattern in ("hexagonal", "square", "rectangular", "parallelogram"):
    ax.plot(ratios, [sr.analysis.characteristic_volume(pattern, r)[0] for r in ratios], label=pattern)
ax.set_xlabel("h / dx")
ax.set_ylabel("characteristic volume v_c")
ax.legend()
fig.tight_layout()
plt.show()
