"""Fluid at rest in LAMMPS SPH: spurious kinetic energy from an unrelaxed and a relaxed start.

A periodic 2D box of particles at the cell centres with a random shift
(Fan Sec. 3.1, jitter 0.25 dx) is relaxed with Fan's total error in LAMMPS
(``lammps_io.run``, min_style fire), both sets are written as atom_style sph
and run as weakly compressible SPH (``sph/rhosum`` + ``sph/taitwater``) with
zero initial velocity.  The relaxed set should stay much closer to rest.

    python reproductions/fan-sph-at-rest/run.py [--n 40] [--relax-steps 3000] [--steps 400] \
        [--out reproductions/fan-sph-at-rest/results]

Writes <out>/at_rest.json: the settings, the relaxation and, per start, the
kinetic energy after the run, its maximum, max |v| / c0 and std(rho)/rho, and
ke_ratio = KE(unrelaxed) / KE(relaxed).
"""
import argparse
import json
import time
from pathlib import Path

from ase_sphrelax.build import periodic_box

import lammps_io


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40, help="particles per side (default 40)")
    parser.add_argument("--ratio", type=float, default=2.6, help="h / dx for relaxation and SPH (default 2.6)")
    parser.add_argument("--jitter", type=float, default=0.25, help="random shift / dx of the start (default 0.25)")
    parser.add_argument("--relax-steps", type=int, default=3000, help="FIRE iterations in LAMMPS (default 3000)")
    parser.add_argument("--steps", type=int, default=400, help="SPH time steps (default 400)")
    parser.add_argument("--c0", type=float, default=10.0, help="sound speed (default 10)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default="reproductions/fan-sph-at-rest/results",
                        help="folder for at_rest.json (default reproductions/fan-sph-at-rest/results)")
    args = parser.parse_args(argv)
    dx = 1.0
    h = args.ratio * dx
    start = periodic_box((args.n, args.n), dx=dx, dim=2, lattice="square", jitter=args.jitter, seed=args.seed)
    t0 = time.perf_counter()
    relaxed = lammps_io.run(start, h, dx, steps=args.relax_steps, style="table")
    info = relaxed.info["lammps"]
    print(f"relaxation: N={len(start)} h/dx={args.ratio} iterations={info['iterations']} "
          f"E={info['energy']:.6g} fnorm={info['fnorm']:.3g} wall={time.perf_counter() - t0:.2f} s")
    print(f"SPH at rest: sph/rhosum + sph/taitwater, rho0=1, c0={args.c0}, alpha=0.1, "
          f"dt=0.1 h/c0, {args.steps} steps")
    print(f"{'start':>10} {'KE final':>12} {'KE max':>12} {'vmax/c0':>10} {'std(rho)/rho':>13}")
    results = {}
    for name, atoms in (("unrelaxed", start), ("relaxed", relaxed)):
        r = lammps_io.sph_at_rest(atoms, h, dx, steps=args.steps, c0=args.c0)
        results[name] = r
        print(f"{name:>10} {r['ke']:12.4e} {r['ke_max']:12.4e} {r['vmax_over_c0']:10.3e} {r['rho_std']:13.3e}")
    ratio = results["unrelaxed"]["ke"] / results["relaxed"]["ke"]
    print(f"KE(unrelaxed) / KE(relaxed) after {args.steps} steps: {ratio:.1f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    record = {"settings": vars(args), "n_particles": len(start),
              "relaxation": {"iterations": info["iterations"], "energy": info["energy"], "fnorm": info["fnorm"]},
              "runs": {name: {key: float(r[key]) for key in ("ke", "ke_max", "vmax_over_c0", "rho_std")}
                       for name, r in results.items()},
              "ke_ratio": ratio}
    (out / "at_rest.json").write_text(json.dumps(record, indent=1) + "\n")
    return results


if __name__ == "__main__":
    main()
