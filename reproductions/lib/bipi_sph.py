"""BIPI's downstream tests in LAMMPS (issue 17 item 4): hydrostatic tanks (a wedge, a coral) and the elliptic drop.

    python reproductions/lib/bipi_sph.py --case wedge --out reproductions/bipi-fig13-14/results [--dx 0.02]
    python reproductions/lib/bipi_sph.py --case coral --out reproductions/bipi-fig15-18/results [--dx 0.02] [--walls packed]
    python reproductions/lib/bipi_sph.py --case drop --out reproductions/bipi-fig22/results [--dx 0.02]
    python reproductions/lib/bipi_sph.py --case wedge ... --fixed 10_10 100_100 [--walls packed]

(``--out`` defaults to those folders.)

Geometry (Boregowda & Liu, Sec. 4.2.1, after Ferrand et al. 2013): a tank 2.05 m wide, water 0.5 m
deep, a wedge of height sqrt(2)/8 m on the floor. The paper gives no more; we take a symmetric
90-degree wedge (sides at 45 degrees, base sqrt(2)/4 m) centred on the floor. rho0 = 1000 kg/m^3,
g = 9.81 m/s^2. The water region (floor, wedge, side walls and the free surface as its top edge) is
the packing domain; h_B / dx = 2 (support h = 4 dx) for the packing and, unless ``--sph-h`` gives
another support (in units of dx), for the SPH run.

Starts (each given the same wall particles: :func:`ase_sphrelax.drivers.bipi_packer.add_walls`,
ceil(h/dx) layers of the Step-1 grid outside the floor, wedge and side walls, plus the cell centres
the fill dropped within dx/8 of the boundary (so every wall is 1 dx from the Cartesian fluid; at
dx = 0.02 the tank's right wall passes through a column of centres), none above the water surface):

* ``cartesian``: Step 1 only (cell centres, none within dx/8 of the boundary);
* ``bipi``: BIPIPacker with the 1 % rules (window 10, caps 5000 / 1000);
* ``fan``: the same Step-1 particles relaxed by Fan's Eq. 2.4 (FanCalculator with the polygon's
  level set, ``make_optimizer("fan")``, c = 0.01, 2000 steps, as in reproductions/bipi-vs-fan/run.py).

SPH run: :func:`lammps_io.hydrostatic_tank` (Tait water, c0 = 10 sqrt(g H), Monaghan alpha = 0.5
(``--alpha``; with 0.1 every start, and a flat tank without the wedge, went unstable within 1 s),
continuity densities, hydrostatic densities at t = 0, Lucy kernel of support h). The physical time
is ``--t-end``; by default it is chosen from a measured short run so that one case takes about
``--budget`` seconds of wall time (capped at the paper's 20 s); the output says which.

Writes ``wedge_dx{dx}.json.gz`` (gzipped JSON; per start: packing metrics, KE(t), pressure against depth, the
pressure error) and ``wedge_dx{dx}.png`` (KE(t) on a log scale; p against depth with rho0 g d).

``--fixed N2A_N2C ...`` adds BIPI starts with exactly N2A Step-2a and N2C Step-2c iterations (the
paper's Fig. 18 study; the 1 % rules off). ``--walls packed`` replaces the grid walls by one BIPI
packing of the wall band (:mod:`ase_sphrelax.drivers.bipi_walls`), the same for every start.

``--case coral`` (item 4 b, our own complex tank, like the paper's coral): a trapezoidal tank
(floor 1.4 m, sides leaning out to 1.9 m at the surface, water 0.5 m deep) with a branching obstacle
on its floor whose branches are 2.5 dx thick with round tips of radius 1.25 dx (:func:`coral_tank`);
the same starts, walls and run as the wedge. Both tanks also write ``{tag}_particles.png``.

``--case drop`` (item 4 c, the paper's Fig. 22): the circle of ../shared/geometries/EllipticDrop.edges
(R = 0.5 m, 3142 edges), v = (A0 x, -A0 y) with A0 = 100 1/s, run to A0 t = 2 by
:func:`lammps_io.elliptic_drop` (continuity densities, alpha = 0.02, c0 = 14 A0 R, no walls) from
the same three starts; the semi-axes from the particles' second moments (a = 2 sqrt(<x^2>)) against
the analytic ones (Monaghan's ODE). Writes ``drop_dx{dx}.json.gz`` and ``drop_dx{dx}.png``.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # BLAS threads collapse under contention here (FACTS.md)
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # reproductions/, for lib
from lib.results_io import write_json  # noqa: E402

WIDTH, DEPTH, WEDGE_HEIGHT = 2.05, 0.5, math.sqrt(2.0) / 8.0
RHO0, G = 1000.0, 9.81
H_OVER_DX = 4.0  # support; the paper's h_B / dx_r = 2
STARTS = ("cartesian", "bipi", "fan")
CORAL_DEPTH, CORAL_RADIUS_DX = 0.5, 1.25
ZOOM = dict(wedge=(0.75, 1.3, -0.1, 0.3), coral=(0.6, 1.35, -0.1, 0.45))  # particle figures
T_PAPER = 20.0
GEOMETRIES = Path(__file__).resolve().parents[3] / "shared" / "geometries"


def wedge_tank(width=WIDTH, depth=DEPTH, wedge_height=WEDGE_HEIGHT):
    """The water region as BoundarySegments: floor with a symmetric 90-degree wedge, walls, surface."""
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.domains import Polygon

    c, b = 0.5 * width, wedge_height  # half base = height for 45-degree sides
    loop = [[0.0, 0.0], [c - b, 0.0], [c, wedge_height], [c + b, 0.0], [width, 0.0], [width, depth], [0.0, depth]]
    return BoundarySegments.from_polygon(Polygon([loop]))


def coral_tank(dx=0.02):
    """Case (b): a trapezoidal tank with a branching obstacle ("coral") on its floor, as BoundarySegments.

    Tank: floor 1.4 m (x from 0.3 to 1.7), sides leaning out to x = 0.05 and 1.95 at the water
    surface y = 0.5 m. Coral: the union of round-capped branches (shapely ``buffer`` of a tree of
    line segments) of radius 1.25 dx, so its tips have curvature radius 1.25 dx and the forks
    concave corners; its trunk is rooted in the floor. The water is tank minus coral.
    """
    import shapely

    from ase_sphrelax.boundary import BoundarySegments

    tank = shapely.Polygon([(0.3, 0.0), (1.7, 0.0), (1.95, CORAL_DEPTH), (0.05, CORAL_DEPTH)])
    r = CORAL_RADIUS_DX * dx
    branches = [[(1.0, -0.1), (1.0, 0.12)], [(1.0, 0.12), (0.86, 0.24)], [(1.0, 0.12), (1.13, 0.27)],
                [(0.86, 0.24), (0.78, 0.31)], [(0.86, 0.24), (0.90, 0.34)], [(1.13, 0.27), (1.10, 0.37)],
                [(1.13, 0.27), (1.24, 0.33)], [(1.0, 0.05), (1.12, 0.10)], [(0.78, 0.31), (0.70, 0.30)]]
    coral = shapely.union_all([shapely.LineString(b).buffer(r, quad_segs=8) for b in branches])
    water = tank.difference(coral)
    return BoundarySegments.from_shapely(water, name="coral tank")


def make_start(name, boundary, dx, h, fill):
    """The fluid particles of one start and what it cost.

    ``name``: ``cartesian``, ``bipi``, ``fan`` (Fan's level-set wall term), ``fan_default`` (the default term)
    or ``bipi_fixed_N2A_N2C`` (BIPI with exactly N2A
    Step-2a and N2C Step-2c iterations: the 1 % rules switched off by ``tol = 1e-12``; Fig. 18)."""
    from ase_sphrelax import BIPICalculator, FanCalculator
    from ase_sphrelax.drivers import make_optimizer
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker

    atoms = fill.copy()
    t = time.perf_counter()
    info = {}
    if name == "bipi" or name.startswith("bipi_fixed_"):
        fixed = {}
        if name != "bipi":
            n2a, n2c = (int(v) for v in name.split("_")[2:4])
            fixed = dict(max_steps_2a=n2a, max_steps_2c=n2c, tol=1e-12)
        packer = BIPIPacker(atoms, BIPICalculator(h=h, dx=dx, boundary=boundary), **fixed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            packer.run()
        converged, reason = packer.verdict()
        s = packer.summary()
        info = dict(iterations_2a=s["iterations_2a"], iterations_2c=s["iterations_2c"], converged=converged,
                    reason=reason, gradc_avg_final=float(packer.final_gradc_avg()))
    elif name in ("fan", "fan_default"):
        # "fan": Fan's level-set term, as the stored results used; "fan_default": the package's default boundary
        # term (issue 33: the exact-integral continuum with its contact core for a polygon)
        term = "level_set" if name == "fan" else "auto"
        atoms.calc = FanCalculator(h=h, dx=dx, domain=boundary.domain, boundary_term=term)
        opt = make_optimizer("fan", atoms)
        opt.run(fmax=0.0, steps=2000)
        info = dict(iterations=opt.nsteps)
    atoms.set_constraint()
    atoms.calc = None
    info["wall_time_s"] = time.perf_counter() - t
    info["n_outside"] = int((boundary.domain.phi(atoms.positions[:, :2]) >= 0).sum())
    info["boundary_distance_min_dx"] = float(-boundary.domain.phi(atoms.positions[:, :2]).max() / dx)
    return atoms, info


def with_walls(atoms, boundary, dx, h, depth, walls=None):
    """Fluid + wall particles below the surface: the Step-1 grid's (default) or the given ``walls``."""
    from ase_sphrelax.drivers.bipi_packer import add_walls

    return add_walls(atoms, boundary, dx, h=h, keep=lambda r: r[:, 1] < depth, walls=walls)


def packed_walls(boundary, dx, h, depth):
    """One BIPI packing of the wall band below the surface (drivers/bipi_walls.py) and its layer offsets."""
    import shapely

    from ase_sphrelax.drivers.bipi_walls import packed_wall_particles

    t = time.perf_counter()
    walls = packed_wall_particles(boundary, dx, h=h, clip=shapely.box(-1e3, -1e3, 1e3, depth))
    r = walls.positions[:, :2]
    phi, n = boundary.domain.phi_and_normal(r)
    foot = r - phi[:, None] * n[:, :2]
    corners = np.concatenate(boundary.loops)
    k = walls.info["wall_layers"]
    straight = np.linalg.norm(foot[:, None, :] - corners[None, :, :], axis=2).min(axis=1) > (k + 1) * dx
    off = phi[straight] / dx
    layer = np.clip(np.floor(off).astype(int), 0, k - 1)
    info = dict(mode="packed", n=len(walls), layers=k, wall_time_s=time.perf_counter() - t,
                converged=walls.info["wall_converged"], reason=walls.info["wall_reason"],
                iterations_2a=walls.info["wall_iterations_2a"], iterations_2c=walls.info["wall_iterations_2c"],
                phi_min_dx=float(phi.min() / dx), phi_max_dx=float(phi.max() / dx),
                layer_mean_dx=[float(off[layer == j].mean()) for j in range(k)],
                layer_std_dx=[float(off[layer == j].std()) for j in range(k)],
                layer_count=[int((layer == j).sum()) for j in range(k)],
                note="layers: wall particles whose closest wall point is over (k + 1) dx from every vertex")
    return walls, info


def wall_summary(both, boundary, dx):
    t = both.arrays["type"]
    phi = boundary.domain.phi(both.positions[t == 2, :2])
    return dict(mode="grid", n=int((t == 2).sum()), layers=both.info["wall_layers"], phi_min_dx=float(phi.min() / dx),
                phi_max_dx=float(phi.max() / dx))


def start_names(args):
    return list(args.starts) + [f"bipi_fixed_{n}" for n in args.fixed]


def run_case(args):
    from ase_sphrelax.drivers.bipi_packer import initial_fill
    from lammps_io import hydrostatic_tank

    dx = args.dx
    h = H_OVER_DX * dx
    h_sph = (args.sph_h or H_OVER_DX) * dx
    case = args.case
    boundary, depth = (wedge_tank(), DEPTH) if case == "wedge" else (coral_tank(dx), CORAL_DEPTH)
    fill = initial_fill(boundary, dx)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tag = (f"{case}_dx{dx:g}_alpha{args.alpha:g}" + ("" if args.sph_h is None else f"_sphh{args.sph_h:g}")
           + ("_packedwalls" if args.walls == "packed" else "") + ("_fig18" if args.fixed else "") + args.tag)
    print(f"{case} tank: dx = {dx:g} m, h = {H_OVER_DX:g} dx = {h:g} m (support) for the packing, "
          f"{h_sph / dx:g} dx in LAMMPS, {len(fill)} fluid particles, {args.walls} walls", flush=True)
    walls, walls_info = (packed_walls(boundary, dx, h, depth) if args.walls == "packed" else (None, None))
    if walls_info:
        print(f"  packed walls: {walls_info}", flush=True)
    starts = {}
    for name in start_names(args):
        atoms, info = make_start(name, boundary, dx, h, fill)
        starts[name] = (with_walls(atoms, boundary, dx, h, depth, walls=walls), info)
        print(f"  start {name}: {info}", flush=True)
    if walls_info is None:
        walls_info = wall_summary(next(iter(starts.values()))[0], boundary, dx)
    plot_particles({n: a for n, (a, _) in starts.items()}, boundary, out / f"{tag}_particles.png",
                   zoom=ZOOM[case], title=f"{case} tank, dx = {dx:g} m, {args.walls} walls")
    first = next(iter(starts.values()))[0]
    run_kw = dict(rho0=RHO0, g=G, alpha=args.alpha, samples=args.samples, nthreads=args.threads, progress=True)
    if args.t_end is None:
        probe_t = 0.05
        t = time.perf_counter()
        probe = hydrostatic_tank(first, h_sph, dx, t_end=probe_t, **dict(run_kw, samples=5))
        per_step = (time.perf_counter() - t) / probe["steps"]
        t_end = min(T_PAPER, round(args.budget / per_step * probe["dt"], 2))
        how = (f"chosen from a probe run ({probe['steps']} steps, {per_step * 1e3:.2f} ms/step, dt = "
               f"{probe['dt']:.3g} s) for about {args.budget:g} s of wall time per case, capped at the paper's {T_PAPER:g} s")
    else:
        t_end, how = args.t_end, "given by --t-end"
    print(f"physical time per case: {t_end:g} s ({how})", flush=True)
    geometry = (dict(width=WIDTH, wedge_height=WEDGE_HEIGHT) if case == "wedge" else
                dict(coral_radius_dx=CORAL_RADIUS_DX, n_segments=len(boundary), area=boundary.area))
    results = dict(case=case, dx=dx, h=h, h_over_dx=H_OVER_DX, h_sph=h_sph, depth=depth, **geometry,
                   rho0=RHO0, g=G, alpha=args.alpha, t_end=t_end, t_end_how=how, paper_t_end=T_PAPER,
                   walls=walls_info, command=" ".join([Path(sys.argv[0]).as_posix()] + sys.argv[1:]), starts={})
    for name, (atoms, info) in starts.items():
        t = time.perf_counter()
        r = hydrostatic_tank(atoms, h_sph, dx, t_end=t_end, **run_kw)
        wall = time.perf_counter() - t
        ke = np.array(r["ke_history"])
        row = dict(start=info, n_fluid=r["n_fluid"], n_wall=r["n_wall"], steps=r["steps"], dt=r["dt"], c0=r["c0"],
                   wall_time_s=wall, ke_history=r["ke_history"], ke_final=r["ke_final"], ke_max=r["ke_max"],
                   ke_mean_second_half=float(ke[ke[:, 0] >= 0.5 * t_end, 1].mean()),
                   pressure_profile=r["pressure_profile"], pressure_error=r["pressure_error"], max_drop=r["max_drop"])
        results["starts"][name] = row
        print(f"  {name}: KE max {r['ke_max']:.3e} J, final {r['ke_final']:.3e} J, mean over the second half "
              f"{row['ke_mean_second_half']:.3e} J; pressure error {100 * r['pressure_error']:.2f} % of rho0 g H; "
              f"max drop {r['max_drop']:.2f} dx; {r['steps']} steps in {wall:.0f} s", flush=True)
        write_json(out / f"{tag}.json.gz", results)
    return finish(results, out, tag, plot)


def finish(results, out, tag, plotter):
    """Write the results JSON and the figure; say where."""
    write_json(out / f"{tag}.json.gz", results)
    plotter(results, out / f"{tag}.png")
    print(f"wrote {out / (tag + '.json.gz')}, {out / (tag + '.png')}")
    return results


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def run_drop(args):
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.drivers.bipi_packer import initial_fill
    from lammps_io import elliptic_drop

    dx, a0 = args.dx, 100.0
    h = H_OVER_DX * dx
    boundary = BoundarySegments.from_edges(GEOMETRIES / "EllipticDrop.edges")
    fill = initial_fill(boundary, dx)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tag = f"drop_dx{dx:g}"
    t_end = 2.0 / a0
    print(f"elliptic drop: R = 0.5 m, dx = {dx:g} m, h = {H_OVER_DX:g} dx (support), {len(fill)} particles, "
          f"A0 = {a0:g} 1/s, t_end = {t_end:g} s (A0 t = 2)", flush=True)
    results = dict(case="drop", dx=dx, h=h, h_over_dx=H_OVER_DX, a0=a0, t_end=t_end, alpha=args.alpha,
                   command=" ".join([Path(sys.argv[0]).as_posix()] + sys.argv[1:]), starts={})
    for name in args.starts:
        atoms, info = make_start(name, boundary, dx, h, fill)
        t = time.perf_counter()
        r = elliptic_drop(atoms, h, dx, a0=a0, t_end=t_end, alpha=args.alpha, samples=args.samples // 5 or 1,
                          center=(0.0, 0.0),
                          nthreads=args.threads, progress=True)
        last = r["history"][-1]
        row = dict(start=info, n=r["n"], steps=r["steps"], dt=r["dt"], c0=r["c0"], radius=r["radius"],
                   wall_time_s=time.perf_counter() - t, history=r["history"], axis_error=r["axis_error"],
                   a_final=last["a_moment"], b_final=last["b_moment"], a_exact=last["a_exact"],
                   b_exact=last["b_exact"], b_error_final=abs(last["b_moment"] - last["b_exact"]) / r["radius"])
        results["starts"][name] = row
        print(f"  {name}: {info}\n    a = {last['a_moment']:.4f} (exact {last['a_exact']:.4f}), b = "
              f"{last['b_moment']:.4f} (exact {last['b_exact']:.4f}) at A0 t = 2; max |a - a_exact| / R = "
              f"{r['axis_error']:.4f}; {r['steps']} steps", flush=True)
        write_json(out / f"{tag}.json.gz", results)
    return finish(results, out, tag, plot_drop)


def plot_drop(results, path):
    plt = pyplot()
    fig, (ax, ax_err) = plt.subplots(1, 2, figsize=(11, 4.2))
    for k, (name, row) in enumerate(results["starts"].items()):
        hist = row["history"]
        at = np.array([results["a0"] * r["time"] for r in hist])
        a = np.array([r["a_moment"] for r in hist])
        b = np.array([r["b_moment"] for r in hist])
        ax.plot(at, a, "-", color=f"C{k}", label=f"{name} a")
        ax.plot(at, b, "--", color=f"C{k}", label=f"{name} b")
        a_ex = np.array([r["a_exact"] for r in hist])
        b_ex = np.array([r["b_exact"] for r in hist])
        ax_err.plot(at, (a - a_ex) / row["radius"], "-", color=f"C{k}", label=f"{name} a")
        ax_err.plot(at, (b - b_ex) / row["radius"], "--", color=f"C{k}", label=f"{name} b")
    ax.plot(at, a_ex, "k:", label="analytic")
    ax.plot(at, b_ex, "k:")
    ax.set(xlabel="A0 t", ylabel="semi-axis (m)", title=f"elliptic drop, dx = {results['dx']:g} m")
    ax_err.set(xlabel="A0 t", ylabel="(SPH - analytic) / R", title="semi-axis error")
    ax.legend(fontsize=7)
    ax_err.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_particles(starts, boundary, path, zoom, title):
    """The starts side by side around ``zoom`` = (x0, x1, y0, y1): fluid dots, wall crosses, the boundary."""
    plt = pyplot()
    cols = min(3, len(starts))
    rows = -(-len(starts) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    for ax in axes.ravel()[len(starts):]:
        ax.set_axis_off()
    for ax, (name, atoms) in zip(axes.ravel(), starts.items()):
        t = atoms.arrays["type"]
        r = atoms.positions
        for v in boundary.loops:
            w = np.vstack([v, v[:1]])
            ax.plot(w[:, 0], w[:, 1], "k-", lw=0.6)
        ax.plot(r[t == 1, 0], r[t == 1, 1], ".", ms=2.5, color="C0")
        ax.plot(r[t == 2, 0], r[t == 2, 1], "x", ms=2.5, color="C3")
        ax.set(xlim=zoom[:2], ylim=zoom[2:], aspect="equal", title=name)
        ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def plot(results, path):
    plt = pyplot()
    fig, (ax_ke, ax_p) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, row in results["starts"].items():
        ke = np.array(row["ke_history"])
        ax_ke.semilogy(ke[1:, 0], ke[1:, 1], label=name)
        p = np.array(row["pressure_profile"])
        ax_p.plot(p[:, 1] / 1e3, p[:, 0], "o-", ms=3, label=f"{name} ({100 * row['pressure_error']:.2f} %)")
    d = np.linspace(0, results["depth"], 20)
    ax_p.plot(results["rho0"] * results["g"] * d / 1e3, d, "k--", label=r"$\rho_0 g d$")
    ax_p.invert_yaxis()
    ax_ke.set(xlabel="t (s)", ylabel="kinetic energy (J per m)",
              title=f"{results['case']} tank, {results['walls']['mode']} walls, dx = {results['dx']:g} m, SPH support "
                    f"{results.get('h_sph', results['h']) / results['dx']:g} dx")
    ax_p.set(xlabel="p (kPa)", ylabel="depth d (m)", title=f"pressure at t = {results['t_end']:g} s")
    ax_ke.legend(fontsize=7)
    ax_p.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


OUT_DIRS = {"wedge": "bipi-fig13-14", "coral": "bipi-fig15-18", "drop": "bipi-fig22"}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", choices=("wedge", "coral", "drop"), default="wedge")
    parser.add_argument("--out", default=None, help="default reproductions/bipi-fig13-14/results (wedge), "
                        "bipi-fig15-18/results (coral), bipi-fig22/results (drop)")
    parser.add_argument("--dx", type=float, default=0.02)
    parser.add_argument("--starts", nargs="*", default=list(STARTS), choices=STARTS)
    parser.add_argument("--t-end", type=float, default=None, help="physical time (default: from --budget)")
    parser.add_argument("--budget", type=float, default=200.0, help="wall seconds per case for the default t_end")
    parser.add_argument("--sph-h", type=float, default=None,
                        help="wedge: support of the LAMMPS run in units of dx (default the packing's 4)")
    parser.add_argument("--alpha", type=float, default=None,
                        help="Monaghan's artificial viscosity (default 0.5 for the tanks, 0.02 for the drop)")
    parser.add_argument("--fixed", nargs="*", default=[], metavar="N2A_N2C",
                        help="tanks: also BIPI starts with exactly N2A Step-2a and N2C Step-2c iterations (Fig. 18), "
                             "e.g. 10_10 100_50")
    parser.add_argument("--walls", choices=("grid", "packed"), default="grid",
                        help="tanks: wall particles on the Step-1 grid (default) or BIPI-packed in the wall band "
                             "(one packing for every start)")
    parser.add_argument("--tag", default="", help="suffix of the output names")
    parser.add_argument("--samples", type=int, default=200, help="KE samples")
    parser.add_argument("--threads", type=int, default=1, help="OpenMP threads of LAMMPS")
    args = parser.parse_args(argv)
    if not (args.dx > 0):
        parser.error(f"--dx must be positive, got {args.dx}")
    if args.out is None:
        args.out = "reproductions/" + OUT_DIRS[args.case] + "/results"
    if args.alpha is None:
        args.alpha = 0.02 if args.case == "drop" else 0.5
    if args.case == "drop" and not GEOMETRIES.is_dir():
        sys.exit(f"{GEOMETRIES} not found")
    for spec in args.fixed:
        parts = spec.split("_")
        if len(parts) != 2 or not all(p.isdigit() and int(p) >= 1 for p in parts):
            parser.error(f"--fixed: give N2A_N2C with integers >= 1 (e.g. 100_50), got {spec!r}")
    (run_drop if args.case == "drop" else run_case)(args)


if __name__ == "__main__":
    main()


def add_bisph_options(parser, start=True):
    """The BISPH options the tank comparisons share: ``--eq21``, ``--segment-ratio`` and (``start``) ``--start``."""
    parser.add_argument("--eq21", choices=("pointwise", "segment"), default="pointwise",
                        help="Eq. 21 pointwise along the wall (default) or at each segment's nearest point")
    parser.add_argument("--segment-ratio", type=float, default=None,
                        help="split the walls into segments of at most dx / RATIO (BIPI2D: 10; default: one per side)")
    if start:
        parser.add_argument("--start", choices=("cartesian", "bipi"), default=None,
                            help="run one start only (two processes in parallel), merged into summary{tag}.json "
                                 "and ke{tag}.json.gz under a lock")


def add_start_ratios(summary):
    """Cartesian/BIPI ratios of the run-averaged and the final KE into ``summary`` when both starts ran; returns
    whether they did."""
    runs = summary["runs"]
    if not {"cartesian", "bipi"} <= set(runs):
        return False
    summary["ke_mean_ratio_cartesian_over_bipi"] = runs["cartesian"]["ke_mean"] / runs["bipi"]["ke_mean"]
    summary["ke_final_ratio_cartesian_over_bipi"] = runs["cartesian"]["ke_final"] / runs["bipi"]["ke_final"]
    return True
