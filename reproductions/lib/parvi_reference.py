"""The NUTS reference of the 32-D logistic posterior (4000 draws), shared by the SPH-ParVI entries.

Not committed (1 MB of random draws): :func:`logistic_reference` loads ``reproductions/lib/reference_logistic.npy``
and makes it when missing with ``benchmarks/bench_sampling.py``'s ``nuts_reference`` (blackjax NUTS, 4 chains with
keys 0-3, window adaptation, 2000 warm-up, thinned by 5; a few minutes), the draws the stored results used.
"""
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
PATH = Path(__file__).resolve().parent / "reference_logistic.npy"


def logistic_reference(path=PATH):
    """(4000, 32) NUTS draws of the logistic posterior: loaded from ``path``, made and saved there when missing."""
    path = Path(path)
    if not path.exists():
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import bench_sampling
        from ase_sphrelax.sampling import get_target

        np.save(path, bench_sampling.nuts_reference(get_target("logistic"), 4000))
    return np.load(path)
