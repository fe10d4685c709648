"""Figures of particle distributions (matplotlib, non-interactive)."""
from __future__ import annotations

import numpy as np


def plot_particles(atoms, value_p, path, domain=None, dx=None, title="", label="", slice_width=None,
                   range_mask=None):
    """Scatter plot of the particles coloured by ``value_p``; writes ``path`` (PNG).

    Markers below :data:`PIXEL_MARKER` pixels across (about 3e5 particles and more in 2D) give way to an image of
    the mean value of the particles in each pixel. 2D: all particles, with the domain boundary (``phi = 0``
    contour). 3D: the slab ``|z - z_mid| < slice_width / 2`` (default ``dx``). The colour range spans
    the 1st to 99th percentile of ``value_p[range_mask]`` (e.g. interior particles,
    so that the boundary layer does not hide the interior variation).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r_pc = atoms.positions
    dim = domain.dim if domain is not None else (3 if atoms.pbc[2] or np.ptp(r_pc[:, 2]) > 0 else 2)
    value_p = np.asarray(value_p)
    ranged_p = value_p if range_mask is None or not np.any(range_mask) else value_p[np.asarray(range_mask)]
    if dim == 3:
        z_mid = 0.5 * (r_pc[:, 2].min() + r_pc[:, 2].max())
        width = slice_width or dx or np.ptp(r_pc[:, 2]) / 10
        keep = np.abs(r_pc[:, 2] - z_mid) < width / 2
        r_pc, value_p = r_pc[keep], value_p[keep]
        title = f"{title} (slice z = {z_mid:.3g})"
    dpi = 150
    lo, hi = r_pc[:, :2].min(axis=0), r_pc[:, :2].max(axis=0)
    extent = float(max(hi - lo)) or 1.0
    # the longer side of the particles' box spans 5 inches, the figure follows their aspect (an airfoil 8 times
    # longer than thick had a 6-inch-tall figure, mostly white); a box less than half as tall as wide takes its
    # colour bar below it
    span_x, span_y = (max(float(s), 0.02 * extent) / extent * 5.0 for s in hi - lo)
    wide = span_y < 0.5 * span_x
    figsize = (max(span_x, 3.0) + 0.6, span_y + 1.9) if wide else (span_x + 1.6, max(span_y, 3.0) + 1.0)
    fig, ax = plt.subplots(figsize=figsize, dpi=dpi)
    spacing = dx or extent / np.sqrt(len(r_pc))
    # marker diameter ~ 0.8 of the particle spacing, in points
    diameter = 0.8 * spacing / extent * 5.0 * 72
    # robust colour range: a few boundary particles must not hide the interior variation
    vmin, vmax = np.percentile(ranged_p, [1, 99]) if len(ranged_p) > 50 else (ranged_p.min(), ranged_p.max())
    if diameter / 72 * dpi < PIXEL_MARKER:
        # markers smaller than a pixel or two (1e6 particles): each pixel shows the mean of its particles, one image
        # instead of a marker per particle (matplotlib drew 1e6 markers in 3 s)
        # (pixels at least 1.5 spacings wide, so that none inside the particles is empty)
        pixels = max(1, min(int(5.0 * dpi), int(extent / (1.5 * spacing))))
        points = _pixel_means(ax, r_pc[:, :2], value_p, lo, hi, pixels, vmin, vmax)
    else:
        points = ax.scatter(r_pc[:, 0], r_pc[:, 1], c=value_p, s=diameter**2, cmap="viridis", linewidths=0,
                            vmin=vmin, vmax=vmax)
    if domain is not None and domain.dim == 2:
        pad = 0.05 * extent
        gx = np.linspace(lo[0] - pad, hi[0] + pad, 400)
        gy = np.linspace(lo[1] - pad, hi[1] + pad, 400)
        xx, yy = np.meshgrid(gx, gy)
        phi = domain.phi(np.column_stack([xx.ravel(), yy.ravel()])).reshape(xx.shape)
        ax.contour(xx, yy, phi, levels=[0.0], colors="k", linewidths=0.6)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    fig.colorbar(points, ax=ax, label=label, shrink=0.85, extend="both",
                 **({"orientation": "horizontal", "fraction": 0.25, "aspect": 40} if wide else {}))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


# below this marker diameter in pixels plot_particles draws an image of per-pixel means instead of markers
PIXEL_MARKER = 1.5


def _pixel_means(ax, r_pc, value_p, lo, hi, pixels, vmin, vmax):
    """The mean of ``value_p`` over the particles in each of ``pixels`` x ``pixels`` cells of the box ``[lo, hi]``
    (empty cells transparent), drawn by ``imshow``; returns the image."""
    span = np.maximum(hi - lo, 1e-300)
    cell_pc = np.minimum(((r_pc - lo) / span * pixels).astype(np.int64), pixels - 1)
    flat = cell_pc[:, 1] * pixels + cell_pc[:, 0]
    count = np.bincount(flat, minlength=pixels * pixels)
    total = np.bincount(flat, weights=value_p, minlength=pixels * pixels)
    mean = np.where(count > 0, total / np.maximum(count, 1), np.nan).reshape(pixels, pixels)  # no 0 / 0
    return ax.imshow(np.ma.masked_invalid(mean), origin="lower", extent=(lo[0], hi[0], lo[1], hi[1]),
                     cmap="viridis", vmin=vmin, vmax=vmax, interpolation="nearest")


def save_figure(fig, path, dpi=90, colors=256):
    """Write ``fig`` to ``path`` as a PNG of ``colors`` palette colours (a third to a quarter of the size), close it.

    Returns ``path``.
    """
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return quantize_png(path, colors)


def quantize_png(path, colors=256):
    """Rewrite the PNG at ``path`` with ``colors`` palette colours; returns ``path``."""
    from PIL import Image

    with Image.open(path) as image:
        image.convert("RGB").quantize(colors=colors).save(path, optimize=True)
    return path


def plot_concentration_gradient(atoms, calc, path, title=""):
    """Particles coloured by ``log10 |grad C_a|`` of a BIPICalculator (the paper's Figs. 10-12); 3D: a slice.

    Writes ``path`` as a 256-colour PNG (a quarter of the file size); returns ``path``.
    """
    grad = np.linalg.norm(calc.get_concentration_gradient(atoms), axis=1)
    value = np.log10(np.maximum(grad, 1e-300) * calc.model.h)
    plot_particles(atoms, value, path, domain=calc.boundary.domain, dx=calc.model.dx, title=title,
                   label=r"log$_{10}$ (h |$\nabla$C$_a$|)", slice_width=2 * calc.model.dx)
    return quantize_png(path)


def plot_packing_history(history, path=None, title=None):
    """BIPI's ``TPD_avg`` and ``|grad C|_avg`` against the iteration (Fig. 7-9), stages in colours.

    ``history``: :attr:`ase_sphrelax.drivers.BIPIPacker.history`. Returns the figure (closed when
    written to ``path``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    offset = 0
    colours = {"2a": "tab:green", "2c": "tab:blue"}
    for stage in ("2a", "2c"):
        rows = [r for r in history if r["stage"] == stage]
        if not rows:
            continue
        it = offset + np.arange(1, len(rows) + 1)
        axes[0].plot(it, [r["tpd_avg"] for r in rows], color=colours[stage], label=f"step {stage}")
        axes[1].semilogy(it, [max(r["gradc_avg"], 1e-300) for r in rows], color=colours[stage], label=f"step {stage}")
        offset = it[-1]
    axes[0].set(xlabel="iteration", ylabel="TPD$_{avg}$")
    axes[1].set(xlabel="iteration", ylabel=r"$|\nabla C|_{avg}$ (packable)")
    for ax in axes:
        ax.legend()
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
