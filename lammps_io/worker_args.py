"""The MPI worker's arguments as plain JSON data (never a pickle in a folder others may write).

:func:`write_worker_args` writes ``worker.json`` in the run folder: the model's ``h``, ``dx``,
``dim``, kernel and its domain as data (:func:`domain_to_data`: balls, boxes and meshes by their
numbers), ``v0`` and the thread count. :func:`read_worker_args` rebuilds them in each rank. Loading
JSON runs no code, so a ``workdir`` that other users can write cannot make the worker execute theirs.
A domain without a data form (a polygon, a CSG, a tabulated mesh) is refused for ``nprocs > 1`` with
a one-line error (``nprocs=1`` runs it in this process, with no worker).
"""
from __future__ import annotations

import json
from pathlib import Path

__all__ = ["WORKER_FILE", "domain_to_data", "domain_from_data", "write_worker_args", "read_worker_args"]

WORKER_FILE = "worker.json"


def domain_to_data(domain):
    """``domain`` as a JSON-ready dict, or None for no domain; ValueError for a domain without a data form."""
    from ase_sphrelax.domains import Box, Mesh
    from ase_sphrelax.domains.analytic import Ball

    if domain is None:
        return None
    if isinstance(domain, Ball):
        return dict(kind="ball", center=domain.center.tolist(), radius=float(domain.radius))
    if isinstance(domain, Box):
        return dict(kind="box", lo=domain.lo.tolist(), hi=domain.hi.tolist())
    if isinstance(domain, Mesh) and getattr(domain, "_table", None) is None:
        return dict(kind="mesh", vertices=domain.trimesh.vertices.tolist(), faces=domain.trimesh.faces.tolist())
    raise ValueError(f"nprocs > 1 needs a domain the MPI worker can rebuild from plain data (a ball, circle, sphere, "
                     f"box or untabulated Mesh), got {type(domain).__name__}: use nprocs=1")


def domain_from_data(data):
    """The domain of :func:`domain_to_data`'s dict."""
    from ase_sphrelax.domains import Box, Mesh
    from ase_sphrelax.domains.analytic import Ball

    if data is None:
        return None
    kind = data.get("kind")
    if kind == "ball":
        return Ball(data["center"], data["radius"])
    if kind == "box":
        return Box(data["lo"], data["hi"])
    if kind == "mesh":
        import numpy as np
        import trimesh

        return Mesh(trimesh.Trimesh(np.asarray(data["vertices"], float), np.asarray(data["faces"], int),
                                    process=False))
    raise ValueError(f"{WORKER_FILE}: unknown domain kind {kind!r}")


def write_worker_args(folder, model, v0, nthreads):
    """Write ``folder/worker.json`` for :func:`read_worker_args`."""
    data = dict(v0=None if v0 is None else float(v0), nthreads=int(nthreads), model=None)
    if model is not None:
        data["model"] = dict(h=float(model.h), dx=None if model.dx is None else float(model.dx), dim=int(model.dim),
                             kernel=model.kernel.name, domain=domain_to_data(model.domain))
    (Path(folder) / WORKER_FILE).write_text(json.dumps(data))


def read_worker_args(folder):
    """The keyword arguments of :func:`lammps_io.relaxation.execute_deck` from ``folder/worker.json``."""
    from ase_sphrelax.models.fan import FanModel

    data = json.loads((Path(folder) / WORKER_FILE).read_text())
    spec = data.pop("model")
    model = None
    if spec is not None:
        model = FanModel(spec["h"], spec["dx"], domain_from_data(spec["domain"]), spec["dim"], spec["kernel"])
    return dict(model=model, **data)
