"""SPH-ParVI: CPU ms per step (median of 15) at M = 1e4 and 1e5 in a fresh 1-thread process (bench_sampling_speed's step)."""
import os, sys, json, time, statistics
import numpy as np
from ase_sphrelax.models.parvi import CountingTarget, ParVIModel
from ase_sphrelax.sampling import get_target
out = {}
for m in (10000, 100000):
    target = get_target("gaussian")
    model = ParVIModel(CountingTarget(target.log_density, target.score, 2), 2)
    x = target.sample(m, np.random.default_rng(0)); v = np.zeros_like(x)
    model.evaluate(x, v)
    rng = np.random.default_rng(1); ts = []
    for _ in range(15):
        x = x + 1e-4 * rng.standard_normal(x.shape)
        c0 = time.process_time(); model.evaluate(x, v); ts.append(time.process_time() - c0)
    out[m] = 1e3 * statistics.median(ts)
print(json.dumps(dict(cpu_ms=out, load=os.getloadavg()[0])))
