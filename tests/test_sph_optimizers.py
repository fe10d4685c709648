"""SPHFIRE, SPHFIRE2 and SPHLBFGS (issue 33) follow ASE's FIRE, FIRE2 and LBFGS step for step."""
import io

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.io import read

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Box, Circle, Difference, Sphere
from ase_sphrelax.drivers import KeepInDomain, make_optimizer
from ase_sphrelax.drivers.sph_optimizers import SPHFIRE, SPHFIRE2, SPHLBFGS


def fan_case(dim, domain=None, dx=None):
    if domain is None:
        domain = Circle((0.5, 0.5), 0.2) if dim == 2 else Sphere((0.5, 0.5, 0.5), 0.2)
    dx = dx or (1 / 48 if dim == 2 else 1 / 16)
    atoms = fill(domain, dx, jitter=0.1, seed=0)
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    return atoms, domain


def trajectory(name, backend, dim, steps=40, prepare=None, **kwargs):
    """Positions and energies after every step of ``make_optimizer(name, ..., backend=backend)``."""
    atoms, domain = fan_case(dim)
    if prepare is not None:
        prepare(atoms)
    if name == "lbfgs":  # the backends' default histories differ (DEFAULT_MEMORY): compare like with like
        kwargs.setdefault("memory", 5)
    if name == "fire":  # nor has ASE's FIRE make_optimizer's cut of each particle's move (FIRE_PARTICLE_STEP)
        kwargs.setdefault("max_particle_step", None)
    opt = make_optimizer(name, atoms, backend=backend, **kwargs)
    frames = []
    opt.attach(lambda: frames.append((atoms.positions.copy(), atoms.get_potential_energy())))
    opt.run(fmax=0.0, steps=steps)
    return opt, atoms, domain, frames


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name,kwargs", [("fire", {}), ("fire", {"maxstep": 3e-3}), ("fire", {"maxstep": 1e-2}),
                                         ("fire2", {}), ("lbfgs", {"memory": 20}), ("lbfgs", {"memory": 3})],
                         ids=["fire", "fire-capped", "fire-capped-some", "fire2", "lbfgs-memory20", "lbfgs-memory3"])
def test_same_trajectory_as_ases_optimiser(dim, name, kwargs):
    """Every step's positions to 1e-9 dx and energies to 1e-9 relative over 40 steps (memory 20 and 3:
    the history wraps; FIRE's whole step capped by ``maxstep`` at every step after the first, or in 3D at 25 of them
    with an uphill step, SPHFIRE taking the cap's norm from its sums)."""
    ours, _, _, frames = trajectory(name, "sph", dim, **kwargs)
    ase_opt, _, _, reference = trajectory(name, "ase", dim, **kwargs)
    assert type(ours) is {"fire": SPHFIRE, "fire2": SPHFIRE2, "lbfgs": SPHLBFGS}[name]
    assert type(ase_opt).__module__.startswith("ase.optimize")
    assert len(frames) == len(reference) == 41
    dx = 1 / 48 if dim == 2 else 1 / 16
    moved = np.abs(reference[-1][0] - reference[0][0]).max()
    assert moved > 0.05 * dx  # the run relaxes: the comparison is not between two resting systems
    for (r, e), (r_ase, e_ase) in zip(frames, reference):
        np.testing.assert_allclose(r, r_ase, rtol=0, atol=1e-9 * dx)
        assert e == pytest.approx(e_ase, rel=1e-9)
    assert reference[-1][1] < 0.99 * reference[0][1]


@pytest.mark.parametrize("dim", [2, 3])
def test_fire2_goes_back_half_a_step_after_an_uphill_step_as_ase(dim):
    """FIRE2's correction (x -= dt v / 2, v = 0, forces anew) happens in these 60 steps, in ours at the
    same steps as in ASE's: the same positions to 1e-9 dx after every step and the same force count."""
    runs = []
    for backend in ("sph", "ase"):
        opt, atoms, _, frames = trajectory("fire2", backend, dim, steps=60)
        runs.append((frames, atoms.calc.evaluations, opt.dt))
    (frames, evaluations, dt), (reference, evaluations_ase, dt_ase) = runs
    assert evaluations == evaluations_ase > 61  # 1 + 60 steps + one per correction
    assert dt == pytest.approx(dt_ase, rel=1e-12)
    dx = 1 / 48 if dim == 2 else 1 / 16
    for (r, _), (r_ase, _) in zip(frames, reference):
        np.testing.assert_allclose(r, r_ase, rtol=0, atol=1e-9 * dx)


@pytest.mark.parametrize("name", ["fire", "fire2", "lbfgs"])
def test_2d_never_moves_z_and_keeps_dim_times_n_buffers(name):
    opt, atoms, _, frames = trajectory(name, "sph", 2, steps=10)
    assert opt.dim == 2
    buffer = opt._s if name == "lbfgs" else opt.vel
    assert buffer.shape[-1] == 2 and buffer.shape[-2] == len(atoms)
    assert all(np.all(r[:, 2] == 0.0) for r, _ in frames)
    opt3, atoms3, _, _ = trajectory(name, "sph", 3, steps=2)
    assert opt3.dim == 3 and (opt3._s if name == "lbfgs" else opt3.vel).shape[-1] == 3


def test_lbfgs_holds_its_pairs_only_and_forms_the_step_in_the_oldest_slot():
    """2 memory vectors of dim N floats, no work vector: a history of 2 over 6 steps (the slots wrap,
    the step formed in the pair that leaves) stays on ASE's trajectory (with history 2)."""
    opt, atoms, _, frames = trajectory("lbfgs", "sph", 3, steps=6, memory=2)
    held = [v.nbytes for v in vars(opt).values() if isinstance(v, np.ndarray) and v.size >= len(atoms)]
    assert sorted(held) == [2 * len(atoms) * 3 * 8] * 2
    _, _, _, reference = trajectory("lbfgs", "ase", 3, steps=6, memory=2)
    for (r, e), (r_ase, e_ase) in zip(frames, reference):
        np.testing.assert_allclose(r, r_ase, rtol=0, atol=1e-9 / 16)
        assert e == pytest.approx(e_ase, rel=1e-9)


@pytest.mark.parametrize("name", ["fire", "fire2", "lbfgs"])
def test_fixed_particles_stay_and_the_rest_follows_ase(name):
    def fix_first(atoms):
        atoms.set_constraint(FixAtoms(indices=range(20)))

    # without KeepInDomain, which would move a fixed particle that the jitter put outside back in
    _, atoms, _, frames = trajectory(name, "sph", 2, steps=15, prepare=fix_first, keep_inside=False)
    _, _, _, reference = trajectory(name, "ase", 2, steps=15, prepare=fix_first, keep_inside=False)
    assert np.all(frames[-1][0][:20] == frames[0][0][:20])
    assert np.abs(frames[-1][0][20:] - frames[0][0][20:]).max() > 0
    np.testing.assert_allclose(frames[-1][0], reference[-1][0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["fire", "fire2", "lbfgs"])
def test_keep_in_domain_holds_for_every_step_and_matches_ase(name):
    """A domain with a thin part and sharp corners, long steps (c = 0.2): KeepInDomain cuts steps
    in ours exactly as in ASE's optimiser, and no particle is outside after any step."""
    domain = Difference(Box((0.2, 0.2), (0.8, 0.8)), Box((0.2, 0.26), (0.78, 0.74)))
    runs = []
    for backend in ("sph", "ase"):
        atoms, _ = fan_case(2, domain=domain, dx=1 / 48)
        own = {"lbfgs": {"memory": 5}, "fire": {"max_particle_step": None}}.get(name, {})  # like with like
        opt = make_optimizer(name, atoms, c=0.2, backend=backend, **own)
        outside = []
        opt.attach(lambda: outside.append(int((domain.phi(atoms.positions[:, :2]) >= 0).sum())))
        opt.run(fmax=0.0, steps=25)
        keep = [c for c in atoms.constraints if isinstance(c, KeepInDomain)]
        runs.append((atoms.positions.copy(), outside, keep[0].n_returned))
    (r, outside, returned), (r_ase, outside_ase, returned_ase) = runs
    assert max(outside[1:]) == 0 and returned == returned_ase
    np.testing.assert_allclose(r, r_ase, rtol=0, atol=1e-12)


@pytest.mark.parametrize("cls", [SPHFIRE, SPHLBFGS])
def test_attach_trajectory_log_and_irun(tmp_path, cls):
    atoms, _ = fan_case(2)
    atoms.calc.silence_scale_hint()
    path = tmp_path / "relax.traj"
    log = io.StringIO()
    opt = cls(atoms, logfile=log, trajectory=str(path), **({"dt": 0.01} if cls is SPHFIRE else {"alpha": 1.0}))
    calls = []
    opt.attach(lambda: calls.append(opt.nsteps), interval=2)
    for k, converged in enumerate(opt.irun(fmax=0.0, steps=6)):
        assert converged is False
    assert k == 6 and opt.nsteps == 6 and calls == [0, 2, 4, 6]
    opt.close()
    frames = read(str(path), index=":")
    assert len(frames) == 7
    np.testing.assert_array_equal(frames[-1].positions, atoms.positions)
    assert len(log.getvalue().splitlines()) == 8  # header + steps 0..6
    assert opt.run(fmax=1e3, steps=5) and opt.nsteps == 6  # converged: no step


def test_a_step_can_be_called_by_hand_with_given_forces():
    atoms, _ = fan_case(3)
    opt = SPHFIRE(atoms, logfile=None, dt=0.1, maxstep=1e-3)
    start = atoms.positions.copy()
    forces = np.zeros((len(atoms), 3))
    forces[0] = (1.0, 0.0, 0.0)
    opt.step(forces)
    moved = atoms.positions - start
    assert moved[0, 0] == pytest.approx(1e-3) and np.all(moved[1:] == 0.0)


@pytest.mark.parametrize("cls,kwargs,match", [
    (SPHLBFGS, {"memory": 0}, "memory must be an integer >= 1"),
    (SPHLBFGS, {"memory": 2.5}, "memory must be"),
    (SPHLBFGS, {"alpha": -1.0}, "alpha must be a positive"),
    (SPHLBFGS, {"maxstep": 0.0}, "maxstep must be positive"),
    (SPHFIRE, {"dt": 0.0}, "dt must be a positive"),
    (SPHFIRE, {"maxstep": -1.0}, "maxstep must be positive"),
    (SPHFIRE, {"dim": 4}, "dim must be None, 2 or 3"),
    (SPHFIRE, {"max_particle_step": 0.0}, "max_particle_step must be a positive finite"),
    (SPHFIRE, {"max_particle_step": np.inf}, "max_particle_step must be a positive finite"),
    (SPHFIRE2, {"dtmin": 0.0}, "dtmin must be a positive"),
    (SPHFIRE2, {"maxstep": -1.0}, "maxstep must be positive"),
    (SPHLBFGS, {"restart": "state.json"}, "restart: SPHLBFGS keeps no restart file"),
])
def test_bad_input_is_a_one_line_error(cls, kwargs, match):
    atoms, _ = fan_case(2)
    with pytest.raises(ValueError, match=match) as info:
        cls(atoms, logfile=None, **kwargs)
    assert "\n" not in str(info.value)


def test_max_particle_step_cuts_only_the_particles_that_would_move_further():
    """Two runs in step for 8 steps; at the 9th one cuts at the 90 % quantile of the other's moves: its moves equal
    the other's where they are shorter, and are cut to that length in the same direction where they are longer."""
    runs = []
    for _ in range(2):
        atoms, _ = fan_case(3)
        opt = make_optimizer("fire", atoms, max_particle_step=None, keep_inside=False)
        opt.run(fmax=0.0, steps=8)
        runs.append((opt, atoms, atoms.positions.copy()))
    (free, atoms_free, start), (cut, atoms_cut, start_cut) = runs
    np.testing.assert_array_equal(start, start_cut)
    free.step()
    move_free = atoms_free.positions - start
    lengths = np.linalg.norm(move_free, axis=1)
    cap = float(np.quantile(lengths, 0.9))
    cut.max_particle_step = cap
    cut.step()
    move_cut = atoms_cut.positions - start
    longer = lengths > cap
    assert 0 < longer.sum() < len(lengths)
    np.testing.assert_array_equal(move_cut[~longer], move_free[~longer])
    # the moves read back as differences of positions: to round-off of the positions (1e-12 of the cut)
    np.testing.assert_allclose(np.linalg.norm(move_cut[longer], axis=1), cap, rtol=0, atol=1e-12 * cap)
    np.testing.assert_allclose(move_cut[longer], move_free[longer] * (cap / lengths[longer])[:, None], rtol=0,
                               atol=1e-12 * cap)
    np.testing.assert_array_equal(cut.vel, free.vel)  # the velocities are kept


@pytest.mark.parametrize("dim", [2, 3])
def test_make_optimizer_cuts_fires_particle_moves(dim):
    """FIRE_PARTICLE_STEP: 0.01 h in 2D, 0.005 h in 3D (fewer list rebuilds); a run's moves stay within the cut;
    FIRE2 and ASE's backend have none, and refuse one."""
    from ase_sphrelax.drivers.optimizers import FIRE_PARTICLE_STEP

    assert FIRE_PARTICLE_STEP == {2: 0.01, 3: 0.005}
    atoms, _ = fan_case(dim)
    h = atoms.calc.parameters["h"]
    opt = make_optimizer("fire", atoms)
    expected = FIRE_PARTICLE_STEP[dim] * h
    assert opt.max_particle_step == expected and opt.todict()["max_particle_step"] == expected
    frames = [atoms.positions.copy()]
    opt.attach(lambda: frames.append(atoms.positions.copy()))
    opt.run(fmax=0.0, steps=10)
    moves = [np.linalg.norm(b - a, axis=1).max() for a, b in zip(frames[1:], frames[2:])]
    assert max(moves) <= expected * (1 + 1e-12)
    assert max(moves) >= expected * (1 - 1e-12)  # the cut acts in these steps: the test can fail
    assert make_optimizer("fire2", fan_case(dim)[0]).max_particle_step is None
    assert make_optimizer("fire", fan_case(dim)[0], max_particle_step=None).max_particle_step is None
    make_optimizer("fire", fan_case(dim)[0], backend="ase", max_particle_step=None)
    for name, backend in (("fire", "ase"), ("fire2", "sph")):
        with pytest.raises(ValueError, match="max_particle_step: only 'fire' with backend='sph'"):
            make_optimizer(name, fan_case(dim)[0], backend=backend, max_particle_step=0.01 * h)


def test_no_cut_without_a_verlet_list_or_through_a_filter():
    """The cut saves list rebuilds: none for a calculator without a list, none by default through a Filter (its rows
    may be a cell's too), where one can still be asked for."""
    from ase.calculators.lj import LennardJones
    from ase.filters import Filter

    atoms, _ = fan_case(3)
    atoms.calc = LennardJones(sigma=0.05, rc=0.15)
    assert make_optimizer("fire", atoms, h=0.1).max_particle_step is None
    atoms, _ = fan_case(3)
    moving = Filter(atoms, indices=range(30, len(atoms)))
    assert make_optimizer("fire", moving, keep_inside=False).max_particle_step is None
    assert make_optimizer("fire", moving, keep_inside=False, max_particle_step=0.02).max_particle_step == 0.02


def test_make_optimizer_refuses_an_unknown_backend():
    atoms, _ = fan_case(2)
    with pytest.raises(ValueError, match="backend must be one of"):
        make_optimizer("fire", atoms, backend="numpy")


@pytest.mark.parametrize("cls,ase_name", [(SPHFIRE, "FIRE"), (SPHFIRE2, "FIRE2"), (SPHLBFGS, "LBFGS")])
def test_a_filter_goes_through_ases_optimizable_and_matches_ase(cls, ase_name):
    """Not an Atoms: get_x / get_gradient / set_x on all 3 coordinates, the same steps as ASE's."""
    import ase.optimize
    from ase.filters import Filter

    runs = []
    for make in (cls, getattr(ase.optimize, ase_name)):
        atoms, _ = fan_case(2)
        atoms.calc.silence_scale_hint()
        moving = Filter(atoms, indices=range(30, len(atoms)))
        opt = make(moving, logfile=None, **({"alpha": 1.0, "memory": 4} if ase_name == "LBFGS" else {"dt": 0.05}))
        start = atoms.positions.copy()
        opt.run(fmax=0.0, steps=12)
        runs.append((start, atoms.positions.copy()))
    (start, r), (_, r_ase) = runs
    assert np.all(r[:30] == start[:30]) and np.abs(r[30:] - start[30:]).max() > 0
    np.testing.assert_allclose(r, r_ase, rtol=0, atol=1e-12)
