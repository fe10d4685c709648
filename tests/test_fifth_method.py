"""A fifth method in one file, through the same contract checks as the package's four.

Its model: smooth bumps, ``phi(r) = k (1 - r^2 / sigma^2)^3`` for ``r < sigma``, one
:class:`~ase_sphrelax.pairs.PairInteraction`. Its calculator supplies only its parameters and their
check, the cut-off and ``evaluate``: ``SPHCalculator.calculate`` does the rest (the dimension, the
Atoms checks, the neighbour list, free_energy, storing the results).
"""
import numba
import pytest
from test_calculator_contract import CONTRACT, Method, lattice_atoms

from ase_sphrelax.calculators.base import SPHCalculator
from ase_sphrelax.checks import check_positive
from ase_sphrelax.pairs import Output, PairInteraction


@numba.njit(cache=True, inline="always")
def bump_pair(a, b, r2, d, k, sigma):
    """Half of phi to each of a and b; the force on a is -dphi/dx_a = -6 k (1 - q)^2 / sigma^2 d, q = r^2 / sigma^2."""
    s2 = sigma * sigma
    if r2 >= s2:
        return (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0), ()
    w = 1.0 - r2 / s2
    c = 6.0 * k * w * w / s2
    return (0.5 * k * w**3, -c * d[0], -c * d[1], -c * d[2]), (0.5 * k * w**3, c * d[0], c * d[1], c * d[2]), ()


BUMPS = PairInteraction(bump_pair, dict(energies=Output(()), forces=Output((3,))), params=("k", "sigma"))


class BumpCalculator(SPHCalculator):
    """``E = sum_pairs k (1 - r^2 / sigma^2)^3`` with exact forces; ``dim=None`` infers the dimension."""

    implemented_properties = ["energy", "free_energy", "energies", "forces"]
    default_parameters = dict(k=1.0, sigma=1.5, dim=None)

    def _validate_parameters(self):
        super()._validate_parameters()
        for name in ("k", "sigma"):
            self.parameters[name] = check_positive(name, self.parameters[name])

    def cutoff(self, atoms, dim):
        return self.parameters.sigma, 0.1 * self.parameters.sigma

    def evaluate(self, state, properties):
        p = self.parameters
        out = BUMPS.compute(state.nlist, state.r_pc, params=dict(k=p.k, sigma=p.sigma), reach=p.sigma)
        return dict(energy=float(out.energies.sum()), energies=out.energies, forces=out.forces)


def bump_atoms(dim):
    return lattice_atoms(dim, {1: 12, 2: 6, 3: 4}[dim], seed=dim)


BUMP = Method(lambda **kw: BumpCalculator(k=1.5, **kw), bump_atoms, (1, 2, 3), dict(sigma=1.3))


@pytest.mark.parametrize("check", CONTRACT, ids=lambda c: c.__name__[6:])
def test_fifth_method_meets_the_contract(check):
    check(BUMP)
