"""A fifth method in one file, through the same contract checks as the package's four.

Its model: smooth bumps, ``phi(r) = k (1 - r^2 / s^2)^3`` for ``r < s = R_a + R_b`` (per-particle radii
from the Atoms array ``"radius"``), one :class:`~ase_sphrelax.pairs.PairInteraction`. Its calculator
supplies only parameters, their check, the cut-off and ``evaluate``: ``SPHCalculator.calculate`` does
the rest (dimension, Atoms checks, neighbour list, free_energy, results).
"""
import numba
import pytest
from test_calculator_contract import CONTRACT, Method, lattice_atoms

from ase_sphrelax.calculators.base import SPHCalculator
from ase_sphrelax.checks import check_positive
from ase_sphrelax.pairs import Output, PairInteraction


@numba.njit(cache=True, inline="always")
def bump_pair(a, b, r2, d, params, inp):
    """Half of phi to each of a and b; the force on a is -dphi/dx_a = -6 k (1 - q)^2 / s^2 d, q = r^2 / s^2."""
    (k,) = params
    (radius_s,) = inp
    s2 = (radius_s[a] + radius_s[b]) ** 2
    if r2 >= s2:
        return (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0), ()
    w = 1.0 - r2 / s2
    half = 0.5 * k * w * w * w
    c = 6.0 * k * w * w / s2
    return (half, -c * d[0], -c * d[1], -c * d[2]), (half, c * d[0], c * d[1], c * d[2]), ()


BUMPS = PairInteraction(bump_pair, dict(energies=Output(()), forces=Output((3,))))


class BumpCalculator(SPHCalculator):
    """``E = sum_pairs k (1 - r^2 / s^2)^3`` with exact forces; ``dim=None`` infers the dimension."""

    implemented_properties = ["energy", "free_energy", "energies", "forces"]
    default_parameters = dict(k=1.0, dim=None, skin=0.1)

    def _validate_parameters(self):
        super()._validate_parameters()
        check_positive("k", self.parameters.k)

    def cutoff(self, atoms, dim):
        radius_p = atoms.get_array("radius")
        return radius_p + radius_p.max(), self.parameters.skin

    def evaluate(self, state, properties):
        radius_p = state.atoms.get_array("radius")
        out = BUMPS.compute(state.nlist, state.r_pc, params=(self.parameters.k,), inputs=(radius_p,),
                            reach=2.0 * radius_p.max())
        return dict(energy=float(out.energies.sum()), energies=out.energies, forces=out.forces)


def bump_atoms(dim):
    atoms = lattice_atoms(dim, {1: 12, 2: 6, 3: 4}[dim], seed=dim)
    atoms.set_array("radius", 0.6 + 0.3 * (atoms.numbers + (atoms.positions[:, 0] % 1.0)))
    return atoms


BUMP = Method(lambda **kw: BumpCalculator(k=1.5, **kw), bump_atoms, (1, 2, 3), dict(k=2.5))


@pytest.mark.parametrize("check", CONTRACT, ids=lambda c: c.__name__[6:])
def test_fifth_method_meets_the_contract(check):
    check(BUMP)
