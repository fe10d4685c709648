"""Entry point of one MPI rank: ``mpiexec -n P python -m lammps_io._worker FOLDER``.

The arguments come from ``FOLDER/worker.json`` (plain data, :mod:`lammps_io.worker_args`).
"""
import sys

from .relaxation import execute_deck
from .worker_args import read_worker_args


def main(folder):
    execute_deck(folder, **read_worker_args(folder))


if __name__ == "__main__":
    main(sys.argv[1])
