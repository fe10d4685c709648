"""BIPI Figs. 19-21 in BISPH: flow through a periodic array of cylinders between plates, started at its steady state.

    python reproductions/bipi-cylinders-bisph/run.py --out reproductions/bipi-cylinders-bisph/results
    python reproductions/bipi-cylinders-bisph/run.py --out /tmp/cyl --dx 0.008 --t-steady 0.02 --t-avg 0.01 \
        --t-run 0.004  # quick

Geometry: BIPI2D's own ``PeriodicCylinderArray/bulkBdry1D.dat`` (RealTimeSimLab/BIPI2D, commit 3b28f85,
MIT licence), converted by ``reproductions/lib/nastran.py`` to ``PeriodicCylinderArray.edges`` beside
this file: a cell 0.12 m long between plates at y = 0 and 0.08 m, a cylinder of radius 0.02 m (the
paper's r_cyl) at its centre; periodic in x (the file's two ends are the periodic faces, dropped by
``BoundarySegments.with_cell``). The paper gives neither cell size nor dx; the file gives the cell.

Physics (the paper's): F = 100 m/s^2 along x, mu = 10 Pa s, rho0 = 1000 kg/m^3, in
:class:`ase_sphrelax.flows.BISPH` (Eqs. 16-21) with the particle-consistent-gradient viscous term
(``viscosity="pcg"``, as the paper uses for this case), Wendland C2, h_B = 2 dx (support 4 dx),
Molteni-Colagrossi delta = 0.1, c0 = 100 m/s and P_B = 50 kPa (our choices, stated; the paper takes
P_B from its steady state's minimum pressure).

Steps (one process, one run at a time):

1. **Steady state** (the paper takes STAR-CCM+'s; we make ours): BISPH from the Cartesian start
   (``initial_fill``, BIPI's Step 1) at rest, run to ``--t-steady``; snapshots of (x, p, v) every
   ``t_avg/20`` over the last ``--t-avg`` (0.05 s) are pooled into one sample set.
2. **Reference fields** p*(x), v*(x): a linear moving-least-squares fit (SPH interpolation with a
   first-order correction: weighted least squares of ``a + b.(x - x_q)`` with Wendland C2 weights of
   support 2 dx) to the pooled samples and their periodic images; for the velocity, no-slip samples
   (v = 0) every dx/4 along the walls are added.
3. **Starts**: the Cartesian fill (no BIPI) and BIPI with exactly 100 + 100 and 400 + 300 iterations
   of Steps 2a + 2c (``make_start`` of ``reproductions/lib/bipi_sph.py``: ``BIPIPacker`` with those caps
   and the 1 % rules off), packed in the periodic cell. At t = 0 each particle gets v = v*(x_a) and the
   density of p*(x_a) (Eq. 18 inverted).
4. **Runs** to ``--t-run``, and the measure below every ``t_run/100``.

MEASURE (declared before the runs): at each recorded time t, over all N particles of a start,
``p_rms(t) = sqrt(mean_a (p_a(t) - p*(x_a(t)))^2)`` and likewise ``v1_rms``, ``v2_rms`` against
v*_1, v*_2, the reference fields of step 2 at the particles' current positions (Eulerian: the
steady field does not move with the particles). The verdict compares the time means of these over
(0, t_run] between the starts: the paper's ordering is Cartesian > 100 + 100 >= 400 + 300.
Also recorded (not the verdict): the same RMS against each particle's own t = 0 values (the
paper's words "using the values of initial pressure ... as the reference" read literally), and the
mean of p - p* (the uniform part of the pressure error, added after the first runs).

Writes ``summary.json`` (settings, steady state check, Reynolds number, packing iterations, the
time-mean / t = 0 / final RMS of each start), ``rms.json.gz`` (the RMS curves) and ``rms.png``.
The steady-state samples are cached in ``--cache`` (not a result file).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.results_io import write_json  # noqa: E402

HERE = Path(__file__).resolve().parent
EDGES = HERE / "PeriodicCylinderArray.edges"
RHO0, MU, FORCE, R_CYL = 1000.0, 10.0, 100.0, 0.02
C0, P_B = 100.0, 5.0e4
H_OVER_DX = 4.0
T_AVG = 0.05
STARTS = ("cartesian", "bipi_fixed_100_100", "bipi_fixed_400_300")
REF_SUPPORT_DX = 2.0


def cell_boundary():
    from ase_sphrelax.boundary import BoundarySegments

    return BoundarySegments.from_edges(EDGES).with_cell(pbc=(True, False), quiet=True)


WALL_BAND = 0.5  # Eq. 21's band in dx; --wall-band 0 switches it off (the controlled experiment)
EQ21 = "pointwise"  # --eq21 segment: Eq. 21 at each segment's nearest point (the earlier runs)


def make_sim(boundary, r, dx, v=None, rho=None):
    from ase_sphrelax.flows import BISPH

    return BISPH(boundary, r, dx, rho0=RHO0, c0=C0, mu=MU, body_force=(FORCE, 0.0), h_over_dx=H_OVER_DX,
                 p_background=P_B, hydrostatic=False, viscosity="pcg", velocities=v, density=rho,
                 wall_band=WALL_BAND, eq21=EQ21)


def steady_state(boundary, dx, t_steady, t_avg, cache):
    """Step 1: pooled (x, y, p, v1, v2) samples over the last ``t_avg`` and the KE history (cached)."""
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    if cache.exists():
        data = np.load(cache)
        return data["samples"], data["ke"], float(data["wall"])
    sim = make_sim(boundary, initial_fill(boundary, dx).positions, dx)
    t0 = time.perf_counter()
    every = t_avg / 20
    ke, samples = [], []
    next_ke, next_snap = 0.0, t_steady - t_avg
    while sim.t < t_steady - 1e-12:
        sim.step(min(sim.time_step(), t_steady - sim.t))
        if not np.all(np.isfinite(sim.v)):
            raise FloatingPointError(f"steady run diverged at t = {sim.t:.4g} s")
        if sim.t >= next_ke:
            ke.append((sim.t, sim.kinetic_energy()))
            next_ke += t_steady / 200
        if sim.t >= next_snap - 1e-12:
            samples.append(np.column_stack([sim.r[:, :2], sim.pressure(), sim.v[:, :2]]))
            next_snap += every
            print(f"  steady t = {sim.t:.4f} s, KE {ke[-1][1]:.4g} J/m, {time.perf_counter() - t0:.0f} s", flush=True)
    samples, ke, wall = np.concatenate(samples), np.array(ke), time.perf_counter() - t0
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, samples=samples, ke=ke, wall=wall)
    return samples, ke, wall


class Reference:
    """Step 2: p*, v1*, v2* by linear moving least squares over the pooled samples (periodic in x)."""

    def __init__(self, samples, boundary, dx):
        from scipy.spatial import cKDTree

        self.length = float(boundary.cell[0, 0])
        self.radius = REF_SUPPORT_DX * dx
        s = samples.copy()
        s[:, 0] = np.mod(s[:, 0], self.length)
        walls = []
        for v in boundary.loops:
            for a, b in zip(v, np.roll(v, -1, axis=0)):
                if np.isclose(a[0], b[0]) and (np.isclose(a[0], 0.0) or np.isclose(a[0], self.length)):
                    continue  # a periodic face, not a wall
                n = max(1, int(math.ceil(np.linalg.norm(b - a) / (0.25 * dx))))
                t = (np.arange(n) + 0.5) / n
                walls.append(a[None, :] + t[:, None] * (b - a)[None, :])
        walls = np.concatenate(walls)
        wall_rows = np.column_stack([walls, np.full(len(walls), np.nan), np.zeros((len(walls), 2))])
        rows = np.concatenate([s, wall_rows])
        left = rows[rows[:, 0] < self.radius] + [self.length, 0, 0, 0, 0]
        right = rows[rows[:, 0] > self.length - self.radius] - [self.length, 0, 0, 0, 0]
        images = [rows, left, right]
        self.rows = np.concatenate(images)
        self.tree = cKDTree(self.rows[:, :2])

    def __call__(self, x):
        """(p*, v1*, v2*) at points x (N, 2+), (N, 3)."""
        from scipy.spatial import cKDTree

        q = np.column_stack([np.mod(x[:, 0], self.length), x[:, 1]])
        m = cKDTree(q).sparse_distance_matrix(self.tree, self.radius, output_type="coo_matrix")
        i, j, r = m.row, m.col, m.data
        w = (1 - r / self.radius) ** 4 * (1 + 4 * r / self.radius)
        d = self.rows[j, :2] - q[i]
        out = np.empty((len(q), 3))
        for c in range(3):
            f = self.rows[j, 2 + c]
            ok = np.isfinite(f)  # pressure: the wall samples carry none
            basis = np.column_stack([np.ones(ok.sum()), d[ok] / self.radius])
            wb = w[ok, None] * basis
            io, n = i[ok], len(q)
            mat = np.stack([np.bincount(io, wb[:, a] * basis[:, b], n) for a in range(3) for b in range(3)],
                           axis=1).reshape(n, 3, 3)
            rhs = np.stack([np.bincount(io, wb[:, a] * f[ok], n) for a in range(3)], axis=1)
            out[:, c] = np.linalg.solve(mat + 1e-12 * np.eye(3) * mat[:, :1, :1], rhs[..., None])[:, 0, 0]
        return out


def rms(sim, ref, initial):
    """The declared measure (module docstring), the own-initial-value variant and the mean of p - p*
    (a uniform pressure offset, which moves no particle, is part of p_rms)."""
    p = sim.pressure()
    got = np.column_stack([p, sim.v[:, 0], sim.v[:, 1]])
    star = ref(sim.r)
    return (np.sqrt(np.mean((got - star) ** 2, axis=0)).tolist(),
            np.sqrt(np.mean((got - initial) ** 2, axis=0)).tolist(), float(np.mean(got[:, 0] - star[:, 0])))


def reynolds(samples, length, h):
    """``rho0 v_bar r_cyl / mu`` with v_bar the mean v1 of the samples within h of the periodic face."""
    x = np.mod(samples[:, 0], length)
    band = (x < h) | (x > length - h)
    v_bar = float(samples[band, 3].mean())
    return RHO0 * v_bar * R_CYL / MU, v_bar


def plot(curves, summary, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ase_sphrelax.plotting import save_figure

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    labels = dict(cartesian="no BIPI (Cartesian)", bipi_fixed_100_100="BIPI 100 + 100",
                  bipi_fixed_400_300="BIPI 400 + 300")
    for name, c in curves.items():
        t = np.array(c["t"])[1:] * 1e3  # t = 0: zero by construction
        e = np.array(c["rms"])[1:]
        for k, ax in enumerate(axes):
            ax.semilogy(t, e[:, k], label=labels[name])
    for ax, what in zip(axes, ("p_rms (Pa)", "v1_rms (m/s)", "v2_rms (m/s)")):
        ax.set(xlabel="t (ms)", ylabel=what)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"cylinder array in BISPH, dx = {summary['dx']:g} m: RMS error against the steady fields", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colors=64)


def main(argv=None):
    global WALL_BAND, EQ21
    from lib.bipi_sph import make_start
    from ase_sphrelax.drivers.bipi_packer import initial_fill
    from ase_sphrelax.flows.bisph import tait_density

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-cylinders-bisph/results")
    parser.add_argument("--dx", type=float, default=0.004)
    parser.add_argument("--t-steady", type=float, default=0.3, help="length of the steady-state run (s)")
    parser.add_argument("--t-run", type=float, default=0.05, help="length of each start's run (s)")
    parser.add_argument("--t-avg", type=float, default=T_AVG, help="the steady run's averaging window (s)")
    parser.add_argument("--wall-band", type=float, default=WALL_BAND,
                        help="Eq. 21's band in dx, every run (0: compressed density off; the controlled experiment)")
    parser.add_argument("--eq21", choices=("pointwise", "segment"), default=EQ21,
                        help="Eq. 21 pointwise along the wall (default) or at each segment's nearest point")
    parser.add_argument("--tag", default="", help="suffix of summary{tag}.json and rms{tag}.json.gz")
    parser.add_argument("--cache", default=None, help="steady samples (default a file in /tmp named by the settings)")
    args = parser.parse_args(argv)
    if not args.t_steady > args.t_avg > 0:
        parser.error(f"--t-steady must exceed --t-avg > 0, got {args.t_steady!r} and {args.t_avg!r}")
    WALL_BAND, EQ21 = args.wall_band, args.eq21
    dx = args.dx
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(args.cache or f"/tmp/bipi-cyl-steady-dx{dx:g}-t{args.t_steady:g}-{args.t_avg:g}"
                               f"-band{args.wall_band:g}-{args.eq21}.npz")
    boundary = cell_boundary()
    h = H_OVER_DX * dx
    print(f"steady run: dx = {dx:g} m, {args.t_steady:g} s", flush=True)
    samples, ke, steady_wall = steady_state(boundary, dx, args.t_steady, args.t_avg, cache)
    ref = Reference(samples, boundary, dx)
    re, v_bar = reynolds(samples, ref.length, h)
    late = ke[:, 0] >= args.t_steady - args.t_avg
    summary = dict(dx=dx, wall_band_dx=args.wall_band, eq21=args.eq21, h_support=h, h_b=h / 2, rho0=RHO0, mu=MU, force=FORCE, c0=C0,
                   p_background=P_B, viscosity="pcg", t_steady=args.t_steady, t_avg=args.t_avg, t_run=args.t_run,
                   reference="linear moving least squares, Wendland C2 weights of support 2 dx, pooled snapshots",
                   steady=dict(wall_time_s=round(steady_wall, 1), n_samples=len(samples),
                               ke_last=float(ke[-1, 1]),
                               ke_change_over_t_avg=float((ke[late, 1].max() - ke[late, 1].min()) / ke[-1, 1]),
                               p_min=float(np.min(samples[:, 2])), p_max=float(np.max(samples[:, 2])),
                               v_max=float(np.max(np.hypot(samples[:, 3], samples[:, 4]))),
                               reynolds=re, v_bar=v_bar),
                   paper=dict(reynolds=9.8), runs={})
    print(f"  steady: {summary['steady']}", flush=True)
    fill = initial_fill(boundary, dx)
    curves = {}
    for name in STARTS:
        atoms, info = make_start(name, boundary, dx, h, fill)
        r = atoms.positions[:, :2]
        star = ref(r)
        sim = make_sim(boundary, r, dx, v=star[:, 1:], rho=tait_density(star[:, 0], RHO0, C0, P_B))
        initial = np.column_stack([sim.pressure(), sim.v[:, 0], sim.v[:, 1]])
        t0 = time.perf_counter()
        c = dict(t=[], rms=[], rms_own=[], p_bias=[])
        every, next_rec = args.t_run / 100, 0.0
        while True:
            if sim.t >= next_rec - 1e-12:
                a, b, bias = rms(sim, ref, initial)
                c["t"].append(sim.t)
                c["rms"].append(a)
                c["rms_own"].append(b)
                c["p_bias"].append(bias)
                next_rec += every
            if sim.t >= args.t_run - 1e-12:
                break
            sim.step(min(sim.time_step(), args.t_run - sim.t))
            if not np.all(np.isfinite(sim.v)):
                raise FloatingPointError(f"{name} diverged at t = {sim.t:.4g} s")
        e = np.array(c["rms"])
        t = np.array(c["t"])
        mean = np.trapezoid(e[1:], t[1:], axis=0) / (t[-1] - t[1])
        bias = np.array(c["p_bias"])
        info = {k: v for k, v in info.items() if k != "reason"}
        summary["runs"][name] = dict(info, n=len(r), steps=sim.steps, p_bias_final=float(bias[-1]),
                                     p_bias_mean=float(np.trapezoid(bias[1:], t[1:]) / (t[-1] - t[1])),
                                     run_wall_time_s=round(time.perf_counter() - t0, 1),
                                     **{f"{q}_rms_{k}": float(v) for k, vals in (("mean", mean), ("t0", e[0]),
                                                                                 ("final", e[-1]))
                                        for q, v in zip(("p", "v1", "v2"), vals)})
        curves[name] = c
        print(f"  {name}: {summary['runs'][name]}", flush=True)
    runs = summary["runs"]
    summary["ordering_reproduced"] = {
        q: bool(runs["cartesian"][f"{q}_rms_mean"] > runs["bipi_fixed_100_100"][f"{q}_rms_mean"]
                >= runs["bipi_fixed_400_300"][f"{q}_rms_mean"]) for q in ("p", "v1", "v2")}
    summary["command"] = " ".join(["python", "reproductions/bipi-cylinders-bisph/run.py"] + sys.argv[1:])
    (out / f"summary{args.tag}.json").write_text(json.dumps(summary, indent=1) + "\n")
    write_json(out / f"rms{args.tag}.json.gz", curves)
    if not args.tag:
        plot(curves, summary, out / "rms.png")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
