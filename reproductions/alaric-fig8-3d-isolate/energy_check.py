"""Is ALARIC's dynamics dissipative on a stored Fig. 8 state? Per step, the potential at unit mass
``U / (m c_s^2) - N ln m`` (the Eq. 44 mass resets do not move it) plus the kinetic energy ``sum v^2 / (2 c_s^2)``:
friction, viscosity and velocity stops only remove energy, so every increase is injected by the time integration.

    python reproductions/alaric-fig8-3d-isolate/energy_check.py continue FOLDER --max-steps 300 [options] --out FILE.json

Takes the options of ``reproductions/lib/alaric_fig8_isolate.py`` (``--cfl``, ``--no-viscosity``, ``--wall-length-factor``,
``--smooth-wall``, ...); ``--out`` is the JSON file written: the totals and the per-step rows.
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_fig8_isolate import build, parser  # noqa: E402


def main():
    args = parser().parse_args()
    from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics

    load0 = os.getloadavg()
    atoms, calc, boundary = build(args)
    dyn = ALARICDynamics(atoms, cfl=args.cfl, viscosity=not args.no_viscosity,
                         velocity_stop=not args.no_velocity_stop)
    rows = []

    def observe():
        v = atoms.get_velocities()
        r = np.linalg.norm(calc.points(atoms.positions, atoms), axis=1)
        pot = float(calc.results["energy"]) / (calc.mass * calc.parameters.cs2) - len(atoms) * float(np.log(calc.mass))
        ek = 0.5 * float((v * v).sum()) / calc.parameters.cs2
        rows.append(dict(step=dyn.nsteps, dt=float(dyn.dt), potential=pot, kinetic=ek, total=pot + ek,
                         outside=int(np.count_nonzero(r > 1.0)),
                         v_max=float(np.sqrt((v * v).sum(axis=1).max() / calc.parameters.cs2))))

    dyn.attach(observe, interval=1)
    dyn.run(args.max_steps)
    total = np.array([r["total"] for r in rows])
    inc = np.diff(total)
    time_span = float(sum(r["dt"] for r in rows[1:]))
    summary = dict(source=args.folder, n=len(atoms), cfl=args.cfl, viscosity=not args.no_viscosity,
                   velocity_stop=not args.no_velocity_stop, wall_length_factor=args.wall_length_factor,
                   smooth_wall=args.smooth_wall, steps=len(rows), time=time_span,
                   total_start=float(total[0]), total_end=float(total[-1]), steps_increasing=int((inc > 0).sum()),
                   sum_of_increases=float(inc[inc > 0].sum()), increase_per_time=float(inc[inc > 0].sum() / time_span),
                   largest_increase=float(inc.max()), v_max=max(r["v_max"] for r in rows),
                   load_average_start=load0, load_average_end=os.getloadavg(), command=" ".join(sys.argv))
    Path(args.out).write_text(json.dumps(dict(summary=summary, rows=rows), indent=1))
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
