"""The default configuration is unchanged bit for bit: the same sample() calls under two checkouts.

(The "default" is the one of 2026-12-02, pinned as ``reproductions/lib/parvi_pinned.CLASSIC``.)

    for w in /work/main /work/wt-logit; do (cd $w && PYTHONPATH=$w OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \
        /work/main/.venv/bin/python /work/wt-logit/reproductions/parvi-logistic-goal/bit_identity.py \
        /tmp/bitid_$(basename $w).npz); done
    /work/main/.venv/bin/python reproductions/parvi-logistic-goal/bit_identity.py --compare \
        /tmp/bitid_main.npz /tmp/bitid_wt-logit.npz > reproductions/parvi-logistic-goal/results/bit_identity.txt
"""
import subprocess
import sys
import warnings

import numpy as np

if sys.argv[1] == "--compare":
    a, b = np.load(sys.argv[2]), np.load(sys.argv[3])
    for key in a.files:
        if key != "git":
            print(key, "identical" if np.array_equal(a[key], b[key]) else "DIFFERENT")
    print("revisions:", str(a["git"]), str(b["git"]))
    sys.exit()

warnings.simplefilter("ignore")
from ase_sphrelax import sample  # noqa: E402
from ase_sphrelax.sampling.targets import get_target  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)

out = {}
for name, kw, n, steps in (("banana", {}, 300, 100), ("gaussian10d", dict(neighbours="knn", whiten="covariance"), 100, 100)):
    t = get_target(name)
    out[f"{name}_{'default' if not kw else 'knn+whiten'}"] = sample(t.log_density, t.score, **classic(
        n=n, dim=t.dim, seed=1, steps=steps, **kw)).samples
out["git"] = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
np.savez(sys.argv[1], **out)
