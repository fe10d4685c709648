"""SPHLBFGS forms its step and moves the particles in one pass when no particle's step can reach ``maxstep``
(issue 33, item 1): the same trajectory bit for bit as the two passes, and the bound that decides it holds."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Circle, Sphere
from ase_sphrelax.drivers import make_optimizer
from ase_sphrelax.drivers import sph_optimizers as so
from ase_sphrelax.parallel import reduce_chunks


def relaxed(dim, one_pass, steps=30, **kwargs):
    """Positions after ``steps`` SPHLBFGS steps on a jittered fill (KeepInDomain acting), and how many steps took the
    one pass; ``one_pass`` False: the two passes at every step."""
    domain = Circle((0.5, 0.5), 0.2) if dim == 2 else Sphere((0.5, 0.5, 0.5), 0.2)
    dx = 1 / 64 if dim == 2 else 1 / 24
    atoms = fill(domain, dx, jitter=0.3, seed=1)
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    opt = make_optimizer("lbfgs", atoms, **kwargs)
    used = []
    unscaled = opt._unscaled
    opt._unscaled = lambda *a: used.append(one_pass and unscaled(*a)) or used[-1]
    opt.run(fmax=0.0, steps=steps)
    return atoms.positions.copy(), sum(used), len(used)


@pytest.mark.parametrize("dim", [2, 3])
def test_one_pass_steps_give_the_two_pass_trajectory_bit_for_bit(dim):
    r_one, taken, asked = relaxed(dim, one_pass=True)
    r_two, none, _ = relaxed(dim, one_pass=False)
    assert taken == asked == 29 and none == 0  # every step after the first took the one pass
    np.testing.assert_array_equal(r_one, r_two)


def test_steps_that_may_need_scaling_take_the_two_passes():
    """With a maxstep below the moves the bound refuses the one pass, and the steps are scaled as ASE's."""
    r_one, taken, asked = relaxed(2, one_pass=True, steps=12, c=0.5, maxstep=1e-5)
    r_two, _, _ = relaxed(2, one_pass=False, steps=12, c=0.5, maxstep=1e-5)
    assert taken == 0 and asked == 11
    np.testing.assert_array_equal(r_one, r_two)


@settings(max_examples=80, deadline=None, database=None, derandomize=True)
@given(seed=st.integers(0, 2**16), n=st.integers(1, 300), m=st.integers(1, 6), dim=st.sampled_from([2, 3]),
       zero=st.floats(0.0, 1.0), scale=st.sampled_from([1e-12, 1.0, 1e9]))
def test_the_bound_covers_every_particles_step(seed, n, m, dim, zero, scale):
    """|z_p| <= |cg| max|g| + sum_j |cs_j| max|s_j| + |cy_j| max|y_j| for random histories, coefficients of both
    signs (some zero), rows of zeros and coincident rows, over many scales: the one pass is taken only when it holds
    below maxstep."""
    rng = np.random.default_rng(seed)
    s = rng.normal(size=(m, n, dim)) * scale
    y = rng.normal(size=(m, n, dim)) * scale
    f = rng.normal(size=(n, 3)) * scale
    f[:, dim:] = 0.0
    s[:, : n // 3] = 0.0  # rows of zeros
    y[:, n // 2:] = y[:, :1]  # coincident rows
    cs, cy = rng.normal(size=m) * 10, rng.normal(size=m) * 10
    cs[rng.random(m) < zero] = 0.0
    cg = float(rng.normal())
    opt = so.SPHLBFGS.__new__(so.SPHLBFGS)
    opt._s_max = np.sqrt((s**2).sum(axis=2).max(axis=1))
    opt._y_max = np.sqrt((y**2).sum(axis=2).max(axis=1))
    g_max = float(np.sqrt((f**2).sum(axis=1).max()))
    slot = int(rng.integers(m))
    outs = reduce_chunks(so._lbfgs_combine, n, (f, s.copy(), y, slot, cs, cy, cg, dim), 1)
    longest = float(np.sqrt(so._max(outs, 0)))
    opt.maxstep = longest * (1.0 + 1e-12)  # just above the longest step: the bound may or may not be below it
    if opt._unscaled(cg, cs, cy, g_max):
        assert longest < opt.maxstep
    opt.maxstep = longest  # at the longest step: scaling applies, the one pass must be refused
    assert not opt._unscaled(cg, cs, cy, g_max)
