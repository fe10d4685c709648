"""ALARIC's domain wall: ``wall_form="linear"`` (default, ``m c_s^2 phi_+ / L``) or ``"quadratic"``
(``m c_s^2 phi_+^2 / (2 L^2)``, no force jump at the boundary: reproductions/alaric-fig8-3d-isolate).

FD forces next to, on and outside the boundary; the quadratic wall's force continuous at phi = 0; a particle
crossing the wall under leapfrog: energy error O(dt^2) (quadratic) against O(dt) (linear); the linear default
unchanged to the bit; the CLI option reaching the calculator; the example's smooth wall = the package's form.
"""
import json
import subprocess
import sys

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces
from examples_loader import load_script
from hypothesis import given, settings, strategies as st

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.calculators.alaric import QUADRATIC_WALL_FACTOR
from ase_sphrelax.domains import Circle, Sphere

def _density(x):
    return 1.0 + 0.3 * x[:, 0]


def _gradient(x):
    return np.eye(x.shape[1])[0] * 0.3 + 0.0 * x


def _domain(dim, kind):
    if dim == 3:
        return Sphere((0.0, 0.0, 0.0), 1.0)
    return Circle((0.0, 0.0), 1.0) if kind == "disc" else Circle((0.0, 0.0), 1.0).to_polygon(24)


def _edge_atoms(dim, domain, seed=0, phis=(-1e-3, 1e-3, 0.0, 0.03)):
    """Random particles in the unit ball, the first four moved to ``phis`` along random directions (default: just
    inside, just outside, on the boundary (phi = 0 to rounding), well outside)."""
    n = {2: 40, 3: 70}[dim]
    rng = np.random.default_rng(seed)
    u_nd = rng.normal(size=(n, dim))
    u_nd /= np.linalg.norm(u_nd, axis=1)[:, None]
    x_nd = u_nd * rng.uniform(0.0, 0.9, n)[:, None] ** (1.0 / dim)
    for k, phi in enumerate(phis):
        x = u_nd[k]
        # the boundary along u (a polygon's is inside the circle): bisect phi(t u) = phi
        lo, hi = 0.5, 1.2
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if float(domain.phi(mid * x[None])[0]) < phi else (lo, mid)
        x_nd[k] = 0.5 * (lo + hi) * x
    pos = np.zeros((n, 3))
    pos[:, :dim] = x_nd
    return Atoms(numbers=np.zeros(n, int), positions=pos, cell=4.0 * np.eye(3), pbc=False)


def _calc(dim, domain, **options):
    return ALARICCalculator(target_density=_density, target_gradient=_gradient, dim=dim, domain=domain, h_tol=1e-14,
                            **options)


@pytest.mark.parametrize("wall_form", ["linear", "quadratic"])
@pytest.mark.parametrize("dim,kind", [(2, "disc"), (2, "polygon"), (3, "ball")])
@pytest.mark.parametrize("boundary", ["wall", "mirror"])
def test_forces_are_the_negative_gradient_at_the_boundary(wall_form, dim, kind, boundary):
    domain = _domain(dim, kind)
    atoms = _edge_atoms(dim, domain)
    atoms.calc = _calc(dim, domain, wall_form=wall_form, boundary=boundary)
    f = atoms.get_forces()
    phi = np.asarray(domain.phi(atoms.positions[:4, :dim]))
    np.testing.assert_allclose(phi, [-1e-3, 1e-3, 0.0, 0.03], atol=1e-12)
    # the linear wall has a kink at phi = 0 (no derivative there): its on-boundary particle is left out
    idx = [0, 1, 3] if wall_form == "linear" else [0, 1, 2, 3]
    fd = calculate_numerical_forces(atoms, eps=1e-6, iatoms=idx, icarts=list(range(dim)))
    np.testing.assert_allclose(f[idx][:, :dim], fd[:, :dim], rtol=0, atol=1e-6 * np.abs(f).max())
    # the wall energy is the formula's: particles 1 and 3 outside (phi 1e-3, 0.03), against no wall (L huge)
    calc = atoms.calc
    n, m, volume = len(atoms), calc.mass, float(domain.volume)
    factor = 0.1 if wall_form == "linear" else QUADRATIC_WALL_FACTOR
    length = factor * (volume / n) ** (1.0 / dim)
    expected = m * (1e-3 + 0.03) / length if wall_form == "linear" else m * (1e-3**2 + 0.03**2) / (2 * length**2)
    e = atoms.get_potential_energy()
    atoms.calc = _calc(dim, domain, wall_form=wall_form, boundary=boundary, mass=m, wall_length=1e12)
    assert abs(e - atoms.get_potential_energy() - expected) < 1e-9 * expected


@settings(max_examples=6, deadline=None, database=None)
@given(wall_form=st.sampled_from(["linear", "quadratic"]), dim=st.sampled_from([2, 3]),
       seed=st.integers(min_value=0, max_value=2**31 - 1),
       phis=st.lists(st.floats(min_value=-0.05, max_value=0.05).filter(lambda x: abs(x) > 1e-4), min_size=4,
                     max_size=4))
def test_forces_are_the_negative_gradient_property(wall_form, dim, seed, phis):
    """Random starts with four particles at random depths in and out of the domain (away from the kink by more
    than the FD step): forces = -grad U for both walls."""
    domain = _domain(dim, "disc")
    atoms = _edge_atoms(dim, domain, seed=seed % 1000, phis=tuple(phis))
    atoms.calc = _calc(dim, domain, wall_form=wall_form)
    f = atoms.get_forces()
    fd = calculate_numerical_forces(atoms, eps=1e-6, iatoms=[0, 1, 2, 3], icarts=list(range(dim)))
    np.testing.assert_allclose(f[:4, :dim], fd[:, :dim], rtol=0, atol=1e-6 * np.abs(f).max())


def _force_across(wall_form, phi):
    domain = Circle((0.0, 0.0), 1.0)
    atoms = _edge_atoms(2, domain)
    atoms.positions[0, :2] *= (1.0 + phi) / np.linalg.norm(atoms.positions[0, :2])
    atoms.calc = _calc(2, domain, wall_form=wall_form, mass=1.0, wall_length=0.05)
    return atoms.get_forces()[0, :2]


def test_quadratic_wall_force_is_continuous_at_the_boundary():
    """Crossing phi = 0 (from -1e-9 to +1e-9): the quadratic wall's force changes by O(1e-9 / L^2); the linear one
    jumps by m c_s^2 / L = 20 (m = 1, L = 0.05)."""
    jump = {w: np.linalg.norm(_force_across(w, 1e-9) - _force_across(w, -1e-9)) for w in ("linear", "quadratic")}
    assert jump["quadratic"] < 1e-5
    assert abs(jump["linear"] - 20.0) < 1e-3
    # and the quadratic wall force -> 0 as phi -> 0+: m c^2 phi / L^2 on top of the SPH force
    base = _force_across("quadratic", 0.0)
    for phi in (1e-2, 1e-4, 1e-6):
        wall_part = np.linalg.norm(_force_across("quadratic", phi) - base)
        assert abs(wall_part - phi / 0.05**2) < 0.02 * phi / 0.05**2 + 1e-6


def _leapfrog_energy_error(wall_form, dt):
    """One particle in a periodic cell (its SPH density, from its own images, does not depend on where it is: only
    the wall acts; uniform target) sent at speed 1 through the unit circle's boundary and back (velocity Verlet,
    total time 0.6); the largest |E - E_0| on the way (after the particle is back inside, time reversibility cancels
    most of a lone particle's error; in a many-body run the error made inside the wall is the kick that stays)."""
    domain = Circle((1.5, 1.5), 1.0)
    atoms = Atoms(numbers=[0], positions=[[2.3, 1.5, 0.0]], cell=[3.0, 3.0, 0.0], pbc=[True, True, False])
    calc = ALARICCalculator(target_density=lambda x: np.ones(len(x)), dim=2, domain=domain, mass=1.0,
                            wall_form=wall_form, wall_length=0.05)
    calc.silence_scale_hint()
    atoms.calc = calc
    v = np.array([1.0, 0.0, 0.0])
    f = atoms.get_forces()[0]
    e0 = atoms.get_potential_energy() + 0.5 * v @ v
    error = 0.0
    for _ in range(int(round(0.6 / dt))):
        v = v + 0.5 * dt * f
        atoms.positions = atoms.positions + dt * v
        f = atoms.get_forces()[0]
        v = v + 0.5 * dt * f
        error = max(error, abs(atoms.get_potential_energy() + 0.5 * v @ v - e0))
    assert atoms.positions[0, 0] < 2.45 and v[0] < 0  # came back
    return error


def test_leapfrog_energy_error_is_second_order_for_the_quadratic_wall():
    """Halving dt: the quadratic wall's energy error shrinks 4x (O(dt^2)), the linear wall's 2x (O(dt): the force
    jump m c_s^2 / L = 20, error ~ that jump times the step's path, v dt); measured 8.0e-4, 2.0e-4, 5.0e-5 against
    4.1e-2, 2.0e-2, 1.0e-2."""
    dts = (0.004, 0.002, 0.001)
    quad = np.array([_leapfrog_energy_error("quadratic", dt) for dt in dts])
    lin = np.array([_leapfrog_energy_error("linear", dt) for dt in dts])
    np.testing.assert_allclose(quad[:-1] / quad[1:], 4.0, rtol=0.1)
    np.testing.assert_allclose(lin[:-1] / lin[1:], 2.0, rtol=0.1)
    assert np.all(lin > 10 * quad)


PINNED_ENERGY = float.fromhex("0x1.4706e795340e0p-1")  # computed on bca51d1, before wall_form existed
PINNED_WALL_FORCE = [float.fromhex("-0x1.007ae4a50e4b7p+1"), float.fromhex("-0x1.560c7e4addc28p+0")]
PINNED_WALL_LENGTH = float.fromhex("0x1.cb292f7603cc5p-6")


def _pinned_atoms():
    rng = np.random.default_rng(20)
    n = 40
    r = np.sqrt(rng.uniform(0.0, 1.0, n)) * 1.02
    t = rng.uniform(0.0, 2 * np.pi, n)
    pos = np.zeros((n, 3))
    pos[:, 0] = r * np.cos(t)
    pos[:, 1] = r * np.sin(t)
    return Atoms(numbers=np.zeros(n, int), positions=pos, cell=[4.0, 4.0, 0.0], pbc=[False, False, False])


@pytest.mark.parametrize("options", [{}, {"wall_form": "linear"}])
def test_linear_default_is_unchanged_to_the_bit(options):
    atoms = _pinned_atoms()
    atoms.calc = ALARICCalculator(target_density=_density, target_gradient=_gradient, dim=2,
                                  domain=Circle((0, 0), 1.0), boundary="wall", **options)
    assert atoms.get_potential_energy() == PINNED_ENERGY
    assert atoms.calc._wall == PINNED_WALL_LENGTH
    assert list(atoms.get_forces()[7, :2]) == PINNED_WALL_FORCE  # particle 7: the one outside (r = 1.013)


@pytest.mark.parametrize("options,name", [({"wall_form": "cubic"}, "wall_form"), ({"wall_form": None}, "wall_form"),
                                          ({"wall_length": -1.0}, "wall_length"),
                                          ({"wall_form": "quadratic", "wall_length": 0.0}, "wall_length")])
def test_bad_wall_options_are_refused(options, name):
    with pytest.raises(ValueError, match=name):
        ALARICCalculator(target_density=_density, dim=2, domain=Circle((0, 0), 1.0), **options)


def test_quadratic_default_length_follows_n():
    calc = ALARICCalculator(target_density=_density, dim=2, domain=Circle((0, 0), 1.0), wall_form="quadratic")
    assert calc.quadratic_wall_length(100, 2) == QUADRATIC_WALL_FACTOR * (np.pi / 100) ** 0.5
    calc.set(wall_length=0.3)
    assert calc.quadratic_wall_length(100, 2) == 0.3


def _stand_alone_smooth_wall(length_factor, **kwargs):
    """The first version of reproductions/lib/alaric_fig8_isolate.py's smooth_wall_calculator (before the package option),
    which made the stored fig8_3d_isolate results: the linear wall switched off, the quadratic one added."""

    class SmoothWallALARIC(ALARICCalculator):
        def evaluate(self, st, properties):
            self._wall = np.inf
            out = super().evaluate(st, properties)
            p, d, n = self.parameters, st.dim, len(st.r_pc)
            length = length_factor * (float(p.domain.volume) / n) ** (1.0 / d)
            phi_p, normal_pd = p.domain.phi_and_normal(self.points(st.atoms.positions, st.atoms))
            depth_p = np.maximum(np.asarray(phi_p, dtype=float), 0.0)
            k = self.mass * p.cs2 / length**2
            out["energies"] = out["energies"] + 0.5 * k * depth_p**2
            out["energy"] = float(out["energies"].sum())
            if "forces" in out:
                out["forces"] = out["forces"].copy()
                out["forces"][:, :d] -= (k * depth_p)[:, None] * np.asarray(normal_pd, dtype=float)[:, :d]
            return out

    return SmoothWallALARIC(**kwargs)


def _example_module():
    return load_script("reproductions/lib/alaric_fig8_isolate.py")


@pytest.mark.parametrize("length_factor", [0.5, 1.0])
def test_example_smooth_wall_is_the_package_quadratic_wall(length_factor):
    """The stored Fig. 8 3D isolate runs are reproducible with the package: the example's smooth_wall_calculator
    (now ``wall_form="quadratic"``) and its stand-alone first version give the same energy and forces."""
    domain = Sphere((0.0, 0.0, 0.0), 1.0)
    kwargs = dict(target_density=_density, target_gradient=_gradient, dim=3, domain=domain, boundary="mirror")
    results = []
    for calc in (_stand_alone_smooth_wall(length_factor, **kwargs),
                 _example_module().smooth_wall_calculator(length_factor, **kwargs)):
        atoms = _edge_atoms(3, domain, seed=2)
        atoms.calc = calc
        results.append((atoms.get_potential_energy(), atoms.get_forces()))
    (e_old, f_old), (e_new, f_new) = results
    assert abs(e_new - e_old) <= 1e-12 * abs(e_old)
    np.testing.assert_allclose(f_new, f_old, rtol=0, atol=1e-12 * np.abs(f_old).max())
    if length_factor == QUADRATIC_WALL_FACTOR:  # the package default itself
        atoms = _edge_atoms(3, domain, seed=2)
        atoms.calc = ALARICCalculator(wall_form="quadratic", **kwargs)
        assert atoms.get_potential_energy() == e_new


def test_cli_wall_form_reaches_the_calculator(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "density", "--profile", "eq49", "--dim", "2",
                           "--n", "60", "--split", "0", "--max-steps", "3", "--no-polish", "--wall-form", "quadratic",
                           "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((out / "summary.json").read_text())["wall_form"] == "quadratic"
    bad = subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "density", "--wall-form", "cubic", "--out",
                          str(tmp_path / "bad")], capture_output=True, text=True, timeout=600)
    assert bad.returncode != 0 and "--wall-form" in bad.stderr
    one_d = subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "density", "--wall-form", "quadratic", "--out",
                            str(tmp_path / "bad1d")], capture_output=True, text=True, timeout=600)
    assert one_d.returncode == 2 and "--wall-form is for --dim 2 or 3" in one_d.stderr
    assert "Traceback" not in one_d.stderr


@pytest.mark.parametrize("wall_form", ["linear", "quadratic"])
def test_stress_includes_the_wall(wall_form):
    """A periodic 3D cell with a ball domain inside it (about half the particles outside): the stress is the strain
    derivative of the energy, wall included (the wall's share comes in through -F_ext (x) x)."""
    from ase.calculators.fd import calculate_numerical_stress

    rng = np.random.default_rng(5)
    grid = (np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) + 0.5) / 5
    atoms = Atoms(numbers=np.zeros(len(grid), int), positions=grid + rng.uniform(-0.03, 0.03, grid.shape),
                  cell=np.eye(3), pbc=True)
    domain = Sphere((0.5, 0.5, 0.5), 0.4)
    atoms.calc = _calc(3, domain, wall_form=wall_form)
    stress = atoms.get_stress()
    assert np.sum(np.asarray(domain.phi(atoms.positions)) > 0) > 20
    with_wall = atoms.get_potential_energy()
    fd = calculate_numerical_stress(atoms, eps=1e-6)
    np.testing.assert_allclose(stress, fd, atol=1e-6 * np.abs(stress).max())
    atoms.calc = _calc(3, domain, wall_form=wall_form, mass=atoms.calc.mass, wall_length=1e12)
    assert with_wall - atoms.get_potential_energy() > 0.1 * abs(with_wall)  # the wall carries a real share
    assert np.abs(atoms.get_stress() - stress).max() > 0.1 * np.abs(stress).max()
