"""The drivers run the ASE optimisers' steps with BLAS on one thread, keeping a user's setting (issue 9, item 4)."""
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import periodic_box
from ase_sphrelax.drivers import make_optimizer
from ase_sphrelax.drivers.blas import BLAS_THREAD_VARIABLES, limit_blas_in_steps, resolve_blas_threads


def blas_threads_now():
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


@pytest.fixture
def no_user_setting(monkeypatch):
    for name in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)


def small_box():
    atoms = periodic_box((8, 8), dx=1.0, jitter=0.2, seed=1)
    atoms.calc = FanCalculator(h=2.6, dx=1.0)
    return atoms


class Recorder:
    """An optimiser stand-in whose step records the BLAS thread counts it runs with."""

    def __init__(self):
        self.seen = []

    def step(self, f=None):
        self.seen.append(blas_threads_now())
        return "stepped"


def test_steps_run_on_one_blas_thread_and_the_setting_comes_back(no_user_setting):
    with threadpool_limits(limits=2, user_api="blas"):  # as on a 2-core machine, whatever this one has
        before = blas_threads_now()
        assert before and all(n == 2 for n in before)
        opt = limit_blas_in_steps(Recorder())
        assert opt.blas_threads == 1
        assert opt.step() == "stepped"
        assert all(n == 1 for n in opt.seen[0])
        assert blas_threads_now() == before


def test_a_users_own_setting_is_kept(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    before = blas_threads_now()
    opt = limit_blas_in_steps(Recorder())
    assert opt.blas_threads is None
    opt.step()
    assert opt.seen[0] == before
    assert resolve_blas_threads(3) == 3  # an explicit value still wins


@pytest.mark.parametrize("name", ["fire", "lbfgs", "bfgs"])
def test_make_optimizer_limits_blas_in_the_ase_optimisers(no_user_setting, name):
    atoms = small_box()
    opt = make_optimizer(name, atoms)
    assert opt.blas_threads == 1
    before = atoms.get_potential_energy()
    opt.run(fmax=0.0, steps=5)
    assert atoms.get_potential_energy() < before
    assert make_optimizer(name, small_box(), blas_threads=False).blas_threads is None


@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", True])
def test_bad_blas_threads_fail_before_any_work(bad):
    atoms = small_box()
    calls = []
    atoms.calc.calculate = lambda *a, **k: calls.append(1)
    with pytest.raises(ValueError, match="blas_threads"):
        make_optimizer("lbfgs", atoms, blas_threads=bad)
    assert not calls
