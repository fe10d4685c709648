"""BIPI Fig. 22 in BISPH: the elliptic drop from a Cartesian and a BIPI start against Monaghan's ODE.

    python reproductions/bipi-fig22-bisph/run.py --out reproductions/bipi-fig22-bisph/results --dx 0.02 \
        --starts cartesian bipi jitter

The drop of ``reproductions/bipi-fig22`` (there in LAMMPS), here in :class:`ase_sphrelax.flows.BISPH`, the
paper's own solver (Eqs. 16-21), set up by :func:`ase_sphrelax.flows.scene.elliptic_drop`: BIPI2D's EllipticDrop
circle (R = 0.5 m, 3142 edges; rebuilt here as the regular 3142-gon, which matches
RealTimeSimLab/BIPI2D ParticleGeneration/Test_datafiles/EllipticDrop, MIT licence, to 2e-6 m), the paper's
Eq. 22 at t = 0 (v = (A0 x, -A0 y), p = rho0 A0^2 (R^2 - r^2)/2 with R each start's second-moment radius
sqrt(2 <r^2>)), no gravity, a free surface (the walls a square of half-width 5 R: no particle comes within
a support of them, every gamma_a = 1). The paper gives Eq. 22 only; the rest is ours and the LAMMPS entry's:
A0 = 100 1/s, rho0 = 1000, c0 = 14 A0 R (Mach 0.07), mu = 10 Pa s (the paper's viscosity for its other flows;
the viscous term vanishes for the exact, linear velocity field), Wendland C2 with h_B = 2 dx, Molteni-Colagrossi
delta = 0.1, run to A0 t = 2.

Starts: ``cartesian``, the Step-1 fill (``initial_fill``: cell centres, none within dx/8 of the circle);
``bipi``, the same fill packed by ``BIPIPacker`` with the 1 % rules (``lib.bipi_sph.make_start``).
Controlled experiment (``--starts ... jitter``; added after the dx 0.01 Cartesian run showed that the b error does
not fall with dx, before any jitter run): ``jitter``, the Cartesian fill with each particle moved by a uniform
random vector in [-dx/4, dx/4]^2 (seed 0): the lattice broken without BIPI's boundary conformity.

MEASURE (declared before the runs): the semi-axes from the particles' second moments, a = 2 sqrt(<x^2>),
b = 2 sqrt(<y^2>) (exact for a uniform ellipse), sampled every 0.02 in A0 t, against the ODE
(``lammps_io.elliptic_drop_axes`` from the start's R). Primary: ``b_error_max`` = max over A0 t in [0, 2] of
abs(b - b_exact) / R; the BIPI start "follows the analytic boundary better" if its ``b_error_max`` is below the
Cartesian one's. Also reported: the same for a (``a_error_max``), both at A0 t = 2, and the extents
(max abs(x) + dx/2). Conservation: the largest abs(total momentum) / (M A0 R) over the run.

Writes ``drop_dx{dx}{tag}.json.gz`` (the histories and the measures) and ``drop_dx{dx}{tag}.png`` (a(t), b(t) against
the ODE, their errors, the particles at A0 t = 2 on the analytic ellipse).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "reproductions"))
sys.path.insert(0, str(ROOT))  # lammps_io
import numpy as np  # noqa: E402

from lib.bipi_sph import H_OVER_DX, make_start, pyplot  # noqa: E402
from lib.results_io import write_json  # noqa: E402

A0, RADIUS, N_EDGES = 100.0, 0.5, 3142
AT_END, SAMPLES = 2.0, 100
MU = 10.0


def circle():
    """BIPI2D's EllipticDrop: the regular 3142-gon of radius 0.5 about the origin."""
    from ase_sphrelax.boundary import BoundarySegments

    k = np.arange(N_EDGES)
    return BoundarySegments.from_vertices(RADIUS * np.column_stack([np.cos(2 * math.pi * k / N_EDGES),
                                                                    np.sin(2 * math.pi * k / N_EDGES)]))


def moments(sim):
    rel = sim.r[:, :2] - sim.r[:, :2].mean(axis=0)
    a, b = 2.0 * np.sqrt(np.mean(rel**2, axis=0))
    ext_a, ext_b = np.abs(rel).max(axis=0) + 0.5 * sim.dx
    p = sim.mass * sim.v[:, :2].sum(axis=0)
    return dict(a=float(a), b=float(b), a_extent=float(ext_a), b_extent=float(ext_b), ke=sim.kinetic_energy(),
                momentum=float(np.hypot(*p)))


def run_start(positions, dx):
    from ase_sphrelax.flows.scene import elliptic_drop
    from lammps_io import elliptic_drop_axes

    sim = elliptic_drop(positions, dx, a0=A0, mu=MU)
    rel = sim.r[:, :2] - sim.r[:, :2].mean(axis=0)
    radius = math.sqrt(2.0 * float(np.mean(np.sum(rel**2, axis=1))))
    hist = [dict(at=0.0, **moments(sim))]
    t = time.perf_counter()
    for k in range(1, SAMPLES + 1):
        t_k = AT_END * k / SAMPLES / A0
        sim.run(t_k, record_every=t_k - sim.t, progress=False)
        hist.append(dict(at=A0 * sim.t, **moments(sim)))
    wall = time.perf_counter() - t
    a_ex, b_ex, _ = elliptic_drop_axes(A0, [h["at"] / A0 for h in hist], radius)
    for h, a, b in zip(hist, a_ex, b_ex):
        h.update(a_exact=float(a), b_exact=float(b))
    a_err = [abs(h["a"] - h["a_exact"]) / radius for h in hist]
    b_err = [abs(h["b"] - h["b_exact"]) / radius for h in hist]
    mass = sim.mass * len(sim.r)
    final = sim.r[:, :2] - sim.r[:, :2].mean(axis=0)
    return dict(n=len(sim.r), radius=radius, c0=sim.c0, steps=sim.steps, run_wall_time_s=round(wall, 1),
                b_error_max=max(b_err), a_error_max=max(a_err), b_error_final=b_err[-1], a_error_final=a_err[-1],
                at_b_error_max=hist[int(np.argmax(b_err))]["at"],
                momentum_max=max(h["momentum"] for h in hist) / (mass * A0 * radius),
                ke_final_over_initial=hist[-1]["ke"] / hist[0]["ke"], history=hist), final


def plot(results, finals, path):
    from ase_sphrelax.plotting import save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), gridspec_kw=dict(width_ratios=[1, 1, 1.3]))
    ax, ax_err, ax_xy = axes
    for k, (name, row) in enumerate(results["starts"].items()):
        h = row["history"]
        at = np.array([r["at"] for r in h])
        for key, style in (("a", "-"), ("b", "--")):
            val = np.array([r[key] for r in h])
            ex = np.array([r[key + "_exact"] for r in h])
            ax.plot(at, val / row["radius"], style, color=f"C{k}", label=f"{name} {key}")
            ax_err.plot(at, (val - ex) / row["radius"], style, color=f"C{k}", label=f"{name} {key}")
        x = finals[name]
        shift = (0.8, 0.0, -0.8)[k]
        ax_xy.plot(x[:, 0] / row["radius"], x[:, 1] / row["radius"] + shift, ".", ms=1.0, color=f"C{k}",
                   label=f"{name} (y + {shift:g} R)")
        th = np.linspace(0, 2 * np.pi, 400)
        ae, be = h[-1]["a_exact"] / row["radius"], h[-1]["b_exact"] / row["radius"]
        ax_xy.plot(ae * np.cos(th), be * np.sin(th) + shift, "k-", lw=0.8)
    ax.plot(at, [r["a_exact"] / row["radius"] for r in h], "k:", label="ODE")
    ax.plot(at, [r["b_exact"] / row["radius"] for r in h], "k:")
    ax.set(xlabel="A0 t", ylabel="semi-axis / R", title=f"elliptic drop in BISPH, dx = {results['dx']:g} m")
    ax_err.set(xlabel="A0 t", ylabel="(BISPH - ODE) / R", title="semi-axis error (second moments)")
    ax_xy.set(xlabel="x / R", ylabel="y / R", title="A0 t = 2, analytic ellipse in black", aspect="equal")
    ax_xy.set_ylim(-1.3, 1.8)
    ax.legend(fontsize=7)
    ax_err.legend(fontsize=7)
    ax_xy.legend(fontsize=7, loc="upper center", ncol=3, markerscale=5)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def main(argv=None):
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-fig22-bisph/results")
    parser.add_argument("--dx", type=float, default=0.02)
    parser.add_argument("--starts", nargs="+", choices=("cartesian", "bipi", "jitter"), default=["cartesian", "bipi"])
    parser.add_argument("--tag", default="", help="suffix of the output names")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    dx, boundary = args.dx, circle()
    fill = initial_fill(boundary, dx)
    results = dict(dx=dx, h_support=H_OVER_DX * dx, a0=A0, mu=MU, at_end=AT_END,
                   measure="max over A0 t in [0, 2] of abs(b - b_exact) / R (b = 2 sqrt(<y^2>))",
                   command=" ".join(["python", "reproductions/bipi-fig22-bisph/run.py"] + sys.argv[1:]), starts={})
    finals = {}
    for name in args.starts:
        if name == "jitter":
            atoms, info = fill.copy(), dict(jitter_dx=0.25, seed=0)
            atoms.positions[:, :2] += np.random.default_rng(0).uniform(-0.25 * dx, 0.25 * dx, (len(atoms), 2))
        else:
            atoms, info = make_start(name, boundary, dx, H_OVER_DX * dx, fill)
        row, finals[name] = run_start(atoms.positions, dx)
        results["starts"][name] = dict(start=info, **row)
        print(f"{name}: {info} {len(atoms)} particles; b_error_max {row['b_error_max']:.4f} R at A0 t = "
              f"{row['at_b_error_max']:.2f}, a_error_max {row['a_error_max']:.4f} R, final b {row['b_error_final']:.4f}"
              f" a {row['a_error_final']:.4f} R; momentum {row['momentum_max']:.2e}; {row['steps']} steps in "
              f"{row['run_wall_time_s']} s", flush=True)
    s = results["starts"]
    if "cartesian" in s and "bipi" in s:
        results["b_error_max_ratio_cartesian_over_bipi"] = s["cartesian"]["b_error_max"] / s["bipi"]["b_error_max"]
        results["bipi_better"] = bool(s["bipi"]["b_error_max"] < s["cartesian"]["b_error_max"])
    tag = f"drop_dx{dx:g}{args.tag}"
    write_json(out / f"{tag}.json.gz", results)
    plot(results, finals, out / f"{tag}.png")
    print(f"wrote {out / (tag + '.json.gz')}, {out / (tag + '.png')}; BIPI better: {results.get('bipi_better')}")


if __name__ == "__main__":
    main()
