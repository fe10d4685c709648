"""Pattern of a relaxed distribution in a bounded domain, without periodicity (Fan Sec. 5.2, Figs. 12-14).

Two measures on the interior particles (level set ``phi < -margin``):

* the local lattice of every particle from its nearest-neighbour vectors:
  the shortest vector ``a1`` and the shortest one not parallel to it,
  Gauss-reduced (``|a1| <= |a2|``, angle in [60, 90] degrees), classified as
  hexagonal (ratio 1, 60 deg), square (ratio 1, 90 deg), rectangular (90 deg),
  diamond (rhombic: ratio 1, or centred: ``a2 . a1 = |a1|^2 / 2``) or
  parallelogram, with tolerances; the pattern is the majority class;
* the bond-orientational (hexatic) order ``|psi_k|`` for k = 4 (4 nearest
  neighbours) and k = 6 (6 nearest), averaged over the interior, computed by
  freud (``freud-analysis``) in a box large enough that nothing wraps.

:func:`relax_circle` builds Fan's circle (centre (0.5, 0.5), r = 0.2, 256 x
256 background mesh) and relaxes it at a given ``h/dp`` with
``dp = sqrt(V / N)``.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["local_lattice_patterns", "hexatic_order", "classify_bounded_pattern", "relax_circle",
           "plot_bounded_pattern"]

_PATTERN_CODES = ("hexagonal", "square", "rectangular", "diamond", "parallelogram")


def _reduce_pair(a1, a2):
    """Gauss-reduce two 2D vectors (rows of equal length arrays): |a1| <= |a2|, 0 <= a1.a2 <= |a1|^2/2."""
    for _ in range(8):
        n1 = np.einsum("ij,ij->i", a1, a1)
        n2 = np.einsum("ij,ij->i", a2, a2)
        swap = n2 < n1
        a1[swap], a2[swap] = a2[swap].copy(), a1[swap].copy()
        n1 = np.einsum("ij,ij->i", a1, a1)
        m = np.rint(np.einsum("ij,ij->i", a1, a2) / n1)
        a2 -= m[:, None] * a1
    dot = np.einsum("ij,ij->i", a1, a2)
    a2[dot < 0] *= -1.0
    return a1, a2


def local_lattice_patterns(r_pc, mask=None, rtol=0.04, angle_tol=4.0, return_geometry=False):
    """Local 2D lattice class of each particle from its nearest-neighbour vectors.

    Parameters
    ----------
    r_pc : (N, 2 or 3) array
    mask : (N,) bool, optional
        Particles to classify (neighbours are taken among all particles).
    rtol : float
        Relative tolerance on length ratios and on the centring projection.
    angle_tol : float
        Tolerance on angles, degrees.

    return_geometry : bool
        Also return ``(ratio, gamma)``: ``|a2|/|a1| >= 1`` and the angle in degrees.

    Returns
    -------
    (M,) ndarray of str
        One of ``"hexagonal", "square", "rectangular", "diamond", "parallelogram"``.
    """
    r = np.asarray(r_pc, dtype=float)[:, :2]
    idx = np.arange(len(r)) if mask is None else np.flatnonzero(mask)
    tree = cKDTree(r)
    _, nb = tree.query(r[idx], k=min(9, len(r)))
    vec = r[nb[:, 1:]] - r[idx][:, None, :]
    length = np.linalg.norm(vec, axis=2)
    a1 = vec[:, 0].copy()
    # shortest neighbour vector not (anti)parallel to a1
    cross = np.abs(a1[:, None, 0] * vec[..., 1] - a1[:, None, 1] * vec[..., 0]) / (length[:, :1] * length)
    ok = cross > math.sin(math.radians(20.0))
    first = np.argmax(ok, axis=1)
    a2 = vec[np.arange(len(idx)), first].copy()
    a1, a2 = _reduce_pair(a1, a2)
    l1 = np.linalg.norm(a1, axis=1)
    l2 = np.linalg.norm(a2, axis=1)
    ratio = l2 / l1
    gamma = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a1, a2) / (l1 * l2), -1.0, 1.0)))
    proj = np.einsum("ij,ij->i", a1, a2) / l1**2  # 0.5 for a centred lattice
    out = np.full(len(idx), "parallelogram", dtype=object)
    rhombic = np.abs(ratio - 1.0) < rtol
    centred = np.abs(proj - 0.5) < rtol
    right = np.abs(gamma - 90.0) < angle_tol
    out[rhombic | centred] = "diamond"
    out[right] = "rectangular"
    out[right & rhombic] = "square"
    out[(rhombic | centred) & (np.abs(gamma - 60.0) < angle_tol) & (np.abs(ratio - 1.0) < rtol)] = "hexagonal"
    if return_geometry:
        return out.astype(str), ratio, gamma
    return out.astype(str)


def hexatic_order(r_pc, k, mask=None):
    """Mean ``|psi_k|`` over ``mask`` with the ``k`` nearest neighbours (freud), no periodicity."""
    import freud

    r = np.asarray(r_pc, dtype=float)
    pts = np.zeros((len(r), 3))
    pts[:, :2] = r[:, :2] - r[:, :2].mean(axis=0)
    span = 4.0 * (np.abs(pts).max() + 1.0)
    box = freud.box.Box.square(span)
    op = freud.order.Hexatic(k=k)
    op.compute(system=(box, pts), neighbors={"num_neighbors": k})
    psi = np.abs(op.particle_order)
    return float(psi.mean() if mask is None else psi[mask].mean())


def classify_bounded_pattern(atoms, domain, margin, order_threshold=0.8):
    """Pattern of the particles deeper than ``margin`` inside ``domain``.

    ``"hexagonal"`` when the mean ``|psi_6|`` reaches ``order_threshold`` and
    the median local lattice has ``|a2|/|a1| < 1.1`` and an angle within 8
    degrees of 60; ``"square"`` when the mean ``|psi_4|`` reaches it with a
    median ratio below 1.05 and an angle within 4 degrees of 90 (the
    bond-orientational order and the medians are robust to the elastic
    distortions of an unfinished relaxation, the per-particle lattice test is
    not); otherwise the majority local lattice of :func:`local_lattice_patterns`.

    Returns
    -------
    pattern : str
    info : dict
        ``fractions`` of every class, ``psi4``, ``psi6``, ``n_interior``.
    """
    r = atoms.positions[:, :2]
    mask = np.asarray(domain.phi(r)) < -margin
    if mask.sum() < 10:
        raise ValueError(f"fewer than 10 particles deeper than margin={margin} inside the domain")
    labels, ratio, gamma = local_lattice_patterns(r, mask, return_geometry=True)
    fractions = {name: float(np.mean(labels == name)) for name in _PATTERN_CODES}
    psi4, psi6 = hexatic_order(r, 4, mask), hexatic_order(r, 6, mask)
    med_ratio, med_gamma = float(np.median(ratio)), float(np.median(gamma))
    if psi6 >= order_threshold and med_ratio < 1.1 and abs(med_gamma - 60.0) < 8.0:
        pattern = "hexagonal"
    elif psi4 >= order_threshold and med_ratio < 1.05 and abs(med_gamma - 90.0) < 4.0:
        pattern = "square"
    else:
        pattern = max(fractions, key=fractions.get)
    info = dict(fractions=fractions, psi4=psi4, psi6=psi6, median_ratio=med_ratio, median_angle=med_gamma,
                n_interior=int(mask.sum()), labels=labels, mask=mask)
    return pattern, info


def relax_circle(h_over_dp, dx=1.0 / 256.0, steps=3000, optimizer="fire", seed=0, fmax=None, logfile=None,
                 jitter=0.1, start=None):
    """Fan's circle (centre (0.5, 0.5), r = 0.2) filled on a ``dx`` mesh and relaxed at ``h = h_over_dp * dp``.

    ``dp = sqrt(V / N)`` (Sec. 5.2); the calculator uses ``v0 = vt = V / N``.
    ``jitter`` is the initial random shift (fraction of ``dx``) of the
    cell-centre particles: the square start is a stationary point, a large
    jitter (e.g. 0.45) lets non-square patterns form in fewer steps.
    ``start`` (Atoms of the same filled circle, e.g. an earlier result)
    continues a relaxation from its positions.
    Returns the relaxed Atoms with ``info["h"]``, ``info["dp"]``.
    """
    from ..build import fill
    from ..calculators.fan import FanCalculator
    from ..domains import Circle
    from ..drivers.optimizers import make_optimizer

    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, dx, jitter=jitter, seed=seed)
    if start is not None:
        if len(start) != len(atoms):
            raise ValueError(f"start has {len(start)} particles, the filled circle {len(atoms)}")
        atoms.positions = start.positions
    dp = math.sqrt(domain.volume / len(atoms))
    h = h_over_dp * dp
    atoms.calc = FanCalculator(h=h, dx=None, domain=domain, dim=2)
    opt = make_optimizer(optimizer, atoms, h=h, logfile=logfile)
    opt.run(fmax=fmax if fmax is not None else 1e-12, steps=steps)
    previous = int(start.info.get("steps", 0)) if start is not None else 0
    atoms.info.update(h=h, dp=dp, h_over_dp=h_over_dp, steps=previous + opt.nsteps,
                      energy=atoms.get_potential_energy())
    return atoms, domain


def plot_bounded_pattern(atoms, domain, path, title="", margin=None, zoom=0.06):
    """Figure like Fan Figs. 12-14: the whole circle coloured by local lattice, and a zoom of the centre."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = atoms.positions[:, :2]
    margin = margin if margin is not None else 2.0 * atoms.info.get("h", 0.0)
    labels = local_lattice_patterns(r)
    colours = dict(hexagonal="tab:blue", square="tab:orange", rectangular="tab:green", diamond="tab:red",
                   parallelogram="tab:purple")
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 5.4))
    for name, colour in colours.items():
        sel = labels == name
        ax0.scatter(r[sel, 0], r[sel, 1], s=0.6, color=colour, label=f"{name} ({sel.mean():.0%})")
    theta = np.linspace(0, 2 * np.pi, 400)
    c = np.asarray(getattr(domain, "center", (0.5, 0.5)))
    rad = float(getattr(domain, "radius", 0.2))
    ax0.plot(c[0] + rad * np.cos(theta), c[1] + rad * np.sin(theta), "k-", lw=0.5)
    ax0.set_aspect("equal")
    ax0.legend(markerscale=8, fontsize=8, loc="upper right")
    ax0.set_title(title)
    sel = np.all(np.abs(r - c) < zoom, axis=1)
    for name, colour in colours.items():
        s2 = sel & (labels == name)
        ax1.scatter(r[s2, 0], r[s2, 1], s=14, color=colour)
    ax1.set_aspect("equal")
    ax1.set_title("centre zoom")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
