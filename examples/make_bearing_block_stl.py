"""Write ``bearing-block.stl``, the surface the STL example meshes (run once; the STL is committed).

    python examples/make_bearing_block_stl.py

A bearing block (lengths in mm): a base plate 120 x 60 x 12 with two bolt holes (radius 6), a boss
(radius 22, 30 high) standing on it, and a bore (radius 12) through boss and plate. Built with
manifold3d (exact booleans, closed and outward-oriented) and written as binary STL. Circles have 64
segments: the chordal error is 0.12 % of the radius, so the feature recognition sees the bore and the
bolt holes as holes and the concave circle where the boss meets the plate as a re-entrant edge.
"""

from __future__ import annotations

from pathlib import Path

import manifold3d as m3
import trimesh

SEGMENTS = 64


def bearing_block() -> trimesh.Trimesh:
    plate = m3.Manifold.cube([120.0, 60.0, 12.0]).translate([-60.0, -30.0, 0.0])
    boss = m3.Manifold.cylinder(36.0, 22.0, 22.0, SEGMENTS).translate([0.0, 0.0, 6.0])
    bore = m3.Manifold.cylinder(60.0, 12.0, 12.0, SEGMENTS).translate([0.0, 0.0, -10.0])
    bolts = [m3.Manifold.cylinder(30.0, 6.0, 6.0, SEGMENTS).translate([x, 0.0, -10.0]) for x in (-44.0, 44.0)]
    solid = plate + boss - bore
    for bolt in bolts:
        solid = solid - bolt
    mesh = solid.to_mesh()
    return trimesh.Trimesh(mesh.vert_properties[:, :3], mesh.tri_verts, process=True)


if __name__ == "__main__":
    path = Path(__file__).with_name("bearing-block.stl")
    surface = bearing_block()
    surface.export(path)
    print(
        f"wrote {path}: {len(surface.faces)} triangles, volume {surface.volume:.6g}, "
        f"watertight {surface.is_watertight}, {path.stat().st_size / 1024:.0f} KB"
    )
