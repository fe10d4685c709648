"""Issue 10 item 3: every built-in scene has N v0 consistent with its volume, and relaxing it helps.

The former box scene [0.3, 0.7]^3 held 1728 dx^3 = 0.0527 of its volume 0.064 and its kernel-sum
error grew from 0.022 to 0.150 when relaxed. Each scene runs through ``sphrelax relax`` (LBFGS from
make_optimizer, at a coarser dx where the default is large) and must lower E, the mean and max
|Σ V W - 1| and the mean h|Σ V ∇W| of its interior particles, with no particle outside.
"""
import json

import numpy as np
import pytest

from ase_sphrelax.cli import main
from ase_sphrelax.cli.relax import VOLUME_TOL
from ase_sphrelax.cli.scene import BUILTIN_DOMAINS, make_scene

SCENES = [("circle", 2, None), ("box", 2, None), ("box", 3, None), ("sphere", 3, None), ("periodic", 2, None),
          ("periodic", 3, None)]
RELAXED = [("circle", 2, 1 / 128), ("box", 2, 1 / 128), ("box", 3, None), ("sphere", 3, None),
           ("periodic", 2, 1 / 48), ("periodic", 3, 1 / 12)]
KERNEL_SUM_NEAR_OPTIMUM = {"circle": 0.01, "box": 0.01, "periodic": 0.01}  # |mean Σ V W - 1/v_c| after relaxing


def test_every_builtin_scene_is_covered():
    assert {name for name, _, _ in SCENES} == set(BUILTIN_DOMAINS) == {name for name, _, _ in RELAXED}


@pytest.mark.parametrize("name, dim, dx", SCENES, ids=[f"{n}-{d}d" for n, d, _ in SCENES])
def test_particle_volume_times_n_matches_the_domain(name, dim, dx):
    scene = make_scene(name, dim, dx)
    volume = scene.domain.volume if scene.domain is not None else abs(np.linalg.det(scene.atoms.cell.array[:dim, :dim]))
    assert len(scene.atoms) * scene.dx**dim == pytest.approx(volume, rel=VOLUME_TOL)


def test_box_mesh_follows_the_box_for_any_dx():
    """A box's mesh starts at its corner: with sides a whole number of dx, N dx^d = V exactly."""
    scene = make_scene("box", 2, 0.375 / 30)
    assert len(scene.atoms) == 30 * 30


@pytest.mark.slow
@pytest.mark.parametrize("name, dim, dx", RELAXED, ids=[f"{n}-{d}d" for n, d, _ in RELAXED])
def test_relaxing_each_builtin_scene_lowers_e_and_the_kernel_sum_errors(tmp_path, name, dim, dx):
    args = ["relax", "--domain", name, "--dim", str(dim), "--optimizer", "lbfgs", "--steps", "100",
            "--out", str(tmp_path)] + ([] if dx is None else ["--dx", str(dx)])
    assert main(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(f"JSON has {c}"))
    before, after = summary["quality_before"], summary["quality_after"]
    assert summary["energy_after"] < summary["energy_before"]
    for key in ("kernel_sum_error_mean", "kernel_sum_error_max", "gradient_error_mean"):
        assert after[key] < before[key], key
    assert after["n_interior"] > 0
    assert after.get("n_outside", 0) == 0
    # the relaxed interior sits near Fan's lattice optimum 1/v_c, not at 1; the bounded 3D scenes at their
    # default dx have an interior only about 4 dx across, where the boundary layer sets the density (sphere:
    # 0.984 against 1/v_c = 1.006), so they are not held to it
    offset = abs(after["kernel_sum_mean"] - summary["lattice_optimum"]["inverse_v_c"])
    print(f"{name} {dim}D: mean Σ V W {after['kernel_sum_mean']:.5f}, 1/v_c {summary['lattice_optimum']['inverse_v_c']:.5f}")
    if dim == 2 or name == "periodic":
        assert offset < KERNEL_SUM_NEAR_OPTIMUM[name]
