"""ALARIC paper, Sec. 5.2, Figs. 14-15: a point explosion in LAMMPS from lattice, ALARIC and WVT starts.

    PYTHONPATH=. .venv/bin/python reproductions/alaric-fig14-15/run.py --out reproductions/alaric-fig14-15/results/

Starts (same N, same area per particle, periodic box of area 1, rho = 1):
  square     the square lattice (n x n), the paper's "cubic";
  hexagonal  the hexagonal lattice (n columns x n rows, a box of 1.075 x 0.931), the paper's HCP;
  ALARIC     ALARIC's dynamics (relax_density, log potential, no splitting) from one uniformly random start;
  WVT        WVT (r^-2 weight) from the same random start.
Each runs lammps_io.point_explosion (sph/idealgas, E0 = 1, half spread evenly, half deposited with
Lucy weights over 2h about the particle closest to the box centre, t_end = 0.09). The front is located
per angular bin (32 bins) at the radius of the binned density maximum (and of -div v), and its
relative spread over angle std_k R_k / mean_k R_k is the isotropy measure, against time; the angular
harmonics a_4 and a_6 separate a lattice's preferred directions from noise.

``--checks-only`` writes ``checks.json``: the energy error against the Courant factor and the deposits that
fail in LAMMPS. Otherwise writes ``results.json.gz``, ``fig14.png`` (density and -div v at t_end), ``fig15.png`` (radial projections
and the spread against time), ``README.md``, and caches the relaxed starts in ``starts/`` (not committed).
"""
from __future__ import annotations

import argparse
import gzip
import json
import os
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from ase import Atoms  # noqa: E402
from ase.io import read, write  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from ase_sphrelax import ALARICCalculator  # noqa: E402
from ase_sphrelax.analysis.shock import angular_modes, shock_isotropy  # noqa: E402
from ase_sphrelax.build import periodic_box  # noqa: E402
from ase_sphrelax.drivers.alaric_dynamics import relax_density  # noqa: E402
from ase_sphrelax.drivers.wvt import WVTRelaxation  # noqa: E402
from lammps_io import point_explosion  # noqa: E402

STARTS = ("square", "hexagonal", "ALARIC", "WVT")
COLOURS = dict(square="tab:blue", hexagonal="tab:orange", ALARIC="tab:green", WVT="tab:red")
MODES = (1, 2, 3, 4, 5, 6, 8, 12)
FIELDS = {"density": "density", "div_v": "-div v"}
ESTIMATORS = {"peak": "peak", "edge": "threshold", "centroid": "centroid"}  # shock_radii's methods
SERIES = [f"{field}/{method}" for field in FIELDS for method in ESTIMATORS]
SETTLED = 0.03  # from here on the front is well outside the deposit (2h = 0.052 at n = 100)


def uniform_density(x):
    return np.ones(len(x))


def random_start(n, seed):
    rng = np.random.default_rng(seed)
    pos = np.zeros((n, 3))
    pos[:, :2] = rng.uniform(0.0, 1.0, (n, 2))
    return Atoms(numbers=np.zeros(n, int), positions=pos, cell=np.eye(3), pbc=(True, True, False))


def clean(atoms):
    """Positions, cell and pbc only, wrapped into the cell."""
    out = Atoms(numbers=np.zeros(len(atoms), int), positions=atoms.positions, cell=atoms.cell, pbc=atoms.pbc)
    out.wrap()
    return out


def start_quality(atoms):
    """ALARIC's epsilon (Eq. 45) of a uniform target and the nearest-neighbour statistics (periodic)."""
    probe = clean(atoms)
    probe.calc = ALARICCalculator(target_density=uniform_density, dim=2, form="log")
    probe.calc.silence_scale_hint()
    probe.get_forces()
    eps = float(probe.calc.results["epsilon"])
    box = np.diag(atoms.cell.array)[:2]
    x = np.mod(atoms.positions[:, :2], box)
    nn = cKDTree(x, boxsize=box).query(x, k=2)[0][:, 1]
    return dict(epsilon=eps, nn_min_over_mean=float(nn.min() / nn.mean()), nn_std_over_mean=float(nn.std() / nn.mean()))


def build_starts(n_side, seed, alaric_steps, wvt_steps, cache):
    cache.mkdir(parents=True, exist_ok=True)
    n = n_side * n_side
    starts = {"square": periodic_box(n_side, dx=1.0 / n_side, dim=2),
              "hexagonal": periodic_box((n_side, n_side), dx=1.0 / n_side, dim=2, lattice="hexagonal")}
    timing = {}
    for name in ("ALARIC", "WVT"):
        path = cache / f"{name}_n{n}_seed{seed}_steps{alaric_steps if name == 'ALARIC' else wvt_steps}.extxyz"
        if path.exists():
            starts[name] = read(path)
            timing[name] = json.loads(path.with_suffix(".json").read_text())
            print(f"{name}: start read from {path}", flush=True)
            continue
        atoms = random_start(n, seed)
        t0 = time.perf_counter()
        if name == "ALARIC":
            res = relax_density(atoms, uniform_density, 2, splits=0, max_steps=alaric_steps, eps_min=0.0,
                                eps_dot_min=0.0, progress=True, form="log")
            atoms = res["atoms"]
            info = dict(steps=int(res["steps"]), wall_s=time.perf_counter() - t0, stop_reason=res["stop_reason"])
        else:
            WVTRelaxation(atoms, uniform_density, 2, steps=wvt_steps, weight="r2").run()
            info = dict(steps=int(wvt_steps), wall_s=time.perf_counter() - t0)
        atoms = clean(atoms)
        write(path, atoms)
        path.with_suffix(".json").write_text(json.dumps(info))
        starts[name] = atoms
        timing[name] = info
        print(f"{name}: {info}", flush=True)
    for name in STARTS:
        assert len(starts[name]) == n, (name, len(starts[name]))
    return starts, timing


def isotropy(result, field, method, n_angles, dr):
    cell = np.diag(result["cell"] + [1.0])
    rows = []
    for snap in result["snapshots"][1:]:
        value = snap["density"] if field == "density" else -snap["div_v"]
        iso = shock_isotropy(snap["positions"], value, result["centre"], cell=cell, pbc=(True, True, False),
                             n_angles=n_angles, method=ESTIMATORS[method], dr=dr, r_max=0.45)
        modes = angular_modes(np.asarray(iso["directions"]), np.asarray(iso["radius_k"]), MODES)
        rows.append(dict(time=snap["time"], mean_radius=iso["mean_radius"], spread=iso["spread"], range=iso["range"],
                         empty_bins=iso["empty_bins"], modes={str(m): a for m, a in modes.items()},
                         radius_k=iso["radius_k"]))
    return rows


def hot_particles(result):
    """The deposit's particles at t_end: where they are, and how far their neighbours keep off (SPH without
    thermal conduction keeps them hot, in low-density bubbles behind the front)."""
    first, last = result["snapshots"][0], result["snapshots"][-1]
    deposit = first["esph"] > result["background"] * result["energy"] / result["n"] * (1 + 1e-9)
    box = np.asarray(result["cell"])
    x = np.mod(last["positions"], box)
    nn = cKDTree(x, boxsize=box).query(x, k=2)[0][:, 1]
    dx = float(np.sqrt(np.prod(box) / result["n"]))
    r = np.hypot(*relative(last, result).T)
    front = float(np.percentile(r[last["density"] > 1.5], 50))
    inner = (r < front) & ~deposit
    return dict(count=int(deposit.sum()), median_radius=float(np.median(r[deposit])), max_radius=float(r[deposit].max()),
                nn_over_dx_deposit=float(np.median(nn[deposit]) / dx), nn_over_dx_other_inside=float(np.median(nn[inner]) / dx),
                density_deposit=float(np.median(last["density"][deposit])),
                density_other_inside=float(np.median(last["density"][inner])),
                esph_ratio=float(np.median(last["esph"][deposit]) / np.median(last["esph"][inner])))


def relative(snap, result):
    d = snap["positions"] - np.asarray(result["centre"])
    box = np.asarray(result["cell"])
    return d - box * np.round(d / box)


def fig14(results, out, t_end):
    fig, axes = plt.subplots(2, len(results), figsize=(4.2 * len(results), 8.2))
    for col, (name, res) in enumerate(results.items()):
        snap = res["snapshots"][-1]
        d = relative(snap, res)
        for row, (value, label, cmap) in enumerate(((snap["density"], "density", "viridis"),
                                                    (-snap["div_v"], "-div v", "magma"))):
            ax = axes[row, col]
            lim = np.percentile(value, [1, 99.9])
            sc = ax.scatter(d[:, 0], d[:, 1], c=value, s=max(0.3, 1.2e4 / len(value)), cmap=cmap, vmin=lim[0],
                            vmax=lim[1], linewidths=0)
            ax.set_aspect("equal")
            ax.set_xlim(-0.4, 0.4)
            ax.set_ylim(-0.4, 0.4)
            ax.set_title(f"{name}: {label}, t = {snap['time']:.3g}")
            fig.colorbar(sc, ax=ax, shrink=0.8)
    fig.suptitle(f"Fig. 14: point explosion in LAMMPS (sph/idealgas), N = {next(iter(results.values()))['n']}, "
                 f"t = {t_end:g}")
    fig.tight_layout()
    fig.savefig(out / "fig14.png", dpi=80)
    plt.close(fig)


def fig15(results, series, out):
    names = list(results)
    fig = plt.figure(figsize=(4.2 * len(names), 8.6))
    grid = fig.add_gridspec(2, 12)
    width = 12 // len(names)
    top = [fig.add_subplot(grid[0, k * width:(k + 1) * width]) for k in range(len(names))]
    for ax, name in zip(top, names):
        res = results[name]
        snap = res["snapshots"][-1]
        r = np.hypot(*relative(snap, res).T)
        ax.scatter(r, snap["density"], s=max(0.2, 0.6e4 / len(r)), color=COLOURS[name], linewidths=0)
        ax.set_xlim(0, 0.45)
        ax.set_xlabel("r")
        ax.set_ylabel("density")
        ax.set_title(f"{name}: radial projection, t = {snap['time']:.3g}")
    bottom = [fig.add_subplot(grid[1, 4 * k:4 * (k + 1)]) for k in range(3)]
    for name in names:
        for ax, key in zip(bottom[:2], ("density/centroid", "density/edge")):
            rows = series[name][key]
            ax.plot([r["time"] for r in rows], [r["spread"] for r in rows], "o-", ms=3, color=COLOURS[name], label=name)
        final = series[name]["density/centroid"][-1]
        theta = (np.arange(len(final["radius_k"])) + 0.5) * 2 * np.pi / len(final["radius_k"])
        bottom[2].plot(np.degrees(theta), final["radius_k"], "o-", ms=3, color=COLOURS[name], label=name)
    for ax, field in zip(bottom[:2], ("density, shell centroid", "density, leading edge")):
        ax.set_xlabel("t")
        ax.set_ylabel("std_k R_k / mean_k R_k")
        ax.set_yscale("log")
        ax.set_title(f"front spread over 32 angles ({field})")
        ax.legend(fontsize=8)
    bottom[2].set_xlabel("angle [deg]")
    bottom[2].set_ylabel("R_k (density, shell centroid)")
    bottom[2].set_title("front radius per angle at t_end")
    bottom[2].legend(fontsize=8)
    fig.suptitle("Fig. 15: radial projection of the density and the front's spread over angle")
    fig.tight_layout()
    fig.savefig(out / "fig15.png", dpi=110)
    plt.close(fig)


def summarise(series, settled):
    rows = {}
    for name, fields in series.items():
        row = {}
        for field, data in fields.items():
            late = [r for r in data if r["time"] >= settled - 1e-12]
            final = data[-1]
            row[field] = dict(final_spread=final["spread"], final_radius=final["mean_radius"],
                              mean_spread_late=float(np.mean([r["spread"] for r in late])),
                              final_a4=final["modes"]["4"], final_a6=final["modes"]["6"],
                              mean_a4_late=float(np.mean([r["modes"]["4"] for r in late])),
                              mean_a6_late=float(np.mean([r["modes"]["6"] for r in late])),
                              mean_other_late=float(np.mean([np.mean([r["modes"][str(m)] for m in MODES if m not in (4, 6)])
                                                             for r in late])))
        rows[name] = row
    return rows


def write_readme(out, args, payload, command):
    s = payload["summary"]
    lines = [
        "# ALARIC paper Figs. 14-15: point explosion in LAMMPS from lattice, ALARIC and WVT starts", "",
        payload["verdict"], "",
        "What these numbers say, at both N: `reproductions/alaric-fig14-15/results/FINDINGS.md`.", "",
        "Command (writes everything here; the relaxed starts are cached in `starts/`, not committed):", "",
        f"    {command}", "",
        f"Set-up: N = {payload['n']} particles in a periodic box of area 1 (hexagonal: "
        f"{payload['cells']['hexagonal'][0]:.4f} x {payload['cells']['hexagonal'][1]:.4f}), rho = 1, "
        f"`lammps_io.point_explosion` (pair_style sph/idealgas, gamma = 1.4, summation density, alpha = "
        f"{args.alpha}, cfl = {args.cfl}), E0 = 1: half spread evenly, half with Lucy weights over 2h "
        f"(h = 2.6 dx) about the particle closest to the box centre; t_end = {args.t_end} (the paper's "
        "Fig. 14 time). The paper puts the central half in one particle: in LAMMPS' sph/idealgas "
        "that drives the neighbours' internal energies negative (`lammps_io/sph_explosion.py`, "
        "`tests/test_lammps_explosion.py`), so the deposit is spread.", "",
        f"Front: per {args.n_angles} angular bins about the central particle (`ase_sphrelax.analysis.shock`), "
        "three estimators of its radius R_k, each on the density and on -div v (LAMMPS' continuity rate "
        f"-drho/rho): `peak`, the radius of the maximum of the field binned in radius ({args.dr_factor} dx "
        "bins, parabola-refined); `edge`, the outermost particle above the level midway between the ambient "
        "field and the bins' maxima; `centroid`, the mean radius weighted by the field above that level "
        "(the middle of the compressed shell). Isotropy measure: std_k R_k / mean_k R_k; a_m: relative "
        "amplitudes of the angular harmonics of R_k (a_4: the square lattice's directions, a_6: the "
        "hexagonal's; noise spreads over every m).", "",
        "## Starts", "",
        "| start | epsilon (Eq. 45) | min NN / mean NN | std NN / mean NN | start-up cost |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name in STARTS:
        q = payload["starts"][name]
        cost = payload["start_cost"].get(name)
        cost_s = f"{cost['steps']} steps, {cost['wall_s']:.0f} s" if cost else "lattice"
        lines.append(f"| {name} | {q['epsilon']:.2e} | {q['nn_min_over_mean']:.3f} | {q['nn_std_over_mean']:.3f} | {cost_s} |")
    lines += ["", "## Explosions", "",
              "| start | LAMMPS steps | wall [s] | max abs energy error | summation density spread at t = 0 |",
              "| --- | --- | --- | --- | --- |"]
    for name in STARTS:
        e = payload["explosions"][name]
        lines.append(f"| {name} | {e['steps']} | {e['wall_time']:.1f} | {e['energy_error_max']:.1e} | "
                     f"{e['rho_spread_t0']:.2e} |")
    lines += ["", "## The deposit's particles at t_end (hot bubbles)", "",
              "LAMMPS' sph/idealgas has no thermal conduction: the particles that received the deposit stay hot and "
              "keep their neighbours off, in low-density bubbles (the ring of holes behind the front in fig14.png); "
              "the same in every start. 'inside': the other particles within the median radius of the "
              "particles denser than 1.5.", "",
              "| start | deposit particles | their median / max radius | their median NN / dx | others inside | "
              "their median density | others inside | esph ratio (deposit / others inside) |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name in STARTS:
        b = payload["explosions"][name]["hot_particles"]
        lines.append(f"| {name} | {b['count']} | {b['median_radius']:.3f} / {b['max_radius']:.3f} | "
                     f"{b['nn_over_dx_deposit']:.2f} | {b['nn_over_dx_other_inside']:.2f} | {b['density_deposit']:.3f} | "
                     f"{b['density_other_inside']:.3f} | {b['esph_ratio']:.1f} |")
    for key in SERIES:
        field, method = key.split("/")
        label = f"{FIELDS[field]}, {method}"
        lines += ["", f"## Front spread over angle ({label})", "",
                  f"| start | R at t_end | spread at t_end | mean spread, t >= {SETTLED} | a_4 (mean, t >= {SETTLED}) | "
                  f"a_6 (mean) | other harmonics (mean) |",
                  "| --- | --- | --- | --- | --- | --- | --- |"]
        for name in STARTS:
            r = s[name][key]
            lines.append(f"| {name} | {r['final_radius']:.4f} | {r['final_spread']:.4f} | {r['mean_spread_late']:.4f} | "
                         f"{r['mean_a4_late']:.4f} | {r['mean_a6_late']:.4f} | {r['mean_other_late']:.4f} |")
    lines += ["", "Every number above is in `results.json.gz` (per start: the start's quality, the explosion's "
              "energy history, and the front per snapshot: radius per angle, spread, range, harmonics).",
              "Figures: `fig14.png` (density and -div v at t_end), `fig15.png` (radial projection of the density "
              "at t_end; spread against time for both fields; R_k against angle at t_end).", ""]
    (out / "README.md").write_text("\n".join(lines))


def verdict(summary):
    """Count the (field, estimator) pairs in which ALARIC's mean late spread is below both lattices'."""
    wins, parts = [], []
    for key in SERIES:
        late = {name: summary[name][key]["mean_spread_late"] for name in STARTS}
        if late["ALARIC"] < min(late["square"], late["hexagonal"]):
            wins.append(key)
        parts.append(f"{key}: ALARIC {late['ALARIC']:.4f}, WVT {late['WVT']:.4f}, square {late['square']:.4f}, "
                     f"hexagonal {late['hexagonal']:.4f}")
    if len(wins) == len(SERIES):
        head = "**ALARIC's start gives a more isotropic front than both lattices by every estimator here**"
    elif wins:
        head = (f"**ALARIC's start gives a more isotropic front than both lattices by {len(wins)} of the "
                f"{len(SERIES)} estimators only** ({', '.join(wins)})")
    else:
        head = "**ALARIC's start does not give a more isotropic front than both lattices by any estimator here**"
    return (f"{head}: mean relative spread of the front radius over the angles for t >= {SETTLED} ("
            + "; ".join(parts) + ").")


def model_checks(out):
    """The measurements behind the model choices: energy error against the Courant factor (40 x 40 square
    lattice) and the deposits that make LAMMPS' energies negative (the paper's one particle; Lucy weights
    over h) against the default over 2h."""
    rows = dict(energy_vs_cfl=[], deposits=[])
    small = periodic_box(40, dx=1 / 40, dim=2)
    for cfl in (0.2, 0.1, 0.05, 0.025):
        res = point_explosion(small, cfl=cfl, snapshots=1, progress=False)
        rows["energy_vs_cfl"].append(dict(n=40 * 40, cfl=cfl, steps=res["steps"], energy_error_max=res["energy_error_max"],
                                          energy_error_final=res["history"][-1]["energy_error"]))
        print(rows["energy_vs_cfl"][-1], flush=True)
    lattice = periodic_box(100, dx=0.01, dim=2)
    h = 2.6 * 0.01
    cases = [(40, dict(deposit="particle")), (100, dict(deposit="particle")), (100, dict(deposit_radius=h)),
             (100, dict(deposit_radius=h, cfl=0.025)), (100, dict()), (100, dict(deposit_radius=3 * h))]
    for n_side, kwargs in cases:
        atoms = small if n_side == 40 else lattice
        row = dict(n=n_side * n_side, **{k: v for k, v in kwargs.items()})
        try:
            res = point_explosion(atoms, snapshots=1, progress=False, **kwargs)
            row.update(ok=True, t_reached=res["t_end"], steps=res["steps"], deposit_count=res["deposit_count"],
                       energy_error_max=res["energy_error_max"])
        except RuntimeError as err:
            row.update(ok=False, error=str(err))
        rows["deposits"].append(row)
        print(row, flush=True)
    (out / "checks.json").write_text(json.dumps(rows, indent=1))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="reproductions/alaric-fig14-15/results/")
    parser.add_argument("--n-side", type=int, default=100, help="N = n_side^2 (even); the paper used about 40K")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--alaric-steps", type=int, default=300)
    parser.add_argument("--wvt-steps", type=int, default=1000)
    parser.add_argument("--t-end", type=float, default=0.09)
    parser.add_argument("--snapshots", type=int, default=18)
    parser.add_argument("--cfl", type=float, default=0.1)
    parser.add_argument("--alpha", type=float, default=1.0)
    parser.add_argument("--n-angles", type=int, default=32)
    parser.add_argument("--dr-factor", type=float, default=1.5, help="radial bin width in particle spacings")
    parser.add_argument("--checks-only", action="store_true",
                        help="only the model checks (energy against cfl, the failing deposits): checks.json")
    args = parser.parse_args()
    if args.n_side < 10 or args.n_side % 2:
        parser.error(f"--n-side must be an even integer >= 10, got {args.n_side}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / ".gitignore").write_text("starts/\n")
    if args.checks_only:
        model_checks(out)
        return
    load = [os.getloadavg()]
    starts, cost = build_starts(args.n_side, args.seed, args.alaric_steps, args.wvt_steps, out / "starts")
    dx = 1.0 / args.n_side
    results, series, explosions, quality = {}, {}, {}, {}
    for name in STARTS:
        quality[name] = start_quality(starts[name])
        print(f"{name}: start {quality[name]}", flush=True)
        res = point_explosion(starts[name], t_end=args.t_end, snapshots=args.snapshots, cfl=args.cfl,
                              alpha=args.alpha, progress=True)
        results[name] = res
        rho0 = res["snapshots"][0]["density"]
        explosions[name] = dict({k: res[k] for k in ("n", "h", "steps", "dt_min", "dt_max", "wall_time", "deposit_count",
                                                     "deposit_radius", "energy_error_max", "centre", "cell")},
                                rho_spread_t0=float(rho0.std() / rho0.mean()), hot_particles=hot_particles(res),
                                history=[{k: r[k] for k in ("time", "kinetic", "internal", "energy_error")}
                                         for r in res["history"]])
        series[name] = {key: isotropy(res, *key.split("/"), args.n_angles, args.dr_factor * dx) for key in SERIES}
        print(f"{name}: {res['steps']} steps, {res['wall_time']:.1f} s, energy error {res['energy_error_max']:.1e}, "
              f"final spread (density centroid) {series[name]['density/centroid'][-1]['spread']:.4f}", flush=True)
    load.append(os.getloadavg())
    summary = summarise(series, SETTLED)
    payload = dict(n=args.n_side**2, args=vars(args), cells={k: v["cell"] for k, v in explosions.items()},
                   starts=quality, start_cost=cost, explosions=explosions, series=series, summary=summary,
                   load_average=load, verdict=verdict(summary))
    with gzip.open(out / "results.json.gz", "wt") as fh:  # 0.6 MB as text
        json.dump(payload, fh, indent=1)
    fig14(results, out, args.t_end)
    fig15(results, series, out)
    command = ("PYTHONPATH=. OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 nice -n 10 .venv/bin/python reproductions/alaric-fig14-15/run.py "
               f"--out {args.out} --n-side {args.n_side} --alaric-steps {args.alaric_steps} --wvt-steps {args.wvt_steps}")
    write_readme(out, args, payload, command)
    print(payload["verdict"])


if __name__ == "__main__":
    main()
