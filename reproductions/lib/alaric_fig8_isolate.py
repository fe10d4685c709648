"""Fig. 8 in 3D (Eq. 46, Delta = 0.01, unit ball, mirror ghosts): ALARIC runs that track pairing along the way,
for isolating the ingredient behind the edge-layer pairing seen at N = 26 411 (issue 20 item 2).

Fresh run, the same recipe as ``sphrelax density --profile eq46 --delta 0.01 --dim 3`` (the CLI's start, log
form, ``boundary auto`` = mirror, ``stage_steps = max_steps // (split + 1)``), through the public API::

    python reproductions/lib/alaric_fig8_isolate.py fresh --n 2075 --split 0 --max-steps 6000 --max-wall 600 --out DIR

Continuation from a stored state (positions and momenta of a ``relaxed.extxyz``; a new ALARICDynamics: velocity
stop interval measured again, viscosity switch restarted at alpha0, the Eq. 44 mass reset at its first evaluation)::

    python reproductions/lib/alaric_fig8_isolate.py continue reproductions/alaric-fig8/results/3d_n26411 \
        --max-wall 1200 --out DIR

Every ``--every`` steps (and at the end) it records epsilon and the pairing checks of
:func:`alaric_fig8_nn.layer_checks` (smallest NN distance / mean, in the edge layer, ``1 - r`` below two mean NN
distances, and in the interior), the potential at unit mass and the kinetic energy in ``DIR/nn_trace.json``;
writes ``DIR/relaxed.extxyz`` (target frame, momenta, h) and
``DIR/summary.json`` (the last checks, steps, stop reason, wall, load average at start and end).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_fig8_nn import layer_checks  # noqa: E402


def smooth_wall_calculator(length_factor, **kwargs):
    """An ALARICCalculator with the package's quadratic domain wall (``wall_form="quadratic"``), ``U_wall = m c_s^2
    phi_+^2 / (2 L^2)`` with ``L = length_factor (V / N)^(1/3)`` (N the current count), in place of the default
    linear wall ``m c_s^2 phi_+ / L0`` (``L0 = 0.1 (V / N)^(1/3)``), whose force jumps from 0 to ``m c_s^2 / L0``
    when a particle crosses the boundary. ``length_factor = 0.5`` is the package's default L; other factors only
    change :meth:`quadratic_wall_length` (``tests/test_alaric_wall_form.py`` checks that the package form gives the
    energy and forces of this experiment's first, stand-alone version)."""
    from ase_sphrelax.calculators.alaric import QUADRATIC_WALL_FACTOR, ALARICCalculator

    if length_factor == QUADRATIC_WALL_FACTOR:
        return ALARICCalculator(wall_form="quadratic", **kwargs)

    class ScaledQuadraticWallALARIC(ALARICCalculator):
        def quadratic_wall_length(self, n, d):
            return length_factor * (float(self.parameters.domain.volume) / n) ** (1.0 / d)

    return ScaledQuadraticWallALARIC(wall_form="quadratic", **kwargs)


def build(args):
    from ase.io import read

    from ase_sphrelax.calculators.alaric import ALARICCalculator
    from ase_sphrelax.domains import Sphere
    from ase_sphrelax.drivers.alaric_dynamics import start_atoms
    from ase_sphrelax.models.alaric import eq46, resolve_boundary
    from ase_sphrelax.splitting import SPLIT_COUNT

    density, gradient = eq46(0.01)
    if args.mode == "fresh":
        p = SPLIT_COUNT[3]
        n0 = args.n // p**args.split
        if n0 * p**args.split != args.n:
            raise SystemExit(f"--n {args.n} is not divisible by 5^{args.split}")
        atoms, origin, domain = start_atoms(n0, 3, seed=args.seed)
    else:
        atoms = read(Path(args.folder) / "relaxed.extxyz")
        atoms.set_cell(np.zeros((3, 3)))
        atoms.pbc = False
        origin, domain = np.zeros(3), Sphere((0.0, 0.0, 0.0), 1.0)
        if not args.keep_velocities:
            atoms.set_momenta(np.zeros((len(atoms), 3)))
    boundary = resolve_boundary(args.boundary, domain)
    kwargs = dict(target_density=density, target_gradient=gradient, dim=3, form="log", domain=domain, origin=origin,
                  boundary=boundary, eta=args.eta)
    if args.smooth_wall is not None:
        calc = smooth_wall_calculator(args.smooth_wall, **kwargs)
    else:
        if args.wall_length_factor is not None:  # the linear wall's length, times the default 0.1 (V / N)^(1/3)
            kwargs["wall_length"] = args.wall_length_factor * 0.1 * (float(domain.volume) / len(atoms)) ** (1 / 3)
        calc = ALARICCalculator(**kwargs)
    atoms.calc = calc
    return atoms, calc, boundary


def parser():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("fresh", "continue"))
    ap.add_argument("folder", nargs="?", default=None, help="continue: a folder with relaxed.extxyz")
    ap.add_argument("--n", type=int, default=2075)
    ap.add_argument("--split", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--boundary", choices=("auto", "mirror", "wall"), default="auto")
    ap.add_argument("--keep-velocities", action="store_true", help="continue: start from the stored momenta")
    ap.add_argument("--eta", type=float, default=None, help="n H^3 = eta^3 (default: the kernel's)")
    ap.add_argument("--wall-length-factor", type=float, default=None,
                    help="the linear wall's length times this (default 1: 0.1 (V / N)^(1/3))")
    ap.add_argument("--smooth-wall", type=float, default=None, metavar="L",
                    help="a quadratic wall of length L (V / N)^(1/3) in place of the linear one "
                         "(smooth_wall_calculator)")
    ap.add_argument("--cfl", type=float, default=0.25, help="CFL factor of the time step (default 0.25)")
    ap.add_argument("--no-viscosity", action="store_true", help="switch the artificial viscosity off")
    ap.add_argument("--no-velocity-stop", action="store_true", help="switch the velocity stops off")
    ap.add_argument("--max-steps", type=int, default=20000)
    ap.add_argument("--max-wall", type=float, default=600.0)
    ap.add_argument("--every", type=int, default=100, help="pairing check every this many steps")
    ap.add_argument("--out", required=True)
    return ap


def main():
    args = parser().parse_args()
    if args.mode == "continue" and args.folder is None:
        raise SystemExit("continue needs a folder")
    from ase.io import write

    from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    atoms, calc, boundary = build(args)
    splits = args.split if args.mode == "fresh" else 0
    dyn = ALARICDynamics(atoms, splits=splits, seed=args.seed, max_wall=args.max_wall, cfl=args.cfl,
                         viscosity=not args.no_viscosity, velocity_stop=not args.no_velocity_stop,
                         stage_steps=args.max_steps // (splits + 1) if splits else None)
    nn_trace = []

    def check():
        res = calc.results
        x = calc.points(atoms.positions, atoms)
        # U / (m c_s^2) - N ln m = sum_a ln(n_a / rho*_a): the potential without the Eq. 44 mass resets' jumps
        unit_mass_u = (float(res["energy"]) / (float(calc.mass) * calc.parameters.cs2)
                       - len(atoms) * float(np.log(calc.mass)))
        row = dict(step=dyn.nsteps, wall=time.perf_counter() - t0, n=len(atoms), stage=dyn.stage,
                   epsilon=float(res["epsilon"]), energy_unit_mass=unit_mass_u,
                   ek_unit_mass=0.5 * float((atoms.get_velocities() ** 2).sum()) / calc.parameters.cs2,
                   **layer_checks(x))
        nn_trace.append(row)
        (out / "nn_trace.json").write_text(json.dumps(nn_trace, indent=1))
        print(json.dumps(row), flush=True)

    check()
    dyn.attach(check, interval=args.every)
    dyn.run(args.max_steps)
    if nn_trace[-1]["step"] != dyn.nsteps:
        check()
    shown = atoms.copy()
    shown.positions[:, :3] = calc.points(atoms.positions, atoms)
    shown.arrays.pop("h", None)
    shown.new_array("h", np.asarray(calc.results["smoothing_lengths"], dtype=float))
    write(out / "relaxed.extxyz", shown, format="extxyz")
    (out / "trace.json").write_text(json.dumps(dyn.trace, indent=1))
    summary = dict(mode=args.mode, source=args.folder, n=len(atoms), split=splits, seed=args.seed, boundary=boundary,
                   keep_velocities=bool(args.keep_velocities), eta=calc.eta, cfl=args.cfl,
                   wall_length_factor=args.wall_length_factor, smooth_wall=args.smooth_wall,
                   viscosity=not args.no_viscosity, velocity_stop=not args.no_velocity_stop, steps=dyn.nsteps,
                   stop_reason=dyn.stop_reason, wall_time_s=time.perf_counter() - t0, load_average_start=load0,
                   load_average_end=os.getloadavg(), command=" ".join(sys.argv),
                   **{k: v for k, v in nn_trace[-1].items() if k not in ("step", "wall", "n")})
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
