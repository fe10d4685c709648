"""Fig. 16 with the paper's force (Eq. 29 with its background pressure, eta = 2.5): epsilon / Eq. 48 against N.

51 equispaced particles on the periodic [-1, 1) (one at x = 0), Eq. 46 with Delta = 0 (as ``../alaric-fig16``),
ALARIC's S+F+V dynamics with ``form="paper"`` (the calculator's defaults: ``background_pressure="deficit"``,
``eta = PAPER_ETA``), 0-4 splitting stages, each split at the epsilon_dot < 1e-8 check of the stage before, no polish.
The run with k stages is the run with k + 1 stages up to its (k+1)-th split (the dynamics is deterministic and the
split happens exactly where the k-stage run stops), so one run with 4 stages gives all five: the state at each
split check, and at the final stop, is recorded as ``results/stages_<k>.json`` (epsilon, Eq. 48 for that N, Eq. 45's
share of the particle nearest x = 0). Only the form differs from ``../alaric-fig16`` (log form, ratio 2.9).

    python reproductions/alaric-fig16-paper-form/run.py --out reproductions/alaric-fig16-paper-form/results
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ase_sphrelax import ALARICDynamics  # noqa: E402
from ase_sphrelax.analysis.alaric import alaric_min_error  # noqa: E402
from lib.alaric_figures import bottom_of_the_well  # noqa: E402
from lib.alaric_reproduce import line_atoms  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="reproductions/alaric-fig16-paper-form/results")
    ap.add_argument("--stages", type=int, default=4)
    ap.add_argument("--delta", type=float, default=0.0)
    ap.add_argument("--form", default="paper")
    ap.add_argument("--cap", type=int, default=60000)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = (f"python reproductions/alaric-fig16-paper-form/run.py --out {args.out} --stages {args.stages} "
               f"--delta {args.delta:g} --form {args.form} --cap {args.cap}")
    atoms = line_atoms(51, args.delta, args.form)
    dyn = ALARICDynamics(atoms, splits=args.stages, eps_dot_min=1e-8)
    t0 = time.perf_counter()
    c0 = time.process_time()

    def record(stop):
        k = dyn.stage
        n = len(atoms)
        eps = dyn.trace[-1]["epsilon"]
        teo = alaric_min_error(n, args.delta, 1)
        below = [e for e in dyn.trace if e["epsilon"] < alaric_min_error(e["n"], args.delta, 1)]
        row = dict(command=command, form=args.form, eta=float(atoms.calc.eta), delta=args.delta, stages=k, n_final=n,
                   steps=dyn.nsteps + (0 if stop else 1), stop=stop or "epsilon_dot (split here in the longer run)",
                   epsilon=eps, eq48=teo, ratio=eps / teo, checks_below_eq48=len(below),
                   wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0, load_average=list(os.getloadavg()),
                   trace=[(e["time"], e["epsilon"], e["n"]) for e in dyn.trace], **bottom_of_the_well(atoms))
        (out / f"stages_{k}.json").write_text(json.dumps(row, indent=1) + "\n")
        print(f"{k} stages: N {n}, {row['steps']} steps, eps {eps:.3e}, Eq. 48 {teo:.3e}, ratio {eps / teo:.3f}, "
              f"bottom x {row['bottom_x']:.2e}, bottom term / Eq. 48 {row['eps_bottom'] / teo:.3f}, "
              f"cpu {row['cpu_s']:.0f} s", flush=True)

    split = dyn._split

    def split_and_record():
        record(None)
        split()

    dyn._split = split_and_record
    dyn.run(args.cap)
    record(dyn.stop_reason)


if __name__ == "__main__":
    main()
