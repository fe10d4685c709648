"""BIPI on the paper's geometries (Boregowda & Liu 2025, Figs. 8-12): packings, figures and one table.

    python reproductions/bipi-table/run.py --out reproductions/bipi-table/results

Cases (``../shared/geometries``; every case starts from Step 1, one particle per cell centre,
BIPI2D's stopping rules: 1 % change of TPD_avg in 2a and of |grad C|_avg in 2c over a window of
10 iterations, caps 5000 and 1000):

* the trapezoid at dx_r = 0.01, 0.02, 0.04 with h_B / dx_r = 2 (Fig. 8);
* the trapezoid at h_B / dx_r = 1.2, 1.7, 2, 2.5, 3 with dx_r = 0.02 (Fig. 9);
* the Stanford 2D bunny (mm), the NACA 6412 airfoil solid and the fluid box with the airfoil as a
  hole (inch) (Figs. 11-12);
* 3D, beyond the paper: a sphere of radius 0.5 (``Sphere.to_mesh(3)``, 1280 triangles) and two closed
  STL files written with trimesh and read back: a unit cube and an icosphere (radius 0.5, 320 triangles).

Writes ``table.md``/``table.csv``/``results.json`` (both conventions: our support h and the paper's
h_B = h / 2), per case ``<case>_history.json.gz`` and ``<case>_start.png``/``<case>_packed.png``
(particles coloured by log10 h |grad C_a|, like Figs. 10-12), and ``fig8_dx.png``, ``fig9_h.png``,
``fig11_12_shapes.png`` (TPD_avg and |grad C|_avg against the iteration). ``--cases`` runs a subset,
``--quick`` caps both stages at 100 iterations (a smoke test), ``--table-only`` rebuilds the table and figures.
``∇C avg`` is |grad C|_avg over the unfrozen particles, in 1/length of the geometry's units.
"""
from __future__ import annotations

import argparse
import csv
import gzip
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

GEOMETRIES = Path(__file__).resolve().parents[3] / "shared" / "geometries"

CASES = {
    "trapezoid_dx0.01": ("TrapezoidalTank", 0.01, 2.0),
    "trapezoid_dx0.02": ("TrapezoidalTank", 0.02, 2.0),
    "trapezoid_dx0.04": ("TrapezoidalTank", 0.04, 2.0),
    "trapezoid_hb1.2": ("TrapezoidalTank", 0.02, 1.2),
    "trapezoid_hb1.7": ("TrapezoidalTank", 0.02, 1.7),
    "trapezoid_hb2.5": ("TrapezoidalTank", 0.02, 2.5),
    "trapezoid_hb3": ("TrapezoidalTank", 0.02, 3.0),
    "bunny": ("Standford2DBunny", 1.0, 2.0),
    "airfoil_solid": ("AirFoilSolid", 0.05, 2.0),
    "airfoil_fluid": ("AirFoilFluid", 0.25, 2.0),
    "sphere_3d": ("sphere", 0.05, 2.0),
    "cube_stl_3d": ("cube.stl", 0.0625, 2.0),
    "icosphere_stl_3d": ("icosphere.stl", 0.05, 2.0),
}
GROUPS = {
    "fig8_dx.png": ("trapezoid, h_B/dx_r = 2 (Fig. 8)", ["trapezoid_dx0.01", "trapezoid_dx0.02", "trapezoid_dx0.04"]),
    "fig9_h.png": ("trapezoid, dx_r = 0.02 (Fig. 9)", ["trapezoid_hb1.2", "trapezoid_hb1.7", "trapezoid_dx0.02",
                                                        "trapezoid_hb2.5", "trapezoid_hb3"]),
    "fig11_12_shapes.png": ("bunny and airfoils (Figs. 11-12)", ["bunny", "airfoil_solid", "airfoil_fluid"]),
    "fig_3d.png": ("3D: sphere, STL cube and icosphere", ["sphere_3d", "cube_stl_3d", "icosphere_stl_3d"]),
}
COLUMNS = ["case", "geometry", "dx", "h_B/dx (paper)", "h/dx (support)", "N", "it 2a", "it 2c", "frozen",
           "TPD_avg 2a", "∇C avg 2c start", "∇C avg end", "drop (orders)", "layer mean d/dx",
           "layer min d/dx", "outside", "wall time s"]


def compact_history(history):
    """History as columns, 4 significant digits."""
    keys = ["stage", "iteration", "tpd_avg", "gradc_avg", "n_pack", "n_selected", "rejected", "time"]
    out = {k: [r[k] for r in history] for k in keys}
    for k in ("tpd_avg", "gradc_avg", "time"):
        out[k] = [float(f"{v:.4g}") for v in out[k]]
    return out


def load_boundary(geometry, out):
    """An edge file of ../shared/geometries, or a 3D shape (the STL files are written into ``out``)."""
    import trimesh

    from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles
    from ase_sphrelax.domains import Sphere

    if geometry == "sphere":
        return BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(3))
    if geometry.endswith(".stl"):
        mesh = (trimesh.creation.box(extents=(1.0, 1.0, 1.0)) if geometry == "cube.stl"
                else trimesh.creation.icosphere(subdivisions=2, radius=0.5))
        mesh.export(out / geometry)
        return BoundaryTriangles.from_file(out / geometry)
    return BoundarySegments.from_edges(GEOMETRIES / f"{geometry}.edges")


def run_case(name, out, quick):
    from ase_sphrelax.analysis.bipi import pack_summary
    from ase_sphrelax.drivers.bipi_packer import pack
    from ase_sphrelax.plotting import plot_concentration_gradient as plot_gradient

    geometry, dx, ratio = CASES[name]
    boundary = load_boundary(geometry, out)
    caps = dict(max_steps_2a=100, max_steps_2c=100) if quick else {}
    t = time.perf_counter()
    atoms, packer, start = pack(boundary, dx, h_over_dx_paper=ratio, progress=True, **caps)
    wall = time.perf_counter() - t
    summary = pack_summary(atoms, packer)
    summary.update(case=name, geometry=geometry, total_wall_time=wall)
    with gzip.open(out / f"{name}_history.json.gz", "wt") as fh:
        fh.write(json.dumps(dict(summary=summary, parameters=packer.todict(), history=compact_history(packer.history))))
    label = f"{geometry}, dx={dx:g}, h_B/dx={ratio:g} (h={summary['h_over_dx']:g} dx)"
    plot_gradient(start, packer.calc, out / f"{name}_start.png", title=f"start: {label}")
    plot_gradient(atoms, packer.calc, out / f"{name}_packed.png",
                  title=f"packed: {label}; 2a {summary['iterations_2a']}, 2c {summary['iterations_2c']} iterations")
    return summary


def table_row(s):
    return [s["case"], s["geometry"], f"{s['dx']:g}", f"{s['h_over_dx_paper']:g}", f"{s['h_over_dx']:g}",
            s["n_particles"], s["iterations_2a"], s["iterations_2c"], s["n_frozen"], f"{s.get('tpd_avg_2a', np.nan):.3g}",
            f"{s.get('gradc_avg_2c_first', np.nan):.3g}", f"{s['gradc_avg_final']:.3g}", f"{s['gradc_drop_orders']:.2f}",
            f"{s['boundary_layer_mean']:.3f}", f"{s['boundary_layer_min']:.3f}", s["n_outside"],
            f"{s['total_wall_time']:.1f}"]


def plot_groups(out, summaries):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for fname, (title, names) in GROUPS.items():
        names = [n for n in names if n in summaries]
        if not names:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
        for name in names:
            with gzip.open(out / f"{name}_history.json.gz", "rt") as fh:
                hist = json.loads(fh.read())["history"]
            stage = np.array(hist["stage"])
            it = np.arange(1, len(stage) + 1)
            geometry, dx, ratio = CASES[name]
            label = f"{geometry[:8]} dx={dx:g}, h_B/dx={ratio:g}"
            line, = axes[0].plot(it, hist["tpd_avg"], lw=1, label=label)
            axes[1].semilogy(it, np.maximum(hist["gradc_avg"], 1e-300), lw=1, color=line.get_color(), label=label)
            switch = np.nonzero(stage == "2c")[0]
            if len(switch):
                for ax in axes:
                    ax.axvline(it[switch[0]], color=line.get_color(), lw=0.5, ls=":")
        axes[0].set(xlabel="iteration (2a, then 2c after the dotted line)", ylabel="TPD$_{avg}$ (packable)")
        axes[1].set(xlabel="iteration", ylabel=r"$|\nabla C|_{avg}$ (packable)")
        axes[0].legend(fontsize=7)
        fig.suptitle(title)
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-table/results")
    parser.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    parser.add_argument("--quick", action="store_true", help="cap both stages at 100 iterations")
    parser.add_argument("--table-only", action="store_true", help="rebuild the table and figures from results.json")
    args = parser.parse_args(argv)
    if not GEOMETRIES.is_dir():
        sys.exit(f"{GEOMETRIES} not found: the geometries live in ../shared/geometries beside the checkout")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore", FutureWarning)
    results_path = out / "results.json"
    summaries = json.loads(results_path.read_text()) if results_path.exists() else {}
    for name in [] if args.table_only else args.cases:
        print(f"== {name}", flush=True)
        summaries[name] = run_case(name, out, args.quick)
        results_path.write_text(json.dumps(summaries, indent=1))
        s = summaries[name]
        print(f"   N={s['n_particles']} 2a={s['iterations_2a']} 2c={s['iterations_2c']} drop={s['gradc_drop_orders']:.2f} "
              f"layer={s['boundary_layer_mean']:.3f} outside={s['n_outside']} {s['total_wall_time']:.1f}s", flush=True)
    rows = [table_row(summaries[n]) for n in CASES if n in summaries]
    with open(out / "table.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([COLUMNS] + rows)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(v) for v in row) + " |" for row in rows]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    plot_groups(out, summaries)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
