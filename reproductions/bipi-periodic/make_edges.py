"""Write results/cylinder_array.edges: one period of BIPI Sec. 4.2.2's flow over a periodic array of cylinders between
parallel plates (cylinder radius 0.02 m; the period and the plate distance 0.1 m, as in Morris et al.'s array,
the paper's ref. [17]). The period is drawn as a closed rectangle, counter-clockwise, whose ends x = 0 and
x = 0.1 are the periodic faces (``sphrelax pack --periodic x`` drops them), with the cylinder as a clockwise
hole of 64 segments."""
import math
from pathlib import Path

L, W, R, N = 0.1, 0.1, 0.02, 64
lines = [f"0 0 {L} 0", f"{L} 0 {L} {W}", f"{L} {W} 0 {W}", f"0 {W} 0 0"]
points = [(L / 2 + R * math.cos(-2 * math.pi * k / N), W / 2 + R * math.sin(-2 * math.pi * k / N)) for k in range(N)]
for k in range(N):
    (ax, ay), (bx, by) = points[k], points[(k + 1) % N]
    lines.append(f"{ax:.17g} {ay:.17g} {bx:.17g} {by:.17g}")
(Path(__file__).resolve().parent / "results" / "cylinder_array.edges").write_text("\n".join(lines) + "\n")
