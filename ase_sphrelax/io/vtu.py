"""VTU (VTK XML unstructured grid) for ParaView, written with ``meshio``.

One point per particle at its position in the atoms' own frame (no shift, no wrap), one
``vertex`` cell per point (so ParaView draws them without a Glyph filter), and one point-data
field per array, in double precision:

===================  ==============================================================
point data           source
===================  ==============================================================
``velocity``         (N, 3), momenta / masses (zeros without momenta)
``mass``             per-particle masses (when known, see :mod:`.particles`)
``support_radius``   the kernel support ``H`` (this package's ``h``) when known
``density``          ``atoms.arrays["rho"]`` (or ``rho0`` with ``dx`` masses)
``internal_energy``  when known
``type``             1 fluid, 2 wall, ...
``forces``           of an attached calculator's results, when present
other arrays         every other numeric ``atoms.arrays`` entry with 1 or 3 components
===================  ==============================================================

Field data (ParaView's "Field Data"): ``cell`` (the 9 entries of the 3 x 3 cell, row by row),
``pbc`` (3, 0/1), ``dim`` and ``origin`` (the frame origin of ``atoms.info["origin"]``, zeros
otherwise). ``meshio`` reads a VTU ``<FieldData>`` block but does not write one: it is added to the
file meshio wrote, as ASCII data arrays (``%.17g``, exact for doubles).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .particles import collect, written_atomically

__all__ = ["write_vtu"]

_READ = {"positions", "numbers", "momenta", "masses", "h", "rho", "internal_energy", "type"}


def _point_data(atoms, particles):
    n = len(particles)
    data = {"velocity": particles.v_pc}
    for name, values in (("mass", particles.m_p), ("support_radius", particles.support_p),
                         ("density", particles.rho_p), ("internal_energy", particles.u_p)):
        if values is not None:
            data[name] = values
    data["type"] = particles.type_p.astype(np.int64)
    results = getattr(atoms.calc, "results", {}) if atoms.calc is not None else {}
    if "forces" in results:
        data["forces"] = np.asarray(results["forces"], dtype=float)
    for name, values in atoms.arrays.items():
        values = np.asarray(values)
        if name in _READ or name in data or values.dtype.kind not in "fiu":
            continue
        if values.shape in ((n,), (n, 1), (n, 3)):
            data[name] = values.reshape(n) if values.shape == (n, 1) else values
    return data


def _add_field_data(path, field_data):
    """Insert ``<FieldData>`` (ASCII ``DataArray``s) as the first child of ``<UnstructuredGrid>``."""
    import xml.etree.ElementTree as ET

    tree = ET.parse(path)
    grid = tree.getroot().find("UnstructuredGrid")
    block = ET.Element("FieldData")
    for name, values in field_data.items():
        values = np.ravel(values)
        kind = "Float64" if values.dtype.kind == "f" else "Int64"
        array = ET.SubElement(block, "DataArray", type=kind, Name=name, NumberOfTuples=str(len(values)),
                              format="ascii")
        array.text = " ".join(f"{v:.17g}" if kind == "Float64" else str(int(v)) for v in values)
    grid.insert(0, block)
    tree.write(path, xml_declaration=True, encoding="utf-8")


def write_vtu(atoms, path, *, dim=None, **sources):
    """Write ``atoms`` as a VTU file of points with point data (see the module docstring).

    Parameters are those of :func:`ase_sphrelax.io.particles.collect`; nothing is required
    beyond positions (missing quantities are left out).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        Before anything is written: NaN or inf, a dimension that disagrees with the geometry,
        arrays of the wrong shape.
    """
    particles = collect(atoms, dim, **sources)
    point_data = _point_data(atoms, particles)
    for name, values in point_data.items():
        if values.dtype.kind == "f" and not np.all(np.isfinite(values)):
            raise ValueError(f"point data {name!r} contains NaN or inf: every value must be finite")
    field_data = {"cell": particles.cell_cc, "pbc": particles.pbc_c.astype(np.int64),
                  "dim": np.array([particles.dim], dtype=np.int64), "origin": particles.origin_c}

    import meshio

    n = len(particles)
    mesh = meshio.Mesh(particles.r_pc, [("vertex", np.arange(n).reshape(n, 1))], point_data=point_data,
                       field_data=field_data)
    path = Path(path)
    with written_atomically(path) as partial:
        meshio.write(partial, mesh, file_format="vtu")
        _add_field_data(partial, field_data)
    return path
