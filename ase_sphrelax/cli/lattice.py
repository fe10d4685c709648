"""predicted and relaxed lattice pattern for a given h/dx (Fan Sec. 5)

Prints v_c of every candidate pattern at unit particle volume (Eq. 5.2), the
predicted pattern (Fan's Table 1 convention and the symmetry of the optimum),
and the pattern a variable-cell relaxation finds, identified by spglib.
"""
from __future__ import annotations

from .usage import positive

__all__ = ["add_arguments", "run"]


def add_arguments(parser):
    parser.add_argument("--h", type=positive(float), required=True, help="kernel support radius h/dx")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2, help="dimension (2)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random relaxation starts (0)")


def run(args):
    from ..analysis.patterns import lattice_report

    print(lattice_report(args.h, dim=args.dim, seed=args.seed))
    return 0
