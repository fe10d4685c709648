"""Entry point of one MPI rank: ``mpiexec -n P python -m lammps_io._worker FOLDER``."""
import pickle
import sys
from pathlib import Path

from .relaxation import execute_deck


def main(folder):
    with open(Path(folder) / "worker.pkl", "rb") as fh:
        kwargs = pickle.load(fh)
    execute_deck(folder, **kwargs)


if __name__ == "__main__":
    main(sys.argv[1])
