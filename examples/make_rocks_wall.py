"""Write ``scenes/data/rocks_wall_mesh.ply``: the closed support mesh of ``scenes/rocks_wall_mesh.toml``.

A curved dry-stone wall: an annular sector (inner radius 3.2 m, 0.9 m thick,
150 degrees) 1.4 m high, whose top is rounded off, as a closed triangle mesh
built directly from its vertex rings. Run from the repository root:

    python examples/make_rocks_wall.py
"""

from pathlib import Path

import numpy as np
import trimesh


def wall_mesh(r_in=3.2, thickness=0.9, height=1.4, sweep_deg=150.0, segments=60, profile=12):
    """Closed, outward-wound mesh of the wall (a swept rounded profile)."""
    # Cross-section in (radius, z), counter-clockwise: bottom, outer side, rounded top, inner side.
    half = thickness / 2
    top = height - half
    arc = np.linspace(0.0, np.pi, profile)
    prof = [(r_in, 0.0), (r_in + thickness, 0.0)]
    prof += [(r_in + half + half * np.cos(a), top + half * np.sin(a)) for a in arc]
    prof = np.array(prof)
    m = len(prof)
    ang = np.radians(np.linspace(-sweep_deg / 2, sweep_deg / 2, segments + 1))
    verts = np.array([[r * np.cos(t), r * np.sin(t), z] for t in ang for r, z in prof])
    faces = []
    for s in range(segments):
        for k in range(m):
            a, b = s * m + k, s * m + (k + 1) % m
            c, d = a + m, b + m
            faces += [[a, b, d], [a, d, c]]
    # End caps: fans around the profile centroid.
    for s, flip in ((0, True), (segments, False)):
        centre = len(verts)
        verts = np.vstack([verts, verts[s * m:(s + 1) * m].mean(axis=0)])
        for k in range(m):
            f = [centre, s * m + k, s * m + (k + 1) % m]
            faces.append(f[::-1] if flip else f)
    mesh = trimesh.Trimesh(verts, np.array(faces), process=True)
    if mesh.volume < 0:
        mesh.invert()
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    return mesh


if __name__ == "__main__":
    out = Path(__file__).resolve().parents[1] / "scenes" / "data" / "rocks_wall_mesh.ply"
    mesh = wall_mesh()
    mesh.export(out)
    print(f"wrote {out} ({len(mesh.vertices)} vertices, {len(mesh.faces)} faces, volume {mesh.volume:.2f} m^3)")
