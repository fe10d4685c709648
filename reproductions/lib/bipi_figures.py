"""BIPI's Figs. 6, 7 and 9 (Boregowda & Liu 2025) and the runs behind the guide's numbers.

One sub-command per figure, each writing into ``--out`` (default ``reproductions/bipi-<what>/results``,
``reproductions/bipi-band-window/results`` for ``backing``)::

    python reproductions/lib/bipi_figures.py fig6     # Eq. 12 against Eq. 15 at the trapezoid's top corners
    python reproductions/lib/bipi_figures.py fig7     # 20 000 + 40 000 iterations (and 1 % 2a + 40 000), dx 0.02/0.04/0.01
    python reproductions/lib/bipi_figures.py fig9     # the h_B/dx series under controlled changes of one ingredient
    python reproductions/lib/bipi_figures.py backing  # band rules, window 1 against 10, 5000 + 1000 fixed, bunny 1000
    python reproductions/lib/bipi_figures.py plot --out DIR  # redraw fig6/fig7/fig9 from the files in DIR

Every run starts from Step 1 on ``../shared/geometries`` (the trapezoid unless named) with
h_B/dx_r = 2 (support h = 4 dx) unless named. "Fixed" iteration counts switch the 1 % rules off (a window
longer than the run); ``--budget`` (seconds of wall time per sub-command) stops a long run early, and its
files and figure then say where it stopped. Histories are written while running
(``fig7_<run>_history.csv``: every iteration up to 1000, then every 10th; ``fig7_<run>_status.json``); at the
end ``fig7_milestones.json`` keeps the values the README quotes from those histories. ``fig6_eq12_vs_eq15.json.gz``
and ``fig9_experiments.json.gz`` are gzipped JSON.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

GEOMETRIES = Path(__file__).resolve().parents[3] / "shared" / "geometries"
NEVER = 10**9  # a stopping-rule window longer than any run: fixed iteration counts
HB_SERIES = (1.2, 1.7, 2.0, 2.5, 3.0)
CORNERS = {"top-left": ((-0.01, 0.24), (0.75, 1.01)), "top-right": ((1.20, 1.51), (0.70, 1.01))}
FIG7_RUNS = [(f"{mode}_dx{dx:g}", mode, dx) for dx in (0.02, 0.04, 0.01) for mode in ("fixed", "rule2a")]

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # reproductions/, for lib
from lib.results_io import read_json, write_json  # noqa: E402


# -- running -----------------------------------------------------------------------------
def boundary_of(geometry="TrapezoidalTank"):
    from ase_sphrelax.boundary import BoundarySegments

    return BoundarySegments.from_edges(GEOMETRIES / f"{geometry}.edges")


def make_packer(boundary, dx, ratio=2.0, n2a=5000, n2c=1000, window=10, tol=0.01, pressure=True, band_rule="ball",
                J=None):
    """Step 1 and a BIPIPacker with the given knobs (``window=NEVER``: fixed iteration counts).

    ``band_rule="centroid"`` (Eq. 21 as written) refines the segments to dx/10 first (BIPI2D's
    ``edge_to_dx_ratio``), as the rule is meant for; the other rules do not depend on the segmentation.
    """
    from ase_sphrelax.calculators.bipi import BIPICalculator
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker, initial_fill

    if band_rule == "centroid":
        boundary = boundary.refine(dx=dx)
    atoms = initial_fill(boundary, dx)
    calc = BIPICalculator.from_paper(ratio, dx, boundary, band_rule=band_rule, **({} if J is None else dict(J=J)))
    packer = BIPIPacker(atoms, calc, max_steps_2a=n2a, max_steps_2c=n2c, window=window, tol=tol, pressure=pressure)
    return atoms, packer


def distances_over_dx(atoms, packer):
    return -packer.calc.boundary.domain.phi(atoms.positions) / packer.model.dx


def layer_numbers(atoms, packer):
    """Boundary layer (d < 0.75 dx) mean and minimum d/dx, and particles closer than 0.25 dx."""
    d = distances_over_dx(atoms, packer)
    layer = d < 0.75
    return dict(layer_mean=float(d[layer].mean()), layer_min=float(d.min()), n_layer=int(layer.sum()),
                n_closer_0p25dx=int(np.sum(d < 0.25)), n_outside=int(np.sum(d <= 0)))


def grad_c_norm(atoms, packer):
    atoms.calc = packer.calc
    return np.linalg.norm(packer.calc.get_concentration_gradient(atoms), axis=1)


def final_numbers(atoms, packer):
    """Iterations, how each stage stopped, |grad C|_avg (2c start, end, drop) and the layer."""
    s = packer.summary()
    final = packer.final_gradc_avg()
    first = s.get("gradc_avg_2c_first", np.nan)
    out = dict(it_2a=s["iterations_2a"], it_2c=s["iterations_2c"], stopped_by=dict(packer.stopped_by),
               tpd_avg_2a=s.get("tpd_avg_2a"), gradc_2c_first=first, gradc_final=final,
               drop_orders=float(np.log10(first / final)) if final > 0 and np.isfinite(first) else None,
               n_frozen=s["n_frozen"], wall_s=s["wall_time"])
    out.update(layer_numbers(atoms, packer))
    return out


class HistoryWriter:
    """Appends the packer's history to a CSV while it runs.

    Every iteration up to 1000 of a stage; beyond, one row per 10 iterations with the block's mean of
    TPD_avg and |grad C|_avg and the block's min and max of |grad C|_avg (Step 2a oscillates with period 2:
    sampling every 10th row would alias it).
    """

    FIELDS = ["stage", "iteration", "tpd_avg", "gradc_avg", "gradc_min", "gradc_max", "n_pack", "rejected", "time"]

    def __init__(self, path):
        self.path = Path(path)
        self.done = 0
        with open(self.path, "w", newline="") as fh:
            csv.writer(fh).writerow(self.FIELDS)

    def flush(self, history, final=False):
        out, block, i = [], [], self.done
        for k in range(self.done, len(history)):
            r = history[k]
            if r["iteration"] <= 1000 and not block:
                out.append((r, r["tpd_avg"], r["gradc_avg"], r["gradc_avg"], r["gradc_avg"]))
                i = k + 1
                continue
            block.append(r)
            stage_ends = k + 1 < len(history) and history[k + 1]["stage"] != r["stage"]
            if r["iteration"] % 10 == 0 or stage_ends or (final and k == len(history) - 1):
                g = [b["gradc_avg"] for b in block]
                out.append((r, np.mean([b["tpd_avg"] for b in block]), np.mean(g), min(g), max(g)))
                block, i = [], k + 1
        with open(self.path, "a", newline="") as fh:
            w = csv.writer(fh)
            for r, tpd, g, lo, hi in out:
                w.writerow([r["stage"], r["iteration"], f"{tpd:.6g}", f"{g:.6g}", f"{lo:.6g}", f"{hi:.6g}", r["n_pack"],
                            r["rejected"], f"{r['time']:.3g}"])
        self.done = i


def run_with_budget(packer, deadline, writer=None, status=None, on_iteration=None, switch_2c=None, every=500):
    """Iterate the packer until done or ``time.time() > deadline``; returns True when it finished."""
    status = status or {}
    for _ in packer.irun():
        n = packer.iteration
        if switch_2c is not None and packer.stage == "2c" and packer.window != switch_2c:
            packer.window = switch_2c  # from here on fixed iteration counts (Fig. 7c-d)
        if on_iteration is not None:
            on_iteration(packer)
        if writer is not None and n % every == 0:
            writer.flush(packer.history)
            status.update(iterations=dict(packer.stage_iterations), stage=packer.stage, time=time.time())
            Path(status["path"]).write_text(json.dumps(status, indent=1))
        if time.time() > deadline:
            break
    if writer is not None:
        writer.flush(packer.history, final=True)
    return packer.stage == "done"


# -- Fig. 6 ------------------------------------------------------------------------------
def fig6(out, budget, dx=0.02, n2a=7000, total=30000, snaps=(4000, 30000)):
    """Eq. 12 (no boundary pressure) against Eq. 15: 7000 iterations of 2a, then 2c up to 30 000."""
    warnings.simplefilter("ignore")
    deadline = time.time() + budget
    boundary = boundary_of()
    result = dict(dx=dx, h_over_dx_paper=2.0, step_2a=n2a, total=total, snapshots=list(snaps), runs={})
    arrays = {}
    for eq, pressure in (("eq12", False), ("eq15", True)):
        atoms, packer = make_packer(boundary, dx, n2a=n2a, n2c=total - n2a, window=NEVER, pressure=pressure)
        rows = {}

        def snap(p, eq=eq, atoms=atoms, rows=rows):
            if p.iteration in snaps:
                g = grad_c_norm(atoms, p)
                arrays[f"{eq}_{p.iteration}_r"] = atoms.positions[:, :2].copy()
                arrays[f"{eq}_{p.iteration}_gradc"] = g
                d = distances_over_dx(atoms, p)
                hist, edges = np.histogram(d, bins=np.arange(0.0, 3.01, 0.05))
                rows[p.iteration] = dict(layer_numbers(atoms, p), gradc_avg_all=float(g.mean()),
                                         gradc_avg_beyond_0p6dx=float(g[d >= 0.6].mean()),
                                         gradc_avg_layer=float(g[d < 0.75].mean()), stage=p.history[-1]["stage"],
                                         d_histogram=dict(edges=edges.round(3).tolist(), counts=hist.tolist()))
        finished = run_with_budget(packer, deadline, on_iteration=snap)
        result["runs"][eq] = dict(snapshots=rows, iterations=dict(packer.stage_iterations), finished=finished,
                                  history=compact(packer.history, every=10))
        print(f"fig6 {eq}: {packer.stage_iterations} finished={finished}", flush=True)
    np.savez_compressed(out / "fig6_positions.npz", **arrays)
    write_json(out / "fig6_eq12_vs_eq15.json.gz", result)
    plot_fig6(out)


def compact(history, every=10):
    keep = [r for r in history if r["iteration"] <= 100 or r["iteration"] % every == 0]
    return {k: [(float(f"{r[k]:.4g}") if isinstance(r[k], float) else r[k]) for r in keep]
            for k in ("stage", "iteration", "tpd_avg", "gradc_avg")}


# -- Fig. 7 ------------------------------------------------------------------------------
def fig7(out, budget, runs=None):
    """20 000 + 40 000 fixed iterations, and 1 % TPD rule in 2a + 40 000 in 2c, per dx; one run at a time."""
    warnings.simplefilter("ignore")
    deadline = time.time() + budget
    boundary = boundary_of()
    for name, mode, dx in FIG7_RUNS:
        if runs and name not in runs:
            continue
        if time.time() > deadline:
            status = dict(path=str(out / f"fig7_{name}_status.json"), run=name, dx=dx, mode=mode,
                          target=dict(step_2a=20000 if mode == "fixed" else "1 % rule", step_2c=40000),
                          iterations={"2a": 0, "2c": 0}, finished=False, reason="wall-time budget (not started)")
            Path(status["path"]).write_text(json.dumps(status, indent=1))
            HistoryWriter(out / f"fig7_{name}_history.csv")
            continue
        t0 = time.time()
        if mode == "fixed":
            atoms, packer = make_packer(boundary, dx, n2a=20000, n2c=40000, window=NEVER)
            switch = None
        else:
            atoms, packer = make_packer(boundary, dx, n2a=5000, n2c=40000, window=10)
            switch = NEVER
        status = dict(path=str(out / f"fig7_{name}_status.json"), run=name, dx=dx, mode=mode, n_particles=len(atoms),
                      target=dict(step_2a=20000 if mode == "fixed" else "1 % rule (window 10, cap 5000)",
                                  step_2c=40000), started=t0)
        writer = HistoryWriter(out / f"fig7_{name}_history.csv")
        finished = run_with_budget(packer, deadline, writer, status, switch_2c=switch)
        status.update(iterations=dict(packer.stage_iterations), stage=packer.stage, finished=finished,
                      reason="done" if finished else "wall-time budget", wall_s=time.time() - t0,
                      stopped_by=dict(packer.stopped_by))
        if packer.stage == "done":
            status.update(final_numbers(atoms, packer))
        status.pop("path")
        (out / f"fig7_{name}_status.json").write_text(json.dumps(status, indent=1))
        print(f"fig7 {name}: {packer.stage_iterations} finished={finished} {time.time() - t0:.0f} s", flush=True)
    fig7_milestones(out)
    plot_fig7(out)


FIG7_AT = (1, 10, 100, 1000, 5000, 10000, 20000, 30000, 40000)


def fig7_milestones(out):
    """Write ``fig7_milestones.json``: per run, the history values the README quotes.

    From ``fig7_<run>_history.csv``: |grad C|_avg of Step 2a at its first and last row; TPD_avg's
    settling (first iteration reaching 90 % / 99 % of its last value, as :func:`settling`); |grad C|_avg
    of Step 2c at the iterations ``FIG7_AT`` (the row of that iteration: beyond 1000, the mean of its
    block of 10); its smallest block mean and smallest block minimum with their iterations, and the
    largest block mean after the smallest block mean. Runs without a history are left out.
    """
    result = {}
    for name, mode, dx in FIG7_RUNS:
        path = out / f"fig7_{name}_history.csv"
        if not path.exists():
            continue
        h = _read_history(path)
        a, c = h["stage"] == "2a", h["stage"] == "2c"
        row = dict(dx=dx, mode=mode)
        if a.any():
            tpd, it = h["tpd"][a], h["iteration"][a]
            row.update(gradc_2a_first=float(h["gradc"][a][0]), gradc_2a_last=float(h["gradc"][a][-1]),
                       tpd_90pc_at=int(it[settling(tpd, 0.9) - 1]), tpd_99pc_at=int(it[settling(tpd, 0.99) - 1]))
        if c.any():
            it, g, lo = h["iteration"][c], h["gradc"][c], h["gradc_min"][c]
            row["gradc_2c_at"] = {str(k): float(g[it == k][0]) for k in FIG7_AT if (it == k).any()}
            k = int(np.argmin(g))
            row.update(gradc_2c_min=float(g[k]), gradc_2c_min_at=int(it[k]),
                       gradc_2c_block_min=float(lo.min()), gradc_2c_block_min_at=int(it[int(np.argmin(lo))]),
                       gradc_2c_max_after_min=float(g[k:].max()),
                       gradc_2c_max_after_min_at=int(it[k + int(np.argmax(g[k:]))]))
        result[name] = row
    write_json(out / "fig7_milestones.json", result)
    return result


# -- Fig. 9 and the controlled experiments ----------------------------------------------------
FIG9_VARIANTS = {
    # name: (description, packer knobs as a function of h_B/dx)
    "baseline": ("1 % rules, window 10, caps 5000 + 1000, band 'ball', J = 0.5 (reproductions/bipi-table/run.py)",
                 lambda r: {}),
    "window1": ("as baseline with window 1 (per-iteration 1 % rule)", lambda r: dict(window=1)),
    "window100": ("as baseline with window 100", lambda r: dict(window=100)),
    "same_D": ("as baseline with J = 0.5 (2 / (h_B/dx))^2: the same D = J h_B^2 as at h_B/dx = 2",
               lambda r: dict(J=0.5 * (2.0 / r) ** 2)),
    "band_centroid": ("as baseline with band_rule 'centroid' (segments refined to dx/10)",
                      lambda r: dict(band_rule="centroid")),
    "rule2a_fixed2c": ("baseline Step 2a (1 % rule, window 10), then a fixed 1000 iterations of 2c",
                       lambda r: dict(fixed_2c=True)),
    "rule2a_fixed2c_5000": ("baseline Step 2a, then a fixed 5000 iterations of 2c (h_B/dx 1.2, 1.7, 2)",
                            lambda r: dict(fixed_2c=True, n2c=5000), (1.2, 1.7, 2.0)),
    "fixed": ("fixed 5000 + 1000 iterations (no stopping rule)", lambda r: dict(window=NEVER)),
    "fixed_same_D": ("fixed 5000 + 1000 iterations, J scaled to the same D", lambda r: dict(window=NEVER,
                                                                                          J=0.5 * (2.0 / r) ** 2)),
}


def stop_iteration(x, window, tol=0.01, relative_to="window"):
    """First iteration i >= window where the 1 % rule holds on X_0..X_i (X_0 = 0 for TPD), or None.

    ``relative_to="window"``: |X_i - X_(i-w)| <= tol |X_(i-w)| (the packer's rule);
    ``"start"``: |X_i - X_(i-w)| <= tol |X_i - X_0| (change over the window against the change so far).
    """
    x = np.concatenate([[0.0], np.asarray(x, dtype=float)])
    for i in range(window, len(x)):
        change = abs(x[i] - x[i - window])
        ref = abs(x[i - window]) if relative_to == "window" else abs(x[i] - x[0])
        if ref > 0 and change <= tol * ref:
            return i
    return None


def settling(x, fraction):
    """First iteration where X reaches ``fraction`` of its last value (TPD rises then levels off)."""
    x = np.asarray(x, dtype=float)
    hit = np.nonzero(x >= fraction * x[-1])[0]
    return int(hit[0]) + 1 if len(hit) else None


def thin_history(series, every=10, full=200):
    """Each series at iterations 1..full, then every ``every``-th (4 significant digits); ``at`` lists them."""
    out = {}
    for name, x in series.items():
        keep = [i for i in range(1, len(x) + 1) if i <= full or i % every == 0]
        out[name] = dict(at=keep, value=[float(f"{x[i - 1]:.4g}") for i in keep])
    return out


def fig9(out, budget, variants=None):
    """Each variant over h_B/dx = 1.2 ... 3 (dx 0.02, trapezoid); one ingredient changed at a time."""
    warnings.simplefilter("ignore")
    deadline = time.time() + budget
    boundary = boundary_of()
    path = out / "fig9_experiments.json.gz"
    result = read_json(path) if path.exists() else {}
    for name, (description, knobs, *ratios) in FIG9_VARIANTS.items():
        if variants and name not in variants:
            continue
        rows = {}
        for r in (ratios[0] if ratios else HB_SERIES):
            if time.time() > deadline:
                break
            kw = knobs(r)
            fixed_2c = kw.pop("fixed_2c", False)
            atoms, packer = make_packer(boundary, 0.02, ratio=r, **kw)
            for _ in packer.irun():
                if fixed_2c and packer.stage == "2c":
                    packer.window = NEVER
            row = final_numbers(atoms, packer)
            tpd = [h["tpd_avg"] for h in packer.history if h["stage"] == "2a"]
            grad2c = [h["gradc_avg"] for h in packer.history if h["stage"] == "2c"]
            row.update(D_over_dx2=packer.model.diffusion / 0.02**2, J=packer.model.J,
                       first_step_tpd_over_dx=tpd[0] / 0.02 if tpd else None,
                       tpd_end_2a_over_dx=tpd[-1] / 0.02 if tpd else None)
            if True:  # rule-free measures of the same series
                row.update(
                    tpd_90pc_at=settling(tpd, 0.9), tpd_99pc_at=settling(tpd, 0.99),
                    rule_2a={f"window{w}": stop_iteration(tpd, w) for w in (1, 10, 100)},
                    rule_2a_relative_to_start={f"window{w}": stop_iteration(tpd, w, relative_to="start")
                                               for w in (10, 100)},
                    rule_2c={f"window{w}": stop_iteration(grad2c, w) for w in (1, 10, 100)},
                    gradc_2c_at={str(k): grad2c[k - 1] for k in (10, 50, 100, 500, 1000, 2000, 5000)
                                 if k <= len(grad2c)},
                    history=thin_history(dict(tpd_2a=tpd, gradc_2c=grad2c)))
            rows[f"{r:g}"] = row
            print(f"fig9 {name} h_B/dx={r:g}: 2a {row['it_2a']} 2c {row['it_2c']} drop {row['drop_orders']:.2f} "
                  f"layer {row['layer_mean']:.3f} {row['wall_s']:.1f}s", flush=True)
        result[name] = dict(description=description, rows=rows)
        write_json(path, result)
    write_fig9_table(out, result)
    plot_fig9(out)


def write_fig9_table(out, result):
    cols = ["variant", "h_B/dx", "D/dx^2", "it 2a", "it 2c", "stopped", "TPD 2a end / dx", "∇C 2c start",
            "∇C end", "drop (orders)", "layer mean d/dx"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    rows = []
    for name, block in result.items():
        for r, row in block["rows"].items():
            vals = [name, r, f"{row['D_over_dx2']:.3g}", row["it_2a"], row["it_2c"],
                    "/".join(row["stopped_by"].get(s, "-") for s in ("2a", "2c")), f"{row['tpd_end_2a_over_dx']:.3f}",
                    f"{row['gradc_2c_first']:.3g}", f"{row['gradc_final']:.3g}", f"{row['drop_orders']:.2f}",
                    f"{row['layer_mean']:.3f}"]
            rows.append(vals)
            lines.append("| " + " | ".join(str(v) for v in vals) + " |")
    (out / "fig9_experiments.md").write_text("\n".join(lines) + "\n")
    with open(out / "fig9_experiments.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([cols] + rows)
    fixed = result.get("fixed", {}).get("rows", {})
    if fixed:
        cols2 = ["h_B/dx", "TPD 90 % at", "TPD 99 % at", "rule w1", "rule w10", "rule w100", "rule w10 vs start",
                 "2c rule w10", "∇C 2c at 10", "at 100", "at 1000", "drop 1000 (orders)"]
        lines += ["", "Fixed 5000 + 1000: where each 2a rule would stop on the same TPD_avg series, and when TPD_avg "
                  "reaches 90 % / 99 % of its value at 5000:", "",
                  "| " + " | ".join(cols2) + " |", "|" + "---|" * len(cols2)]
        for r, row in fixed.items():
            g = row["gradc_2c_at"]
            vals = [r, row["tpd_90pc_at"], row["tpd_99pc_at"], row["rule_2a"]["window1"], row["rule_2a"]["window10"],
                    row["rule_2a"]["window100"], row["rule_2a_relative_to_start"]["window10"],
                    row["rule_2c"]["window10"], f"{g.get('10', np.nan):.3g}", f"{g.get('100', np.nan):.3g}",
                    f"{g.get('1000', np.nan):.3g}", f"{row['drop_orders']:.2f}"]
            lines.append("| " + " | ".join(str(v) for v in vals) + " |")
        (out / "fig9_experiments.md").write_text("\n".join(lines) + "\n")


# -- the guide's numbers ---------------------------------------------------------------------
def pressure_to_gradient(atoms, packer):
    """Median of |(1 / (2 gamma_a)) sum_near grad gamma_as| / |grad C_a| over the particles that feel the pressure."""
    atoms.calc = packer.calc
    near = packer.calc.get_property("wall_gradient", atoms)
    gamma = packer.calc.get_property("gamma", atoms)
    grad_c = packer.calc.get_concentration_gradient(atoms)
    pressure = np.linalg.norm(0.5 * near / gamma[:, None], axis=1)
    feel = pressure > 0
    ratio = pressure[feel] / np.maximum(np.linalg.norm(grad_c[feel], axis=1), 1e-300)
    return dict(n_feel_pressure=int(feel.sum()),
                median_pressure_over_gradc=float(np.median(ratio)) if feel.any() else None)


def backing(out, budget, parts=None):
    """The guide's numbers: band rules (400 + 400 fixed), window 1 against 10, the bunny with 1000 iterations of 2c."""
    warnings.simplefilter("ignore")
    deadline = time.time() + budget
    path = out / "guide_numbers.json"
    result = json.loads(path.read_text()) if path.exists() else {}
    parts = parts or ["band", "window", "bunny"]
    trapezoid = boundary_of()
    for rule in ("normal", "centroid", "ball") if "band" in parts else ():
        atoms, packer = make_packer(trapezoid, 0.02, n2a=400, n2c=400, window=NEVER, band_rule=rule)
        t = time.perf_counter()
        packer.run()
        row = final_numbers(atoms, packer)
        row["run_s"] = time.perf_counter() - t
        row["uptime"] = open("/proc/loadavg").read().split()[:3]
        row["gradc_2c_last"] = packer.history[-1]["gradc_avg"]
        row["gradc_2c_last_10"] = [h["gradc_avg"] for h in packer.history[-10:]]
        row.update(pressure_to_gradient(atoms, packer))
        result[f"band_{rule}_400+400"] = row
        print(f"band {rule}: {row}", flush=True)
        path.write_text(json.dumps(result, indent=1))
    for w in (1, 10) if "window" in parts else ():
        atoms, packer = make_packer(trapezoid, 0.02, window=w)
        packer.run()
        result[f"trapezoid_window{w}"] = final_numbers(atoms, packer)
        print(f"window {w}: {result[f'trapezoid_window{w}']}", flush=True)
        path.write_text(json.dumps(result, indent=1))
    if "bunny" in parts and time.time() < deadline:
        atoms, packer = make_packer(boundary_of("Standford2DBunny"), 1.0, n2c=1000, window=10)
        for _ in packer.irun():
            if packer.stage == "2c":
                packer.window = NEVER
        result["bunny_1pc2a_fixed1000_2c"] = final_numbers(atoms, packer)
        print(f"bunny: {result['bunny_1pc2a_fixed1000_2c']}", flush=True)
    path.write_text(json.dumps(result, indent=1))


# -- figures -----------------------------------------------------------------------------
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path, dpi=90):
    """Write the figure as a 256-colour PNG (a third of the size) and close it."""
    from ase_sphrelax.plotting import save_figure

    save_figure(fig, path, dpi=dpi)


def plot_fig6(out):
    path = out / "fig6_eq12_vs_eq15.json.gz"
    if not path.exists() or not (out / "fig6_positions.npz").exists():
        return  # the positions (200 kB) are not kept in the repository: ``fig6`` rewrites them
    result = read_json(path)
    data = np.load(out / "fig6_positions.npz")
    plt = _plt()
    snaps = result["snapshots"]
    fig, axes = plt.subplots(3, 4, figsize=(15, 11.5), constrained_layout=True,
                             gridspec_kw=dict(height_ratios=[1, 1, 0.8]))
    h = 4 * result["dx"]
    for row, eq in enumerate(("eq12", "eq15")):
        run = result["runs"][eq]
        for k, (corner, (xl, yl)) in enumerate(CORNERS.items()):
            for j, it in enumerate(snaps):
                ax = axes[row, 2 * k + j]
                key = f"{eq}_{it}_r"
                if key not in data:
                    ax.text(0.5, 0.5, f"not reached\n({run['iterations']})", ha="center", transform=ax.transAxes)
                    continue
                r, g = data[key], data[f"{eq}_{it}_gradc"]
                sc = ax.scatter(r[:, 0], r[:, 1], c=np.log10(np.maximum(g * h, 1e-12)), s=22, cmap="viridis",
                                vmin=-4, vmax=-0.5)
                _draw_trapezoid(ax)
                ax.set(xlim=xl, ylim=yl, aspect="equal")
                snap = run["snapshots"][str(it)]
                label = "Eq. 12 (no boundary pressure)" if eq == "eq12" else "Eq. 15 (step pressure)"
                ax.set_title(f"{label}\n{corner}, iteration {it} ({'2a' if it <= result['step_2a'] else '2c'})\n"
                             f"whole tank: layer mean {snap['layer_mean']:.2f} dx, min {snap['layer_min']:.2f} dx",
                             fontsize=8)
    fig.colorbar(sc, ax=axes[:2, :], shrink=0.6, label=r"log$_{10}$(h |$\nabla C_a$|)")
    for j, it in enumerate(snaps):
        ax = axes[2, j]
        for eq, colour in (("eq12", "tab:red"), ("eq15", "tab:blue")):
            s = result["runs"][eq]["snapshots"].get(str(it))
            if s is None:
                continue
            e = np.array(s["d_histogram"]["edges"])
            ax.stairs(s["d_histogram"]["counts"], e, color=colour, label=eq.replace("eq", "Eq. "))
        ax.axvline(0.5, color="k", lw=0.5, ls=":")
        ax.set(xlabel="distance to the wall / dx", ylabel="particles per 0.05 dx", title=f"iteration {it}",
               xlim=(0, 2.0))
        ax.legend(fontsize=8)
    for eq, colour in (("eq12", "tab:red"), ("eq15", "tab:blue")):
        hist = result["runs"][eq]["history"]
        x = np.array(hist["iteration"]) + np.where(np.array(hist["stage"]) == "2c", result["step_2a"], 0)
        axes[2, 2].plot(x, hist["tpd_avg"], color=colour, lw=1, label=eq.replace("eq", "Eq. "))
        axes[2, 3].semilogy(x, hist["gradc_avg"], color=colour, lw=1, label=eq.replace("eq", "Eq. "))
    for ax in axes[2, 2:]:
        ax.axvline(result["step_2a"], color="k", lw=0.5, ls=":")
        ax.set_xlabel("iteration (2a, then 2c after the dotted line)")
        ax.legend(fontsize=8)
    axes[2, 2].set_ylabel("TPD$_{avg}$")
    axes[2, 3].set_ylabel(r"$|\nabla C|_{avg}$ (packable)")
    fig.suptitle(f"Fig. 6: trapezoid dx = {result['dx']}, h_B/dx = 2; Step 2a for {result['step_2a']} iterations, "
                 "then 2c", fontsize=11)
    _save(fig, out / "fig6_eq12_vs_eq15.png")


def _draw_trapezoid(ax):
    x = [0, 1, 1.5, 0, 0]
    y = [0, 0, 1, 1, 0]
    ax.plot(x, y, color="k", lw=1)


def _read_history(path):
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    stage = np.array([r["stage"] for r in rows])
    return dict(stage=stage, iteration=np.array([int(r["iteration"]) for r in rows]),
                tpd=np.array([float(r["tpd_avg"]) for r in rows]),
                gradc=np.array([float(r["gradc_avg"]) for r in rows]),
                gradc_min=np.array([float(r["gradc_min"]) for r in rows]),
                gradc_max=np.array([float(r["gradc_max"]) for r in rows]))


def plot_fig7(out):
    if not any((out / f"fig7_{name}_history.csv").exists() for name, _, _ in FIG7_RUNS):
        return  # no histories here (the repository keeps only the figure): nothing to redraw
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    colours = {0.01: "tab:green", 0.02: "tab:blue", 0.04: "tab:red"}
    notes = []
    for name, mode, dx in FIG7_RUNS:
        hist_path, status_path = out / f"fig7_{name}_history.csv", out / f"fig7_{name}_status.json"
        if not status_path.exists():
            continue
        st = json.loads(status_path.read_text())
        if not hist_path.exists():
            continue  # the histories (2.6 MB) are not kept in the repository: ``fig7`` rewrites them
        h = _read_history(hist_path)
        row = 0 if mode == "fixed" else 1
        n2a = st["iterations"].get("2a", 0)
        done = f"{n2a} + {st['iterations'].get('2c', 0)}"
        target = "20000 + 40000" if mode == "fixed" else "(1 % rule) + 40000"
        stopped = "" if st.get("finished") else f" (stopped at {done} of {target}: {st.get('reason', 'still running')})"
        notes.append(f"{name}: {done}{stopped}")
        if len(h["stage"]) == 0:
            continue
        x = h["iteration"] + np.where(h["stage"] == "2c", n2a, 0)
        for stage, ls in (("2a", "-"), ("2c", ":")):
            m = h["stage"] == stage
            count = done.split(" + ")[0 if stage == "2a" else 1]
            label = f"dx = {dx:g}, {stage}: {count} it.{stopped if stage == '2c' else ''}"
            axes[row, 0].plot(x[m], h["tpd"][m], ls=ls, color=colours[dx], lw=1, label=label)
            axes[row, 1].fill_between(x[m], h["gradc_min"][m], h["gradc_max"][m], color=colours[dx], alpha=0.15, lw=0)
            axes[row, 1].semilogy(x[m], h["gradc"][m], ls=ls, color=colours[dx], lw=1, label=label)
    for row, title in enumerate(("(a, b) 20 000 of Step 2a, then 40 000 of 2c",
                                 "(c, d) 2a to its 1 % TPD rule, then 40 000 of 2c")):
        axes[row, 0].set(xlabel="iteration", ylabel="TPD$_{avg}$", title=title)
        axes[row, 1].set(xlabel="iteration", ylabel=r"$|\nabla C|_{avg}$ (packable; mean of 10, band min-max)",
                         title=title)
        axes[row, 0].legend(fontsize=7)
        axes[row, 1].legend(fontsize=7)
    notes = ["; ".join(notes[k:k + 3]) for k in range(0, len(notes), 3)]
    fig.suptitle("Fig. 7: trapezoid, h_B/dx = 2 (solid: Step 2a, dotted: Step 2c)\n" + "\n".join(notes), fontsize=8)
    _save(fig, out / "fig7_fixed_iterations.png")


def plot_fig9(out):
    path = out / "fig9_experiments.json.gz"
    if not path.exists():
        return
    result = read_json(path)
    plt = _plt()
    names = [n for n in FIG9_VARIANTS if n in result]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    for name in names:
        rows = result[name]["rows"]
        r = np.array([float(k) for k in rows])
        axes[0].plot(r, [rows[k]["it_2a"] for k in rows], "o-", label=name)
        axes[1].plot(r, [rows[k]["it_2c"] for k in rows], "o-", label=name)
        axes[2].plot(r, [rows[k]["drop_orders"] for k in rows], "o-", label=name)
    fixed = result.get("fixed", {}).get("rows", {})
    if fixed:
        r = np.array([float(k) for k in fixed])
        axes[0].plot(r, [fixed[k]["tpd_90pc_at"] for k in fixed], "k:", label="fixed: TPD$_{avg}$ reaches 90 %")
        axes[0].plot(r, [fixed[k]["tpd_99pc_at"] for k in fixed], "k--", label="fixed: TPD$_{avg}$ reaches 99 %")
    axes[0].set(xlabel="h_B / dx", ylabel="iterations of Step 2a", yscale="log")
    axes[1].set(xlabel="h_B / dx", ylabel="iterations of Step 2c", yscale="log")
    axes[2].set(xlabel="h_B / dx", ylabel=r"drop of $|\nabla C|_{avg}$ in 2c (orders)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Fig. 9 re-run (trapezoid, dx = 0.02): one ingredient changed at a time (fig9_experiments.md)")
    _save(fig, out / "fig9_experiments.png", dpi=100)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=["fig6", "fig7", "fig9", "backing", "plot"])
    parser.add_argument("--out", default=None, help="default reproductions/bipi-<what>/results "
                        "(reproductions/bipi-band-window/results for backing)")
    parser.add_argument("--budget", type=float, default=3600.0, help="wall-time budget in seconds")
    parser.add_argument("--only", nargs="*",
                        help="fig7: run names (fixed_dx0.02 ...); fig9: variant names; backing: band, window, bunny")
    args = parser.parse_args(argv)
    if not GEOMETRIES.is_dir():
        sys.exit(f"{GEOMETRIES} not found: the geometries live in ../shared/geometries beside the checkout")
    if args.out is None:
        if args.what == "plot":
            parser.error("plot needs --out")
        args.out = f"reproductions/bipi-{'band-window' if args.what == 'backing' else args.what}/results"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.what == "fig6":
        fig6(out, args.budget)
    elif args.what == "fig7":
        fig7(out, args.budget, args.only)
    elif args.what == "fig9":
        fig9(out, args.budget, args.only)
    elif args.what == "backing":
        backing(out, args.budget, args.only)
    else:
        plot_fig6(out)
        plot_fig7(out)
        plot_fig9(out)


if __name__ == "__main__":
    main()
