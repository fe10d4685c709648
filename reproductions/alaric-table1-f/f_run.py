"""Table 1's F run (friction only, log potential, Eq. 46 Delta = 0, 300 equispaced particles, cap 10000 steps)
with whatever ase_sphrelax PYTHONPATH points at: steps, stop, eps, simulated time, dt statistics (JSON on stdout).

    git archive REV ase_sphrelax | tar -x -C /tmp/REV
    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=/tmp/REV .venv/bin/python \
        reproductions/alaric-table1-f/f_run.py [STEPS] > reproductions/alaric-table1-f/results/f_NAME.json
"""
import json, sys, time
import numpy as np
from ase_sphrelax import ALARICCalculator
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics, start_atoms
from ase_sphrelax.models import alaric as model
import ase_sphrelax

atoms, origin, _ = start_atoms(300, 1)
density, gradient = model.eq46(0.0)
atoms.calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=1, origin=origin, form="log")
dyn = ALARICDynamics(atoms, velocity_stop=False, friction=2.0, viscosity=False)
dts = []
dyn.attach(lambda: dts.append(dyn.dt), interval=1)
c0 = time.process_time()
dyn.run(int(sys.argv[1]) if len(sys.argv) > 1 else 10000)
dts = np.array(dts)
print(json.dumps(dict(package=str(ase_sphrelax.__file__), steps=dyn.nsteps, stop=dyn.stop_reason,
                      eps=dyn.trace[-1]["epsilon"], time=float(dts.sum()), dt_min=float(dts.min()),
                      dt_median=float(np.median(dts)), dt_last=float(dts[-1]), cpu=time.process_time() - c0,
                      trace=[(e["step"], e["epsilon"]) for e in dyn.trace][::max(1, len(dyn.trace) // 15)])))
