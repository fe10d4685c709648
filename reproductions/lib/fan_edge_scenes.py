"""The polygon scenes of the Fan studies as edge files: a chevron (28 and 53 degree tips, a concave corner; the shape
of ``reproductions/fan-corners``) and the boundaries the package ships (``sphrelax data``: tank, bunny, airfoil)."""
from __future__ import annotations

import subprocess
import sys

CHEVRON = [(0.0, 0.0), (0.5, 0.25), (0.0, 0.5), (0.175, 0.25)]
SHIPPED = ("tank", "bunny", "airfoil")


def edge_files(work):
    """Name -> the edge file written into the folder ``work``: ``chevron``, then the shipped ``tank``, ``bunny`` and
    ``airfoil`` as ``sphrelax data`` writes them."""
    chevron = work / "chevron.edges"
    chevron.write_text("".join(f"{a[0]} {a[1]} {b[0]} {b[1]}\n" for a, b in zip(CHEVRON, CHEVRON[1:] + CHEVRON[:1])))
    out = {"chevron": chevron}
    for name in SHIPPED:
        path = work / f"{name}.edges"
        subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "data", f"{name}.edges", "--out", str(path)],
                       check=True, capture_output=True)
        out[name] = path
    return out
