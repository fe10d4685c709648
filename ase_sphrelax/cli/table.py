"""write Table 2 (characteristic volumes) as CSV and a plot

2D: Fan et al.'s Table 2 (v_c of five patterns against h/dx, the winner and its
parameters) plus the symmetry of the global optimum; 3D: sc, bcc, fcc, hcp and
the best one-atom lattice (about 20 s; a progress bar follows the rows).
"""
from __future__ import annotations

__all__ = ["add_arguments", "run"]


def add_arguments(parser):
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2,
                        help="2 (Fan's Table 2: five patterns, h/dx = 1.5..3.5, default) or 3 (sc, bcc, fcc, hcp "
                             "and the best one-atom lattice)")
    parser.add_argument("--out", default=None,
                        help="CSV path (default table2_<dim>d.csv, the name the examples use; the PNG goes beside it)")


def run(args):
    from pathlib import Path

    from ..analysis.patterns import table_path, write_table

    csv = Path(args.out) if args.out else table_path(args.dim)
    png = csv.with_suffix(".png")
    write_table(csv, png, dim=args.dim, progress=None)
    print(f"wrote {csv} and {png}")
    return 0
