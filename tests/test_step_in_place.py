"""A step that moves ``atoms.positions`` in place and tests only the particles near the wall (issue 33, item 1).

SPHFIRE writes its new positions into ``atoms.positions`` itself (the old ones aside) when the only constraints are
:class:`KeepInDomain`; SPHFIRE and SPHLBFGS tell the constraint the longest move of the step and, from the calculator
(``wall_candidates``), which particles can be near the wall; after its step the optimiser's force request skips the
comparison of the positions (``forces_view(moved=True)``) and tells the neighbour list the step's longest move
(``moved_at_most``: it measures the displacements only once the bounds pass half its skin). None of it may change a
trajectory by a bit.
"""
import numpy as np
import pytest
from ase.constraints import FixAtoms
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ase_sphrelax import FanCalculator, neighbors
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Circle, Sphere
from ase_sphrelax.drivers import KeepInDomain, make_optimizer

SETTINGS = dict(deadline=None, database=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def ball_case(dim):
    """Long steps (``make_optimizer``'s c = 0.5) from a start jittered by 0.3 dx in a circle or sphere (Fan's
    level-set wall term, whose calculator knows the particles near the wall): KeepInDomain acts."""
    domain = Circle((0.5, 0.5), 0.2) if dim == 2 else Sphere((0.5, 0.5, 0.5), 0.2)
    dx = 1 / 64 if dim == 2 else 1 / 24
    atoms = fill(domain, dx, jitter=0.3, seed=0)
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    return atoms, domain


def run(name, dim, plain, steps=25):
    """Positions after ``steps`` steps and KeepInDomain's count; ``plain``: the copy into atoms.positions and the
    level set of every particle (a constraint besides KeepInDomain, no calculator hint). ``name`` "fire cut": FIRE
    with make_optimizer's cut of each particle's move (then only the old positions of the particles that can leave
    are kept)."""
    atoms, domain = ball_case(dim)
    if plain:
        atoms.calc.wall_candidates = lambda domain: None
    own = {"lbfgs": {"memory": 5}, "fire": {"max_particle_step": None}, "fire cut": {}}[name]
    opt = make_optimizer(name.split()[0], atoms, c=0.5, **own)
    if plain:
        atoms.set_constraint(list(atoms.constraints) + [FixAtoms(indices=[])])
    tested = []
    keep = next(c for c in atoms.constraints if isinstance(c, KeepInDomain))
    outside = keep._outside
    keep._outside = lambda r_pc: tested.append(len(r_pc)) or outside(r_pc)
    opt.run(fmax=0.0, steps=steps)
    return atoms.positions.copy(), keep.n_returned, tested, len(atoms)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", ["fire", "fire cut", "lbfgs"])
def test_in_place_steps_and_the_wall_hint_leave_the_trajectory_as_it_was(name, dim):
    r_fast, returned, tested, n = run(name, dim, plain=False)
    r_plain, returned_plain, tested_plain, _ = run(name, dim, plain=True)
    assert returned == returned_plain and returned > 0  # the constraint acted, the same number of times
    assert np.array_equal(r_fast, r_plain)  # bit for bit
    assert set(tested_plain) == {n}  # every particle's level set at every step
    assert min(tested) < n  # the hint took: some steps tested the candidates only


@settings(max_examples=60, **SETTINGS)
@given(seed=st.integers(0, 2**16), n=st.integers(1, 400), margin=st.floats(0.01, 0.2),
       fraction=st.sampled_from([0.0, 0.25, 0.4999, 0.5, 0.7, 1.5]), on_edges=st.booleans(), with_phi=st.booleans())
def test_adjust_moved_finds_what_testing_every_particle_finds(seed, n, margin, fraction, on_edges, with_phi):
    """Old positions inside a circle, some on the candidates' edge (phi = -margin) or at the wall; moves up to
    ``fraction * margin`` (some exactly that long). The candidates are the particles with phi > -margin (the
    calculator's promise), with their level set or without; above half the margin the hint must be ignored (here
    then: no candidates at all)."""
    rng = np.random.default_rng(seed)
    domain = Circle((0.0, 0.0), 1.0)
    radius = rng.uniform(0.0, 1.0, n) ** 0.5
    if on_edges:  # the candidates' edge and the wall itself (phi = -1e-12)
        radius[: n // 3] = 1.0 - margin
        radius[n // 3: n // 2] = 1.0 - 1e-12
    angle = rng.uniform(0, 2 * np.pi, n)
    old = np.zeros((n, 3))
    old[:, 0], old[:, 1] = radius * np.cos(angle), radius * np.sin(angle)
    move = rng.normal(size=(n, 3))
    move[:, 2] = 0.0
    length = fraction * margin * rng.uniform(0.0, 1.0, n)
    length[: max(1, n // 5)] = fraction * margin  # the longest move, reached
    move *= (length / np.maximum(np.linalg.norm(move, axis=1), 1e-300))[:, None]
    new = old + move
    longest = float(np.linalg.norm(new - old, axis=1).max())
    phi = domain.phi(old[:, :2]).reshape(-1)
    candidates = np.flatnonzero(phi > -margin) if fraction < 0.5 else np.zeros(0, dtype=int)
    everyone, hinted = KeepInDomain(domain), KeepInDomain(domain)
    expected, got = new.copy(), new.copy()
    everyone.adjust_moved(old, expected)
    hinted.adjust_moved(old, got, longest=longest, candidates=candidates, margin=margin,
                        candidates_phi=phi[candidates] if with_phi else None)
    assert np.array_equal(got, expected)
    assert (hinted.n_returned, hinted.n_left_outside) == (everyone.n_returned, everyone.n_left_outside)
    assert np.all(domain.phi(got[:, :2]) < 0.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_fans_wall_candidates_hold_every_particle_within_the_margin(dim):
    """After every step (its evaluation), each particle that is not a candidate lies at least the margin inside."""
    domain = Circle((0.5, 0.5), 0.2) if dim == 2 else Sphere((0.5, 0.5, 0.5), 0.2)
    dx = 1 / 64 if dim == 2 else 1 / 20
    atoms = fill(domain, dx, jitter=0.2, seed=1)
    calc = atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    assert calc.wall_candidates(domain) is None  # nothing evaluated yet
    opt = make_optimizer("fire", atoms, c=0.05)
    checked = []

    def check():
        atoms.get_forces()
        found = calc.wall_candidates(domain)
        if found is None:  # the first evaluation scans bins, no list
            return
        candidates, margin, phi_k = found
        assert margin == pytest.approx(calc.model.h + 0.5 * calc.nlist.skin)
        rest = np.setdiff1d(np.arange(len(atoms)), candidates)
        assert np.all(domain.phi(atoms.positions[rest, :dim]) <= -margin)
        np.testing.assert_allclose(phi_k, domain.phi(atoms.positions[candidates, :dim]).reshape(-1), rtol=0,
                                   atol=1e-15)  # the candidates' level set there
        assert len(rest) > 0
        checked.append(calc.nlist.builds)

    opt.attach(check)
    opt.run(fmax=0.0, steps=30)
    assert len(checked) >= 25 and checked[-1] > checked[0]  # over several builds of the list
    assert calc.wall_candidates(Circle((0.5, 0.5), 0.2) if dim == 2 else Sphere((0.5, 0.5, 0.5), 0.2)) is None


def test_forces_view_after_a_step_evaluates_without_comparing_positions():
    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, 1 / 32, jitter=0.1, seed=0)
    calc = atoms.calc = FanCalculator(h=2.6 / 32, dx=1 / 32, domain=domain)
    calc.forces_view(atoms)  # the first evaluation (one-shot bins)
    first = calc.forces_view(atoms, moved=True).copy()  # a step that moved nothing: evaluated anew (the list)
    evaluations = calc._evaluations
    calc.forces_view(atoms)
    assert calc._evaluations == evaluations  # cached: the positions compared equal
    again = calc.forces_view(atoms, moved=True)
    assert calc._evaluations == evaluations + 1 and np.array_equal(again, first)  # the same list, the same bits
    atoms.numbers[0] = 2  # numbers are still compared
    assert calc._changes(atoms, moved=True) == ["positions", "numbers"]
    assert calc.check_state(atoms) == ["numbers"]


@pytest.mark.parametrize("bad", ["nan", "inf", "off_plane"])
def test_the_snapshots_scan_still_refuses_bad_positions_at_a_later_evaluation(bad):
    """The calculator's copy of the positions is scanned in the same pass (finite, the plane of 2D atoms): a bad
    position that appears after the first evaluation (the copy into the kept array) is refused by the next one."""
    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, 1 / 32, jitter=0.1, seed=0)
    calc = atoms.calc = FanCalculator(h=2.6 / 32, dx=1 / 32, domain=domain)
    calc.forces_view(atoms)
    calc.forces_view(atoms, moved=True)  # the kept copy is in use from here on
    atoms.positions[1, 0] += 1e-3
    calc.forces_view(atoms, moved=True)
    assert calc.dim == 2
    atoms.positions[7, {"nan": 0, "inf": 1, "off_plane": 2}[bad]] = {"nan": np.nan, "inf": np.inf, "off_plane": 1e-3}[bad]
    match = "finite" if bad != "off_plane" else "z"
    with pytest.raises(ValueError, match=match):
        calc.forces_view(atoms, moved=True)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", ["fire", "lbfgs"])
def test_the_step_bounds_every_move_it_reports_to_the_neighbour_list(name, dim):
    """The longest move a step passes on (``forces_view(moved_at_most=)``, KeepInDomain's corrections included) is
    at least every particle's move since the calculator's previous evaluation; with the bound the run keeps the
    same lists and the same trajectory as one where every displacement is measured."""
    runs = []
    for use_bound in (True, False):
        atoms, domain = ball_case(dim)
        calc = atoms.calc
        own = {"lbfgs": {"memory": 5}, "fire": {"max_particle_step": None}}[name]
        opt = make_optimizer(name, atoms, c=0.5, **own)
        seen = {"last": atoms.positions.copy(), "bounded": 0, "measured": 0}
        original = neighbors.NeighborList.update

        def update(self, positions, *args, moved_at_most=None, _seen=seen, _use=use_bound, **kwargs):
            moved = float(np.sqrt(((positions - _seen["last"]) ** 2).sum(axis=1).max()))
            if moved_at_most is not None:
                assert moved <= moved_at_most * (1 + 1e-12)
                _seen["bounded"] += 1
            _seen["last"] = np.array(positions)
            return original(self, positions, *args, moved_at_most=moved_at_most if _use else None, **kwargs)

        neighbors.NeighborList.update = update
        measure = neighbors._max_displacement2
        neighbors._max_displacement2 = lambda *a: seen.__setitem__("measured", seen["measured"] + 1) or measure(*a)
        try:
            opt.run(fmax=0.0, steps=30)
        finally:
            neighbors.NeighborList.update = original
            neighbors._max_displacement2 = measure
        keep = next(c for c in atoms.constraints if isinstance(c, KeepInDomain))
        runs.append((atoms.positions.copy(), calc.nlist.builds, seen["bounded"], seen["measured"], keep.n_returned))
    (r, builds, bounded, measured, returned), (r_all, builds_all, _, measured_all, returned_all) = runs
    assert bounded >= 25 and returned > 0
    assert np.array_equal(r, r_all) and builds == builds_all and returned == returned_all
    assert measured < measured_all  # some displacements were not measured


def test_neighbour_list_measures_once_the_bounds_pass_half_the_skin():
    from ase_sphrelax.neighbors import NeighborList

    rng = np.random.default_rng(0)
    r_pc = rng.uniform(0, 1, (500, 3))
    nl = NeighborList(0.1, skin=0.02)
    cell, pbc = np.eye(3), [False] * 3
    nl.update(r_pc, cell, pbc)
    calls = []
    measure = neighbors._max_displacement2
    neighbors._max_displacement2 = lambda *a: calls.append(1) or measure(*a)
    try:
        for k in range(4):  # 4 moves of 0.002: the bound 0.008 < 0.01 = skin / 2, nothing measured
            r_pc = r_pc + 0.002 / np.sqrt(3)
            assert not nl.update(r_pc, cell, pbc, moved_at_most=0.002)
        assert calls == []
        r_pc = r_pc + 0.0019 / np.sqrt(3)  # the bound would pass 0.01: measured (0.0099), kept
        assert not nl.update(r_pc, cell, pbc, moved_at_most=0.003)
        assert calls == [1]
        r_pc = r_pc + 0.00005 / np.sqrt(3)  # from the measured 0.0099 on: 0.00995, kept unmeasured
        assert not nl.update(r_pc, cell, pbc, moved_at_most=0.00005)
        assert calls == [1]
        assert not nl.update(r_pc, cell, pbc)  # no bound: measured
        assert calls == [1, 1]
        r_pc = r_pc + 0.001 / np.sqrt(3)  # 0.01095 > 0.01: rebuilt
        assert nl.update(r_pc, cell, pbc, moved_at_most=0.001)
        builds = nl.builds
        r_pc = r_pc + 0.009 / np.sqrt(3)  # a new build: the bounds start from 0 again
        assert not nl.update(r_pc, cell, pbc, moved_at_most=0.009) and nl.builds == builds
    finally:
        neighbors._max_displacement2 = measure


@pytest.mark.parametrize("how", ["irun", "observer"])
def test_numbers_changed_between_steps_are_seen(how):
    """``run`` without observers lets the calculator skip comparing the numbers after a step (no other code ran);
    numbers changed by the caller of ``irun`` between steps, or by an observer, are compared and seen."""
    atoms, domain = ball_case(2)
    calc = atoms.calc
    opt = make_optimizer("fire", atoms)
    calls = []
    changes = calc._changes

    def spy(atoms, moved=False, numbers_kept=False):
        found = changes(atoms, moved, numbers_kept)
        calls.append((numbers_kept, found))
        return found

    calc._changes = spy
    opt.run(fmax=0.0, steps=3)
    assert any(kept for kept, _ in calls)  # run without observers: the numbers not compared after the steps
    calls.clear()
    if how == "irun":
        for k, _ in enumerate(opt.irun(fmax=0.0, steps=3)):
            if k == 1:
                atoms.numbers[5] = 7
    else:
        def change():
            if opt.nsteps == 4:
                atoms.numbers[5] = 7
        opt.attach(change)
        opt.run(fmax=0.0, steps=3)
    assert not any(kept for kept, _ in calls)  # irun or an observer: everything compared
    assert sum("numbers" in found for _, found in calls) == 1  # and the change seen once
