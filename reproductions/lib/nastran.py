"""BIPI2D's Nastran boundary files (GRID points in the x-z plane joined by PLOTEL elements) as edge files.

    python reproductions/lib/nastran.py IN.dat OUT.edges [--scale 0.001] [--header "# ..."]

Reads free-field (comma-separated) ``GRID,id,cp,x,y,z,...`` and ``PLOTEL,eid,g1,g2`` cards,
takes (x, z) of each grid point times ``scale`` (BIPI2D's files are in mm: 0.001 gives m), walks
the elements into closed loops and writes one ``x1 y1 x2 y2`` line per segment, each loop in one
direction with the inside on its left (outer loops counter-clockwise, holes clockwise: the format
of ``ase_sphrelax.boundary.BoundarySegments.from_edges``). BIPI2D's element order is kept where it
already has the inside on the left; a loop running the other way is reversed.
"""
from __future__ import annotations

import argparse

import numpy as np


def read_nastran(text, scale=1.0):
    """``(points, elements)``: ``{grid id: (x, z) * scale}`` and ``[(g1, g2), ...]`` in file order."""
    points, elements = {}, []
    for line in text.splitlines():
        card = [f.strip() for f in line.split(",")]
        if card[0] == "GRID":
            points[int(card[1])] = (float(card[3]) * scale, float(card[5]) * scale)
        elif card[0] == "PLOTEL":
            elements.append((int(card[2]), int(card[3])))
    if not elements:
        raise ValueError("text has no PLOTEL cards (free-field, comma-separated Nastran expected)")
    return points, elements


def loops_of(points, elements):
    """Closed vertex loops (arrays (n, 2)) walked along the elements; every grid id must end two elements."""
    nxt = {}
    for a, b in elements:
        if a in nxt:
            raise ValueError(f"elements: grid {a} starts two elements (only simple closed loops are supported)")
        nxt[a] = b
    loops, seen = [], set()
    for start, _ in elements:
        if start in seen:
            continue
        ids, g = [], start
        while g not in seen:
            seen.add(g)
            ids.append(g)
            if g not in nxt:
                raise ValueError(f"elements: the loop through grid {start} is open at grid {g}")
            g = nxt[g]
        if g != start:
            raise ValueError(f"elements: the loop through grid {start} runs into another at grid {g}")
        loops.append(np.array([points[i] for i in ids], dtype=float))
    return loops


def _area(v):
    w = np.roll(v, -1, axis=0)
    return 0.5 * float(np.sum(v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]))


def oriented(loops):
    """The loops with the inside on the left: counter-clockwise at even nesting depth, clockwise at odd."""
    from matplotlib.path import Path

    out = []
    for i, v in enumerate(loops):
        depth = sum(Path(w).contains_point(v[0]) for j, w in enumerate(loops) if j != i)
        ccw = _area(v) > 0
        out.append(v if ccw == (depth % 2 == 0) else v[::-1])
    return out


def edge_lines(loops):
    """``x1 y1 x2 y2`` lines, loop after loop."""
    return [f"{a[0]:.9g} {a[1]:.9g} {b[0]:.9g} {b[1]:.9g}"
            for v in loops for a, b in zip(v, np.roll(v, -1, axis=0))]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("src")
    parser.add_argument("out")
    parser.add_argument("--scale", type=float, default=1e-3, help="length factor (default mm -> m)")
    parser.add_argument("--header", action="append", default=[], help="comment line(s) for the top of the file")
    args = parser.parse_args(argv)
    with open(args.src) as f:
        loops = oriented(loops_of(*read_nastran(f.read(), args.scale)))
    with open(args.out, "w") as f:
        f.write("".join(h + "\n" for h in args.header) + "\n".join(edge_lines(loops)) + "\n")


if __name__ == "__main__":
    main()
