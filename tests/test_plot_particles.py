"""``plot_particles``: markers for a few particles, an image of per-pixel means when the markers would be below a
pixel or two (a million particles), the same colour range either way."""
import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from ase_sphrelax import plotting  # noqa: E402
from ase_sphrelax.build import fill  # noqa: E402
from ase_sphrelax.domains import Circle, Sphere  # noqa: E402


@pytest.mark.parametrize("dx, image", [(1 / 64, False), (1 / 1200, True)])
def test_dense_scenes_are_drawn_as_pixel_means(dx, image, tmp_path, monkeypatch):
    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, dx, jitter=0.1, seed=0)
    drawn = []
    means = plotting._pixel_means
    monkeypatch.setattr(plotting, "_pixel_means", lambda *a: drawn.append(a) or means(*a))
    path = plotting.plot_particles(atoms, atoms.positions[:, 0], tmp_path / "p.png", domain=domain, dx=dx)
    assert bool(drawn) is image
    with Image.open(path) as png:
        assert png.size[0] > 500
    if image:
        ax, r_pc, value_p, lo, hi, pixels, vmin, vmax = drawn[0]
        mean = ax.images[0].get_array()
        assert mean.shape == (pixels, pixels)
        filled = ~np.ma.getmaskarray(mean)
        # every pixel inside the disc (by its centre, a pixel in from the rim) holds particles, none outside
        xx, yy = np.meshgrid(np.linspace(lo[0], hi[0], pixels, endpoint=False) + (hi[0] - lo[0]) / (2 * pixels),
                             np.linspace(lo[1], hi[1], pixels, endpoint=False) + (hi[1] - lo[1]) / (2 * pixels))
        phi = domain.phi(np.column_stack([xx.ravel(), yy.ravel()])).reshape(pixels, pixels)
        pixel = (hi[0] - lo[0]) / pixels
        assert filled[phi < -2 * pixel].all() and not filled[phi > 2 * pixel].any()
        # a pixel's mean lies within its particles' values: here x, so within the pixel's own x-range
        assert np.all(np.abs(mean[filled] - xx[filled]) <= pixel)


def test_a_dense_3d_slice_is_drawn_as_pixel_means(tmp_path, monkeypatch):
    """The slab of a sphere at dx = 1/1200 (its particles 480 spacings across): an image, no empty pixel inside."""
    domain = Sphere((0.5, 0.5, 0.5), 0.2)
    dx = 1 / 1200
    keep = np.linspace(0.3, 0.7, 481)
    xx, yy = np.meshgrid(keep, keep)
    inside = (xx - 0.5) ** 2 + (yy - 0.5) ** 2 < 0.2**2
    r_pc = np.column_stack([xx[inside], yy[inside], np.full(inside.sum(), 0.5)])
    r_pc = np.concatenate([r_pc, r_pc + [0.0, 0.0, 0.1], r_pc - [0.0, 0.0, 0.1]])  # two layers outside the slab
    from ase import Atoms

    atoms = Atoms(positions=r_pc)
    drawn = []
    means = plotting._pixel_means
    monkeypatch.setattr(plotting, "_pixel_means", lambda *a: drawn.append(a) or means(*a))
    path = plotting.plot_particles(atoms, np.ones(len(atoms)), tmp_path / "s.png", domain=domain, dx=dx)
    assert path.exists() and len(drawn) == 1 and len(drawn[0][1]) == inside.sum()  # the slab's particles only


def test_an_elongated_domain_gets_a_wide_figure_with_its_colour_bar_below(tmp_path):
    """The figure follows the particles' aspect: a strip 8 times longer than tall is not drawn on a square page
    (the airfoil's figure was mostly white), and a square domain keeps a square-ish page with its bar beside it."""
    from ase_sphrelax.domains import Polygon

    strip = Polygon([[(0.0, 0.0), (2.0, 0.0), (2.0, 0.25), (0.0, 0.25)]])
    atoms = fill(strip, 0.02, jitter=0.1, seed=0)
    path = plotting.plot_particles(atoms, atoms.positions[:, 0], tmp_path / "strip.png", domain=strip, dx=0.02)
    with Image.open(path) as png:
        width, height = png.size
    assert height < 0.6 * width
    circle = Circle((0.5, 0.5), 0.2)
    atoms = fill(circle, 1 / 64, jitter=0.1, seed=0)
    path = plotting.plot_particles(atoms, atoms.positions[:, 0], tmp_path / "circle.png", domain=circle, dx=1 / 64)
    with Image.open(path) as png:
        width, height = png.size
    assert 0.8 * width < height < 1.2 * width
