"""Energy distance and resolution diagnostics against SPH steps: one long run, read at checkpoints.

A wrapper of ``reproductions/lib/parvi_run_sph.py`` (its ``build_sampler``, and the benchmark's ``comparison_set`` that
it uses: the same starts, reference and i.i.d. floor). One run of ``max(--checkpoints)`` steps is made per target, M, seed and variant; the
particles are read at every checkpoint (by wrapping the model's ``evaluate``, which the sampler calls once per SPH
step with the positions of that step). Nothing in the K = 1 dynamics depends on ``steps`` (no ramp, no annealing,
no whitening), so the state at checkpoint k is the final state of a run of k steps (checked against run_sph.py's
rows, README). At every checkpoint: the energy distance over i.i.d., the physical time (median particle), the
kinetic energy, the sampler's convergence verdict recomputed on the steps up to there (``assess_convergence`` on
the sampler's own trace and the moments of the recorded states), and the target's diagnostics (``funnel`` and
``banana``: marginal quantiles, tail shares, the spread across the curve per bin and H per bin, against the truth).
Positions at the checkpoints go to ``<out>.npz``-like files in ``snapshots/``.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \\
        reproductions/parvi-rest-vs-time/run_rest.py --targets funnel --m 500 --seeds 0 \\
        --checkpoints 1000 2000 4000 8000 --out reproductions/parvi-rest-vs-time/results/funnel_m500.json.gz
"""
import argparse
import importlib.util
import sys
import json
import math
import os
import subprocess
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.stats import norm

from ase_sphrelax.sampling import get_target, metrics
from ase_sphrelax.sampling import sampler as sampler_module
from ase_sphrelax.sampling.friction import damp as friction_damp
from ase_sphrelax.sampling.convergence import assess_convergence, ensemble_moments

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from lib import parvi_run_sph as run_sph  # noqa: E402  (build_sampler pins lib.parvi_pinned.CLASSIC)
from lib.results_io import read_json as load_json, write_json as save_json  # noqa: E402

QUANTILES = (0.02, 0.05, 0.25, 0.5, 0.75, 0.95, 0.98)
#: x0 bins: the funnel's neck (x1 | x0 ~ N(0, e^x0)), the banana's arms (x0 ~ N(0, 100))
FUNNEL_EDGES = (-np.inf, -6.0, -4.5, -3.0, -1.5, 0.0, 1.5, 3.0, np.inf)
BANANA_EDGES = (-np.inf, -20.0, -15.0, -10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0, np.inf)
BANANA_B = 0.03


def binned(x0_p, edges, sd0, columns):
    """Per bin of x0: the particle count, the count of the truth (x0 ~ N(0, sd0^2)), and each of ``columns``
    (name -> (M,) values, summarised by ``fn`` as given: name -> (values, fn))."""
    out = []
    m = len(x0_p)
    for lo, hi in zip(edges[:-1], edges[1:]):
        in_p = (x0_p >= lo) & (x0_p < hi)
        row = dict(bin=[lo, hi], n=int(in_p.sum()), n_true=float(m * (norm.cdf(hi / sd0) - norm.cdf(lo / sd0))))
        for name, (values_p, fn) in columns.items():
            row[name] = float(fn(values_p[in_p])) if in_p.any() else None
        out.append(row)
    return out


def marginal(x0_p, sd0):
    """Mean, sd and quantiles of the x0 marginal against N(0, sd0^2)."""
    return dict(mean=float(x0_p.mean()), sd=float(x0_p.std()),
                quantiles={str(q): [float(np.quantile(x0_p, q)), float(sd0 * norm.ppf(q))] for q in QUANTILES})


def rms(a):
    return np.sqrt(np.mean(a**2))


def funnel_diagnostics(x_pc, h_p, v_pc):
    """The funnel's neck: x1 / exp(x0/2) ~ N(0, 1) at every x0 (rms 1), and H against the neck's sd exp(x0/2); the
    rms speed per bin (a fluid at rest: 0)."""
    x0_p, x1_p = x_pc[:, 0], x_pc[:, 1]
    speed_p = np.sqrt(np.einsum("pc,pc->p", v_pc, v_pc))
    width_p = np.exp(0.5 * x0_p)
    return dict(x0=marginal(x0_p, 3.0),
                share_below_m3=[float(np.mean(x0_p < -3.0)), float(norm.cdf(-1.0))],
                share_below_m6=[float(np.mean(x0_p < -6.0)), float(norm.cdf(-2.0))],
                bins=binned(x0_p, FUNNEL_EDGES, 3.0, dict(
                    x1_rms_over_width=(x1_p / width_p, rms),
                    x1_mean_over_width=(x1_p / width_p, np.mean),
                    h_median=(h_p, np.median),
                    h_over_width_median=(h_p / width_p, np.median),
                    speed_rms=(speed_p, rms))))


def banana_diagnostics(x_pc, h_p, v_pc):
    """The banana's curve: u = x1 - b (x0^2 - 100) ~ N(0, 1) at every x0; H against the width across the curve,
    1 / sqrt(1 + (2 b x0)^2)."""
    x0_p = x_pc[:, 0]
    speed_p = np.sqrt(np.einsum("pc,pc->p", v_pc, v_pc))
    u_p = x_pc[:, 1] - BANANA_B * (x0_p**2 - 100.0)
    width_p = 1.0 / np.sqrt(1.0 + (2.0 * BANANA_B * x0_p) ** 2)
    return dict(x0=marginal(x0_p, 10.0),
                share_abs_above_15=[float(np.mean(np.abs(x0_p) > 15.0)), float(2 * norm.cdf(-1.5))],
                share_abs_above_20=[float(np.mean(np.abs(x0_p) > 20.0)), float(2 * norm.cdf(-2.0))],
                bins=binned(x0_p, BANANA_EDGES, 10.0, dict(
                    u_rms=(u_p, rms), u_mean=(u_p, np.mean), h_median=(h_p, np.median),
                    h_over_width_median=(h_p / width_p, np.median),
                    speed_rms=(speed_p, rms))))


def particle_drag(sampler):
    """``damp`` of friction.py followed by a per-particle drag along each particle's last score: the component of
    v_a along s_a decays with rate ``2 (alpha)^(1/2) |s_a|`` (B_a = that rate times s_a s_a^T / |s_a|^2: symmetric
    positive semi-definite, zero at rest, so the resting states are unchanged; theory.py F1-F3)."""
    alpha = sampler.model.alpha

    def damp(v_pc, dt, friction, drag):
        v_pc = friction_damp(v_pc, dt, friction, drag)
        s_pc = sampler.target.last_score
        if s_pc is None or s_pc.shape != v_pc.shape:
            return v_pc
        norm_p = np.sqrt(np.einsum("pc,pc->p", s_pc, s_pc))
        unit_pc = np.where(norm_p[:, None] > 0, s_pc / np.where(norm_p > 0, norm_p, 1.0)[:, None], 0.0)
        along_p = np.einsum("pc,pc->p", v_pc, unit_pc)
        decay_p = np.exp(-0.5 * np.ravel(dt * np.ones((len(v_pc), 1))) * 2.0 * math.sqrt(alpha) * norm_p)
        return v_pc + ((decay_p - 1.0) * along_p)[:, None] * unit_pc

    return damp


DIAGNOSTICS = dict(funnel=funnel_diagnostics, banana=banana_diagnostics)


class Checkpoints:
    """Wraps ``sampler.model.evaluate``: the n-th call after the first is SPH step n (K = 1, no whitening). Keeps
    the moments every ``record_every`` steps (those the sampler records) and (r, v, H, rho, drag) at the
    checkpoints."""

    def __init__(self, sampler, checkpoints):
        self.sampler, self.checkpoints = sampler, set(checkpoints)
        self.call, self.moments, self.states = -1, {}, {}
        self.evaluate = sampler.model.evaluate
        sampler.model.evaluate = self

    def __call__(self, r_pc, v_pc=None, **kwargs):
        ev = self.evaluate(r_pc, v_pc, **kwargs)
        self.call += 1
        step = self.call
        if step % self.sampler.record_every == 0:
            self.moments[step] = np.concatenate(ensemble_moments(r_pc))
        if step - 1 in self.states:  # the drag renewed after the checkpoint's evaluation
            self.states[step - 1]["damping_rate"] = self.sampler.damping_rate()
        if step in self.checkpoints:
            self.states[step] = dict(r=np.array(r_pc), v=np.array(v_pc), h=np.array(ev.h), mass=ev.mass)
        return ev


def checkpoint_rows(target, res, hook, ref, iid):
    """One dict per checkpoint: energy over i.i.d., time, kinetic energy, the convergence verdict of a run stopped
    there, the target's diagnostics."""
    trace = res.trace
    rows = []
    for step in sorted(hook.states):
        state = hook.states[step]
        keep = trace["step"] <= step
        x_pc = state["r"]
        moments = [hook.moments[int(s)] for s in trace["step"][keep]]
        rate = state.get("damping_rate", hook.sampler.damping_rate())
        verdict = assess_convergence(trace["step"][keep], trace["time"][keep], trace["kinetic"][keep], moments,
                                     x_pc, friction=rate)
        energy = metrics.energy_distance(x_pc, ref)
        kinetic_k = trace["kinetic"][keep]
        row = dict(steps=step, energy=energy, ratio_to_iid=energy / iid,
                   sim_time_median=float(trace["time"][keep][-1]),
                   kinetic=float(kinetic_k[-1]), kinetic_max_last_half=float(kinetic_k[trace["step"][keep] >= step / 2].max()),
                   converged=bool(verdict["converged"]), convergence_reason=verdict["reason"],
                   mean_drift_se=verdict["mean_drift_se"], cov_drift_se=verdict["cov_drift_se"],
                   kinetic_ratio=verdict["kinetic_ratio"], h_median=float(np.median(state["h"])))
        if target.name in DIAGNOSTICS:
            row["diagnostics"] = DIAGNOSTICS[target.name](x_pc, state["h"], state["v"])
        rows.append(row)
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--targets", nargs="+", default=["funnel"])
    parser.add_argument("--variants", nargs="+", default=["local+critical"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--m", type=int, default=500)
    parser.add_argument("--checkpoints", nargs="+", type=int, default=[1000, 2000, 4000, 8000])
    parser.add_argument("--local-growth", type=float, default=None,
                        help="sampler.LOCAL_GROWTH for this run (the cap on a particle's step growth per step)")
    parser.add_argument("--n-neighbours", type=float, default=None,
                        help="ParVISampler's n_neighbours (default: the model's, 32 in 2D)")
    parser.add_argument("--start", choices=("normal", "iid"), default="normal",
                        help="normal: run_sph's N(0, I) starts; iid: M i.i.d. draws of the target (seed + 700)")
    parser.add_argument("--particle-drag", action="store_true",
                        help="experiment: after the sampler's drag, each particle's velocity along its last score s_a "
                             "is damped with rate 2 (alpha)^(1/2) |s_a| (a per-particle critical rate; a PSD drag)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    extra = {} if args.n_neighbours is None else dict(n_neighbours=args.n_neighbours)
    sampler_module.LOCAL_GROWTH = args.local_growth
    rows = load_json(args.out)["rows"] if args.out.exists() else []
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "ase_sphrelax"], capture_output=True,
                                text=True).stdout.strip())
    snapshots = HERE / "results" / "snapshots"
    snapshots.mkdir(parents=True, exist_ok=True)
    steps = max(args.checkpoints)
    for seed in args.seeds:
        for tname in args.targets:
            target = get_target(tname)
            ref, iid, x0 = run_sph.comparison_set(target, args.m, seed)
            if args.start == "iid":  # a start with the target's own law: does the fluid leave it?
                x0 = target.sample(args.m, np.random.default_rng(seed + 700))
                x0_ratio = metrics.energy_distance(x0, ref) / iid
            for variant in args.variants:
                if "score_every" in variant or "whiten" in variant or "coarse" in variant:
                    raise SystemExit(f"{variant}: the checkpoints need one evaluate call per SPH step (K = 1)")
                load = os.getloadavg()[0]
                t0 = time.perf_counter()
                sampler = run_sph.build_sampler(target, variant, args.m, x0, steps, seed, **extra)
                hook = Checkpoints(sampler, args.checkpoints)
                sampler_module.damp = particle_drag(sampler) if args.particle_drag else friction_damp
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = sampler.run()
                wall = time.perf_counter() - t0
                head = dict(target=tname, m=args.m, seed=seed, variant=variant, iid_energy=iid,
                            git=git + ("+dirty" if dirty else ""), load=load, load_end=os.getloadavg()[0],
                            wall=wall, final_converged=res.info["converged"], local_growth=args.local_growth,
                            n_neighbours=args.n_neighbours, start=args.start, particle_drag=args.particle_drag,
                            start_ratio_to_iid=x0_ratio if args.start == "iid" else None)
                for row in checkpoint_rows(target, res, hook, ref, iid):
                    rows.append(dict(head, **row))
                    print(json.dumps({k: v for k, v in rows[-1].items() if k != "diagnostics"}), flush=True)
                tag = "" if args.local_growth is None else f"_growth{args.local_growth:g}"
                tag += "" if args.n_neighbours is None else f"_nb{args.n_neighbours:g}"
                tag += "" if args.start == "normal" else f"_start{args.start}"
                tag += "_pdrag" if args.particle_drag else ""
                np.savez_compressed(snapshots / f"{tname}_m{args.m}_s{seed}_{variant.replace('+', '_')}{tag}.npz",
                                    **{f"r_{s}": st["r"] for s, st in hook.states.items()},
                                    **{f"h_{s}": st["h"] for s, st in hook.states.items()},
                                    **{f"v_{s}": st["v"] for s, st in hook.states.items()},
                                    time=res.trace["time"], step=res.trace["step"], kinetic=res.trace["kinetic"])
                save_json(args.out, dict(command="see run_rest.py's docstring", rows=rows))


if __name__ == "__main__":
    main()
