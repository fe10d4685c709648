"""The banana's arms at rest against the collapsed-line law: beyond |x0| = 20 the resting particles (M = 500, the
default run at 32000 steps, at rest to round-off) against p's tail and against lambda ∝ p_ridge^(1/2) per unit arc
length (a line of particles with adaptive H: rho ∝ lambda^2, isothermal balance along the line), i.e. a density in
x0 ∝ exp(-x0^2 / 400) (1 + (0.06 x0)^2)^(1/2).

    PYTHONPATH=. .venv/bin/python reproductions/parvi-rest-vs-time/line_law.py
"""
import json
from pathlib import Path

import numpy as np
from scipy.integrate import quad

HERE = Path(__file__).resolve().parent / "results"  # this entry's results
LAWS = {"p (the truth)": lambda t: np.exp(-t * t / 200.0),
        "line law": lambda t: np.exp(-t * t / 400.0) * np.sqrt(1.0 + (0.06 * t) ** 2)}


def tail_summary(law, edge=20.0, inner=25.0):
    norm = quad(law, edge, np.inf)[0]
    return dict(mean_abs_x0=quad(lambda t: t * law(t), edge, np.inf)[0] / norm,
                share_below_inner=quad(law, edge, inner)[0] / norm)


def main():
    out = {}
    for name, step in (("banana_m500_s0_default.npz", 32000), ("banana_m500_s0_local_critical.npz", 16000),
                       ("banana_m500_s0_critical.npz", 32000)):
        x_p = np.abs(np.load(HERE / "snapshots" / name)[f"r_{step}"][:, 0])
        tail_p = x_p[x_p > 20.0]
        out[f"{name} step {step}"] = dict(n=int(tail_p.size), mean_abs_x0=float(tail_p.mean()),
                                          share_below_inner=float(np.mean(tail_p < 25.0)))
    out.update({name: tail_summary(law) for name, law in LAWS.items()})
    (HERE / "line_law.json").write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
