"""Headline numbers of a BIPI packing (Boregowda & Liu 2025), from the packer's result.

The packer (:class:`~ase_sphrelax.drivers.BIPIPacker`) returns data (its ``history`` and
``summary()``); this adds the boundary layer, escapes, the ``|grad C|`` drop and the shared quality
metrics of :mod:`ase_sphrelax.analysis.quality`. Figures: :mod:`ase_sphrelax.plotting`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["pack_summary"]


def pack_summary(atoms, packer):
    """The packer's summary plus boundary layer, escapes, ``|grad C|`` drop and the quality metrics.

    Parameters
    ----------
    atoms : ase.Atoms
        The packed particles.
    packer : BIPIPacker
        The packer that packed them (after :meth:`~ase_sphrelax.drivers.BIPIPacker.run`).

    Returns
    -------
    dict
    """
    from .quality import BOUNDARY_LAYER, quality_summary

    model = packer.model
    domain = packer.calc.boundary.domain
    out = packer.summary()
    d = -domain.phi(atoms.positions) / model.dx
    layer = d < BOUNDARY_LAYER
    final = packer.final_gradc_avg()
    first = out.get("gradc_avg_2c_first", np.nan)
    out.update(n_particles=len(atoms), h_over_dx=model.h / model.dx, n_outside=int(np.sum(d <= 0)),
               boundary_layer_mean=float(d[layer].mean()) if layer.any() else float("nan"),
               boundary_layer_min=float(d.min()), n_boundary_layer=int(layer.sum()), gradc_avg_final=final,
               gradc_drop_orders=float(np.log10(first / final)) if final > 0 and np.isfinite(first) else float("nan"),
               quality=quality_summary(atoms, model.h, dx=model.dx, domain=domain, dim=model.dim,
                                       kernel=model.kernel.name))
    return out
