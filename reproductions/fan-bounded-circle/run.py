"""Relaxed patterns in Fan's circle (Sec. 5.2, Figs. 12-14), classified without periodicity.

Fan's circle: centre (0.5, 0.5), r = 0.2, 256 x 256 background mesh (8224
cell-centre particles here, 8186 in the paper), relaxed with the Fan
calculator (Eq. 3.8 with boundary term) by FIRE at h/dp = 2.25, 2.75, 3.3
(hexagonal in Table 1), 2.0, 2.05 (square) and 2.15 (Table 1 "parallelogram";
a centred rectangular lattice by our lattice analysis). The interior
(phi < -2h) is classified by the majority local lattice of the neighbour
vectors and by the hexatic orders |psi_4|, |psi_6| (freud).

The committed results were made by (about 4 min per 1500 steps and case on 1 core):

    python reproductions/fan-bounded-circle/run.py --steps 1500 --jitter 0.45
    python reproductions/fan-bounded-circle/run.py --continue --steps 3000 --h 2.25 2.75 3.3 2.15
    python reproductions/fan-bounded-circle/run.py --continue --steps 0   # re-classify, redraw

Writes <out> (default reproductions/fan-bounded-circle/results)/circle_<h>.png
(figures like Figs. 12-14), circle_<h>.extxyz (not committed: 0.5 MB each),
summary.txt (one line per run, appended) and summary.json (the last line per h,
parsed: ``cases[h=2.25].pattern``).
"""
import argparse
import json
import os
import re
import time

from ase.io import read

from ase_sphrelax.analysis.bounded import classify_bounded_pattern, plot_bounded_pattern, relax_circle
from ase_sphrelax.analysis import predict_pattern

CASES = (2.25, 2.75, 3.3, 2.0, 2.05, 2.15)
LINE = re.compile(r"h/dp=(?P<h>\S+) N=(?P<n>\d+) steps=(?P<steps>\d+) E=(?P<energy>\S+) interior=(?P<interior>\d+) "
                  r"pattern=(?P<pattern>\w+) \[(?P<fractions>[^]]*)\] psi4=(?P<psi4>\S+) psi6=(?P<psi6>\S+) "
                  r"median \|a2\|/\|a1\|=(?P<median_ratio>\S+) angle=(?P<median_angle>\S+) \| "
                  r"Table 1: (?P<table1>\w+), best lattice: (?P<best_lattice>\w+)")


def write_summary_json(summary_txt, summary_json):
    """Parse the lines of ``summary_txt`` into ``summary_json``: per h the last line's figures."""
    cases = {}
    with open(summary_txt) as fh:
        for line in fh:
            m = LINE.match(line.strip())
            if m is None:
                raise ValueError(f"summary_txt: line not in the expected form: {line.strip()!r}")
            d = m.groupdict()
            case = {"h": float(d["h"]), "n": int(d["n"]), "steps": int(d["steps"]), "energy": float(d["energy"]),
                    "interior": int(d["interior"]), "pattern": d["pattern"],
                    "fractions": {k: float(v) for k, v in (kv.split("=") for kv in d["fractions"].split())},
                    "table1": d["table1"], "best_lattice": d["best_lattice"]}
            case.update({k: float(d[k]) for k in ("psi4", "psi6", "median_ratio", "median_angle")})
            cases[case["h"]] = case
    with open(summary_json, "w") as fh:
        json.dump({"source": os.path.basename(summary_txt), "cases": list(cases.values())}, fh, indent=1)
        fh.write("\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="reproductions/fan-bounded-circle/results")
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--jitter", type=float, default=0.45)
    parser.add_argument("--optimizer", default="fire")
    parser.add_argument("--h", type=float, nargs="*", default=CASES)
    parser.add_argument("--continue", dest="cont", action="store_true",
                        help="continue from <out>/circle_<h>.extxyz when it exists")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "summary.txt"), "a") as summary:
        for h in args.h:
            t0 = time.time()
            path = os.path.join(args.out, f"circle_{h:g}.extxyz")
            start = read(path) if args.cont and os.path.exists(path) else None
            atoms, domain = relax_circle(h, steps=args.steps, optimizer=args.optimizer, jitter=args.jitter,
                                         start=start)
            pattern, info = classify_bounded_pattern(atoms, domain, margin=2.0 * atoms.info["h"])
            fractions = " ".join(f"{k}={v:.2f}" for k, v in info["fractions"].items())
            line = (f"h/dp={h:g} N={len(atoms)} steps={atoms.info['steps']} E={atoms.info['energy']:.6g} "
                    f"interior={info['n_interior']} pattern={pattern} [{fractions}] psi4={info['psi4']:.3f} "
                    f"psi6={info['psi6']:.3f} median |a2|/|a1|={info['median_ratio']:.3f} "
                    f"angle={info['median_angle']:.1f} | Table 1: {predict_pattern(h)}, best lattice: "
                    f"{predict_pattern(h, convention='bravais')} ({time.time() - t0:.0f} s)")
            print(line, flush=True)
            summary.write(line + "\n")
            plot_bounded_pattern(atoms, domain, os.path.join(args.out, f"circle_{h:g}.png"),
                                 title=f"h = {h:g} dp: {pattern} (interior {info['fractions'][pattern]:.0%})")
            atoms.calc = None
            atoms.write(os.path.join(args.out, f"circle_{h:g}.extxyz"))
    write_summary_json(os.path.join(args.out, "summary.txt"), os.path.join(args.out, "summary.json"))


if __name__ == "__main__":
    main()
