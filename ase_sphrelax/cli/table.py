"""write Table 2 (characteristic volumes) as CSV and a plot

2D: Fan et al.'s Table 2 (v_c of five patterns against h/dx, the winner and its
parameters) plus the symmetry of the global optimum; 3D: sc, bcc, fcc, hcp and
the best one-atom lattice.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["add_arguments", "run"]


def add_arguments(parser):
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2, help="dimension (2)")
    parser.add_argument("--out", default=None, help="CSV path (default table2_<dim>d.csv; the PNG goes beside it)")


def run(args):
    from ..analysis.patterns import write_table

    csv = Path(args.out or f"table2_{args.dim}d.csv")
    png = csv.with_suffix(".png")
    write_table(csv, png, dim=args.dim)
    print(f"wrote {csv} and {png}")
    return 0
