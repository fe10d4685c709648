"""predicted and relaxed lattice pattern for a given h/dx (Fan Sec. 5)

Prints v_c of every candidate pattern at unit particle volume (Eq. 5.2), the
predicted pattern (Fan's Table 1 convention and the symmetry of the optimum),
and the pattern a variable-cell relaxation finds, identified by spglib.
A progress bar follows the relaxation starts.
"""
from __future__ import annotations

from .common import H_MIN, add_progress_argument, show_progress
from .usage import UsageError, positive

__all__ = ["add_arguments", "run"]



def add_arguments(parser):
    parser.add_argument("--h-over-dx", "--h", dest="h_over_dx", type=positive(float), required=True,
                        help=f"kernel support radius h in units of dx = (particle volume)^(1/dim), > {H_MIN:g} "
                             "(Fan's Table 2 covers 1.5 to 3.5; --h is the same option)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2,
                        help="2 (Fan's five patterns of Table 2, default) or 3 (sc, bcc, fcc, hcp and the best "
                             "one-atom lattice)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the random starts of the variable-cell relaxation (default 0)")
    add_progress_argument(parser)


def run(args):
    if args.h_over_dx <= H_MIN:
        raise UsageError(f"--h-over-dx (--h) must be > {H_MIN:g}, got {args.h_over_dx:g}: at unit particle volume no "
                         "lattice has a neighbour within h, so every pattern has v_c = 1/W(0) and none is selected")
    from ..analysis.patterns import lattice_report

    print(lattice_report(args.h_over_dx, dim=args.dim, seed=args.seed, progress=show_progress(args)))
    return 0
