"""A corpus of machined-style solids, built with Gmsh's OpenCASCADE kernel and exported as binary STL.

``make_parts(out_dir, names=None)`` writes ``NAME-coarse.stl`` and ``NAME-fine.stl`` for every part (or the
parts in ``names``) and ``manifest.json`` (name, tessellation, path, cad_volume, stl_volume, triangles) into
``out_dir`` and returns ``{name: {tessellation: Path}}``. The triangles are OpenCASCADE's own tessellation
(BRepMesh, as a CAD system exports STL) with the angular and linear deflections of ``TESSELLATIONS``; every
file is checked to bound one closed solid. Same code, same files: nothing is random.

Run as ``python tests/parts/make_parts.py OUTDIR [NAME ...]``.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import gmsh
import numpy as np
import trimesh

occ = gmsh.model.occ

# angular deflection (degrees) and linear deflection (times the bounding-box diagonal) of the STL export
TESSELLATIONS = {"coarse": (15.0, 2e-3), "fine": (5.0, 5e-4)}
EPS = 1e-3


# ----------------------------------------------------------------------------------------------- helpers


def _one(dim_tags) -> int:
    """The tag of the single volume in ``dim_tags``."""
    volumes = [t for d, t in dim_tags if d == 3]
    if len(volumes) != 1:
        raise RuntimeError(f"expected one volume, got {len(volumes)}")
    return volumes[0]


def _fuse(*tags) -> int:
    return _one(occ.fuse([(3, tags[0])], [(3, t) for t in tags[1:]])[0])


def _cut(tag, *tools) -> int:
    return _one(occ.cut([(3, tag)], [(3, t) for t in tools])[0])


def _curves(select) -> list[int]:
    """Curves of the model whose bounding box (xmin, ymin, zmin, xmax, ymax, zmax) passes ``select``."""
    return [c for _, c in occ.getEntities(1) if select(np.array(occ.getBoundingBox(1, c)))]


def _fillet(tag, curves, radius) -> int:
    return _one(occ.fillet([tag], curves, [radius]))


def _chamfer(tag, curves, distance) -> int:
    """Chamfer ``curves`` of volume ``tag`` with equal legs ``distance``."""
    occ.synchronize()
    faces = [gmsh.model.getAdjacencies(1, c)[0][0] for c in curves]
    return _one(occ.chamfer([tag], curves, faces, [distance]))


def _at_z(z):
    """Selector: curves lying in the plane z."""
    return lambda b: abs(b[2] - z) < EPS and abs(b[5] - z) < EPS


def _vertical(z0, z1):
    """Selector: straight vertical edges from z0 to z1."""
    return lambda b: b[3] - b[0] < EPS and b[4] - b[1] < EPS and abs(b[2] - z0) < EPS and abs(b[5] - z1) < EPS


def _hole(x, y, z0, z1, radius) -> int:
    """A cylinder along z from z0 to z1 (tools overshoot the faces they pierce)."""
    return occ.addCylinder(x, y, z0, 0, 0, z1 - z0, radius)


def _slot(x0, x1, y, z0, z1, width) -> int:
    """A stadium-shaped slot along x between the centres x0 and x1, from z0 to z1."""
    r = width / 2
    return _fuse(occ.addBox(x0, y - r, z0, x1 - x0, width, z1 - z0), _hole(x0, y, z0, z1, r), _hole(x1, y, z0, z1, r))


def _prism(points, z0, z1) -> int:
    """A right prism over the closed polygon ``points`` (x, y), from z0 to z1."""
    p = [occ.addPoint(x, y, z0) for x, y in points]
    loop = occ.addCurveLoop([occ.addLine(p[i], p[(i + 1) % len(p)]) for i in range(len(p))])
    return _one(occ.extrude([(2, occ.addPlaneSurface([loop]))], 0, 0, z1 - z0))


# ----------------------------------------------------------------------------------------------- the parts


def fillet_block() -> int:
    """A block with every edge rounded and a through bore."""
    block = _fillet(occ.addBox(0, 0, 0, 80, 50, 30), [c for _, c in occ.getEntities(1)], 5)
    return _cut(block, _hole(40, 25, -1, 31, 8))


def chamfer_block() -> int:
    """A block with chamfered top edges and a through hole chamfered at both rims."""
    block = _cut(occ.addBox(0, 0, 0, 80, 50, 30), _hole(40, 25, -1, 31, 8))
    return _chamfer(
        block,
        _curves(lambda b: abs(b[5] - 30) < EPS and abs(b[2] - 30) < EPS)
        + _curves(lambda b: abs(b[2]) < EPS and abs(b[5]) < EPS and b[3] - b[0] < 17),
        3,
    )


def cone_pin() -> int:
    """A locating pin: flange, shank and a conical tip."""
    return _fuse(
        occ.addCylinder(0, 0, 0, 0, 0, 8, 20),
        occ.addCylinder(0, 0, 8, 0, 0, 40, 10),
        occ.addCone(0, 0, 48, 0, 0, 20, 10, 3),
    )


def countersunk_plate() -> int:
    """A plate with four countersunk (90 degree) through holes."""
    plate = occ.addBox(0, 0, 0, 120, 60, 10)
    tools = []
    for x in (20, 100):
        for y in (15, 45):
            tools += [_hole(x, y, -1, 11, 3.3), occ.addCone(x, y, 10 - 3.2, 0, 0, 4.2, 3.3, 7.5)]
    return _cut(plate, *tools)


def torus_ring() -> int:
    """A ring (O-ring-like torus)."""
    return occ.addTorus(0, 0, 0, 40, 8)


def boss_plate() -> int:
    """A plate carrying three cylindrical bosses, each with a blind hole."""
    plate = _fuse(
        occ.addBox(0, 0, 0, 140, 90, 10), *[_hole(x, y, 5, 30, 12) for x, y in ((30, 25), (110, 25), (70, 65))]
    )
    return _cut(plate, *[_hole(x, y, 15, 31, 5) for x, y in ((30, 25), (110, 25), (70, 65))])


def pocket_block() -> int:
    """A block with a rectangular pocket (rounded vertical corners) and a round pocket."""
    pocket = _fillet(occ.addBox(15, 15, 15, 60, 40, 16), _curves(_vertical(15, 31)), 6)
    return _cut(occ.addBox(0, 0, 0, 100, 70, 30), pocket, _hole(88, 35, 20, 31, 7))


def drilled_block() -> int:
    """A block with through holes, blind holes with 118 degree drill points and a blind cross hole."""
    block = occ.addBox(0, 0, 0, 100, 60, 40)
    tips = [occ.addCone(x, 45, 20, 0, 0, -4 * math.tan(math.radians(31)), 4, 0) for x in (20, 50, 80)]
    blind = [_hole(x, 45, 20, 41, 4) for x in (20, 50, 80)]
    through = [_hole(x, 15, -1, 41, 5) for x in (20, 50, 80)]
    cross = occ.addCylinder(-1, 30, 12, 31, 0, 0, 3)
    return _cut(block, *tips, *blind, *through, cross)


def slotted_plate() -> int:
    """A plate with two through slots and a blind slot."""
    return _cut(
        occ.addBox(0, 0, 0, 150, 80, 12),
        _slot(20, 60, 20, -1, 13, 10),
        _slot(90, 130, 20, -1, 13, 10),
        _slot(30, 120, 58, 6, 13, 12),
    )


def ribbed_plate() -> int:
    """A base plate stiffened by four ribs and an end wall."""
    ribs = [occ.addBox(10, y, 8, 140, 4, 30) for y in (12, 36, 60, 84)]
    return _fuse(occ.addBox(0, 0, 0, 160, 100, 8), occ.addBox(150, 0, 8, 10, 100, 30), *ribs)


def thin_tube() -> int:
    """A thin-walled tube (wall 0.6, under a quarter of the default size) with a collar at one end."""
    return _cut(
        _fuse(occ.addCylinder(0, 0, 0, 0, 0, 100, 20), occ.addCylinder(0, 0, 0, 0, 0, 10, 25)),
        occ.addCylinder(0, 0, -1, 0, 0, 102, 19.4),
    )


def thin_fin() -> int:
    """A block carrying a fin 0.7 thick (under a quarter of the default size) and a thick web."""
    return _fuse(
        occ.addBox(0, 0, 0, 100, 60, 20), occ.addBox(10, 29.65, 20, 80, 0.7, 30), occ.addBox(10, 8, 20, 6, 44, 30)
    )


def freeform_top() -> int:
    """A block whose top is a bicubic B-spline face."""
    heights = np.array(
        [[30, 32, 35, 33, 30], [31, 36, 42, 38, 32], [33, 40, 46, 41, 34], [31, 35, 40, 37, 31], [30, 31, 33, 32, 30]],
        dtype=float,
    )
    xs, ys = np.linspace(-10, 110, 5), np.linspace(-10, 90, 5)
    points = [occ.addPoint(x, y, heights[j, i]) for j, y in enumerate(ys) for i, x in enumerate(xs)]
    skin = occ.addBSplineSurface(points, 5)
    above = _one(occ.extrude([(2, skin)], 0, 0, 40))
    return _cut(occ.addBox(0, 0, 0, 100, 80, 60), above)


def lofted_handle() -> int:
    """A freeform handle: a loft (B-spline face) through ellipses that shrink, swell and twist, with a blind
    bore. (Sections drawn as closed splines through points give a solid whose getMass is off by 0.5-1 %.)"""
    wires = []
    for z, a, b, twist in ((0, 30, 20, 0), (30, 24, 16, 15), (60, 18, 14, 30), (90, 22, 18, 45)):
        ellipse = occ.addEllipse(0, 0, z, a, b)
        occ.rotate([(1, ellipse)], 0, 0, 0, 0, 0, 1, math.radians(twist))
        wires.append(occ.addWire([ellipse]))
    return _cut(_one(occ.addThruSections(wires, makeSolid=True)), _hole(0, 0, -1, 40, 5))


def filleted_hole_floor() -> int:
    """A pocketed block with through holes in the pocket floor; the floor meets the hole walls (r 3) and the
    pocket walls (r 4) through tangent fillets."""
    block = _cut(
        occ.addBox(0, 0, 0, 100, 70, 30),
        occ.addBox(15, 15, 18, 70, 40, 13),
        _hole(35, 35, -1, 19, 7),
        _hole(65, 35, -1, 19, 7),
    )
    floor = _curves(_at_z(18))
    rims = [c for c in floor if occ.getBoundingBox(1, c)[3] - occ.getBoundingBox(1, c)[0] < 15]
    walls = [c for c in floor if c not in rims]
    return _one(occ.fillet([block], rims + walls, [3] * len(rims) + [4] * len(walls)))


def tray() -> int:
    """An open tray (shell 3 thick, rounded outer corners) with holes in its bottom and a slot in a side."""
    box = _fillet(occ.addBox(0, 0, 0, 120, 80, 30), _curves(_vertical(0, 30)), 8)
    shell = _cut(box, _fillet(occ.addBox(3, 3, 3, 114, 74, 30), _curves(_vertical(3, 33)), 5))
    holes = [_hole(x, y, -1, 4, 4) for x in (25, 95) for y in (20, 60)]
    side = occ.addBox(40, -1, 12, 40, 5, 8)
    return _cut(shell, *holes, side)


def bracket() -> int:
    """An L-bracket with a filleted inner corner and two holes in each leg."""
    angle = _fuse(occ.addBox(0, 0, 0, 80, 50, 10), occ.addBox(0, 0, 0, 10, 50, 70))
    angle = _fillet(
        angle,
        _curves(
            lambda b: abs(b[0] - 10) < EPS and abs(b[3] - 10) < EPS and abs(b[2] - 10) < EPS and abs(b[5] - 10) < EPS
        ),
        8,
    )
    holes = [_hole(55, y, -1, 11, 4) for y in (15, 35)] + [occ.addCylinder(-1, y, 45, 12, 0, 0, 4) for y in (15, 35)]
    return _cut(angle, *holes)


def hole_pattern_block() -> int:
    """A block drilled with a 3 x 6 pattern of 18 small through holes."""
    return _cut(
        occ.addBox(0, 0, 0, 120, 80, 20),
        *[_hole(x, y, -1, 21, 2.5) for x in np.linspace(15, 105, 6) for y in (20, 40, 60)],
    )


def chamfered_riser() -> int:
    """A square riser on a base plate, chamfered along its top edges and drilled through."""
    part = _fuse(occ.addBox(0, 0, 0, 100, 100, 12), occ.addBox(30, 30, 6, 40, 40, 56))
    part = _chamfer(part, _curves(_at_z(62)), 4)
    return _cut(part, _hole(50, 50, -1, 63, 8))


def flange() -> int:
    """A flange: disc, hub with a filleted root, a bore and eight bolt holes on a 95 bolt circle."""
    body = _fuse(occ.addCylinder(0, 0, 0, 0, 0, 14, 60), occ.addCylinder(0, 0, 7, 0, 0, 37, 30))
    body = _fillet(body, _curves(lambda b: _at_z(14)(b) and b[3] - b[0] < 61), 4)
    bolts = [_hole(47.5 * math.cos(t), 47.5 * math.sin(t), -1, 15, 5) for t in np.radians(np.arange(0, 360, 45) + 22.5)]
    return _cut(body, _hole(0, 0, -1, 45, 17.5), *bolts)


def counterbore_plate() -> int:
    """A plate with four counterbored through holes (9 bore, 15 x 9 deep counterbore)."""
    tools = []
    for x in (20, 100):
        for y in (20, 60):
            tools += [_hole(x, y, -1, 17, 4.5), _hole(x, y, 7, 17, 7.5)]
    return _cut(occ.addBox(0, 0, 0, 120, 80, 16), *tools)


def hex_nut() -> int:
    """A hexagon nut (24 across flats, 12 high) with chamfered faces and a bore chamfered at both ends.
    (The usual 30 degree cone chamfer meets the flats in hyperbolas, which BRepMesh tessellates
    differently on the two faces of the edge: no closed STL.)"""
    r = 12 / math.cos(math.pi / 6)
    nut = _prism([(r * math.cos(t), r * math.sin(t)) for t in np.radians(np.arange(0, 360, 60))], 0, 12)
    nut = _chamfer(nut, _curves(_at_z(0)) + _curves(_at_z(12)), 1.5)
    nut = _cut(nut, _hole(0, 0, -1, 13, 6))
    return _chamfer(nut, _curves(lambda b: (_at_z(0)(b) or _at_z(12)(b)) and b[3] - b[0] < 13), 1)


def stepped_shaft() -> int:
    """A stepped shaft (30 / 25 / 20) with chamfered ends, a keyway in the middle step and a groove."""
    shaft = _fuse(
        occ.addCylinder(0, 0, 0, 0, 0, 40, 15),
        occ.addCylinder(0, 0, 40, 0, 0, 60, 12.5),
        occ.addCylinder(0, 0, 100, 0, 0, 40, 10),
    )
    shaft = _chamfer(shaft, _curves(_at_z(0)) + _curves(_at_z(140)), 1.5)
    key = _fuse(
        occ.addBox(8.5, -4, 55, 5, 8, 30),
        occ.addCylinder(8.5, 0, 55, 5, 0, 0, 4),
        occ.addCylinder(8.5, 0, 85, 5, 0, 0, 4),
    )
    groove = _cut(occ.addCylinder(0, 0, 120, 0, 0, 3, 11), occ.addCylinder(0, 0, 119, 0, 0, 5, 8.5))
    return _cut(shaft, key, groove)


def pillow_block() -> int:
    """A bearing housing: base with two bolt holes, fillets where the housing meets the base and along the
    base's ends, a bore chamfered at both ends."""
    housing = occ.addCylinder(0, -20, 40, 0, 40, 0, 30)
    body = _fuse(occ.addBox(-60, -20, 0, 120, 40, 15), occ.addBox(-30, -20, 10, 60, 40, 30), housing)
    body = _fillet(body, _curves(lambda b: _at_z(15)(b) and b[4] - b[1] > 39), 5)
    body = _cut(body, occ.addCylinder(0, -21, 40, 0, 42, 0, 18), *[_hole(x, 0, -1, 16, 6) for x in (-45, 45)])
    return _chamfer(
        body,
        _curves(lambda b: abs(b[1] + 20) < EPS and abs(b[4] + 20) < EPS and b[3] - b[0] < 37)
        + _curves(lambda b: abs(b[1] - 20) < EPS and abs(b[4] - 20) < EPS and b[3] - b[0] < 37),
        1.5,
    )


def boss_arm() -> int:
    """A bored boss (r 20, 22 high) carrying a drilled arm 12 thick whose sides meet the boss through
    vertical fillets (r 3) that end square on the arm's top and bottom faces, as at a con-rod's big end: on
    the boss, a fillet's end edge and the boss's edge leave their common corner tangent."""
    body = _fuse(occ.addCylinder(0, 0, -11, 0, 0, 22, 20), occ.addBox(10, -8, -6, 60, 16, 12))
    body = _fillet(body, _curves(lambda b: b[5] - b[2] > 11 and b[3] - b[0] < EPS and abs(b[0] - 18.33) < 0.1), 3)
    return _cut(body, _hole(0, 0, -12, 12, 10), _hole(60, 0, -7, 7, 4))


def cross_bored_block() -> int:
    """A block with a bore (r 10) and a cross bore (r 6) through it at right angles: the bore's wall is a full
    cylinder with two holes in it."""
    return _cut(
        occ.addBox(-30, -25, -20, 60, 50, 40), _hole(0, 0, -21, 21, 10), occ.addCylinder(-31, 0, 0, 62, 0, 0, 6)
    )


def thin_chamfer_plate() -> int:
    """A plate 140 x 90 x 12 whose top edges are chamfered 1 mm: a face four times narrower than the default size
    between two close parallel edges."""
    return _chamfer(occ.addBox(0, 0, 0, 140, 90, 12), _curves(_at_z(12)), 1)


def round_into_wall() -> int:
    """A block 60 x 40 x 20 with a channel 30 wide and 6 deep across it, the convex edge of the channel floor and
    the front face rounded r 2: the round dies into the channel walls, whose faces get two cusps (the wall's
    edge and the round's arc leave one corner together)."""
    block = _cut(occ.addBox(0, 0, 0, 60, 40, 20), occ.addBox(15, -1, 14, 30, 42, 7))
    return _fillet(block, _curves(lambda b: _at_z(14)(b) and abs(b[1]) < EPS and abs(b[4]) < EPS), 2)


def _rectangle_wire(width: float, depth: float, z: float) -> int:
    """A closed wire round the rectangle ``width`` x ``depth`` centred on the z axis at height ``z``."""
    p = [occ.addPoint(sx * width / 2, sy * depth / 2, z) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return occ.addWire([occ.addLine(p[i], p[(i + 1) % 4]) for i in range(4)])


def drafted_housing() -> int:
    """A cast housing: a flange 140 x 100 x 8 carrying a body with 4 deg draft (100 x 70 at its base, 40 high),
    its vertical edges rounded r 6 and its base r 4, a drafted cavity from the top and four bolt holes. Where
    the drafted rounds meet the base round a chart's border folds onto itself within one triangle, and a cut
    across the base round's long facets ran inside it (both refused the coarse STL)."""
    draft = math.tan(math.radians(4))
    body = _one(
        occ.addThruSections(
            [_rectangle_wire(100, 70, 8), _rectangle_wire(100 - 80 * draft, 70 - 80 * draft, 48)],
            makeSolid=True,
            makeRuled=True,
        )
    )
    occ.synchronize()
    body = _fillet(body, _curves(lambda b: b[5] - b[2] > 30 and b[3] - b[0] < 4 and b[4] - b[1] < 4), 6)
    part = _fuse(occ.addBox(-70, -50, 0, 140, 100, 8), body)
    base = _curves(lambda b: _at_z(8)(b) and b[3] - b[0] < 101 and b[4] - b[1] < 71 and max(abs(b[0]), abs(b[3])) < 51)
    part = _fillet(part, base, 4)
    cavity = _one(
        occ.addThruSections(
            [_rectangle_wire(80, 50, 20), _rectangle_wire(80 + 60 * draft, 50 + 60 * draft, 50)],
            makeSolid=True,
            makeRuled=True,
        )
    )
    return _cut(part, cavity, *[_hole(x, y, -1, 9, 5) for x in (-60, 60) for y in (-40, 40)])


PARTS = {
    f.__name__: f
    for f in (
        fillet_block,
        chamfer_block,
        cone_pin,
        countersunk_plate,
        torus_ring,
        boss_plate,
        pocket_block,
        drilled_block,
        slotted_plate,
        ribbed_plate,
        thin_tube,
        thin_fin,
        freeform_top,
        lofted_handle,
        filleted_hole_floor,
        tray,
        bracket,
        hole_pattern_block,
        chamfered_riser,
        flange,
        counterbore_plate,
        hex_nut,
        stepped_shaft,
        pillow_block,
        boss_arm,
        cross_bored_block,
        thin_chamfer_plate,
        round_into_wall,
        drafted_housing,
    )
}


# ----------------------------------------------------------------------------------------------- export


def _export(path: Path, angle: float, linear: float) -> None:
    """Write the current model's OpenCASCADE tessellation as binary STL."""
    gmsh.option.setNumber("Mesh.Binary", 1)
    gmsh.option.setNumber("Mesh.StlOneSolidPerSurface", 0)
    gmsh.option.setNumber("Mesh.StlLinearDeflectionRelative", 0)  # one absolute deflection: faces share edges
    gmsh.option.setNumber("Mesh.StlLinearDeflection", linear)
    gmsh.option.setNumber("Mesh.StlAngularDeflection", math.radians(angle))
    gmsh.write(str(path))


def _clean(path: Path) -> trimesh.Trimesh:
    """Weld the STL of ``path``, drop the triangles that collapse onto an edge (BRepMesh leaves them at the
    poles of spherical corner blends), orient every triangle outward (Gmsh writes the triangles of a
    reversed face as they are), check that it bounds one closed solid and rewrite it."""
    mesh = trimesh.load(path, force="mesh")
    faces = np.sort(mesh.faces, axis=1)
    mesh.update_faces((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]))
    mesh.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(mesh)
    if not (mesh.is_watertight and mesh.is_volume and mesh.body_count == 1):
        raise RuntimeError(
            f"{path.name}: watertight {mesh.is_watertight}, volume {mesh.is_volume}, bodies {mesh.body_count}"
        )
    mesh.export(path, file_type="stl")
    return mesh


def make_parts(out_dir, names=None) -> dict[str, dict[str, Path]]:
    """Build the parts ``names`` (default: all of PARTS), write their STLs and manifest.json into ``out_dir``;
    return {name: {tessellation: path}}."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    paths, manifest = {}, []
    try:
        for name in names or PARTS:
            paths[name] = {}
            for tessellation, (angle, linear) in TESSELLATIONS.items():
                gmsh.clear()  # a fresh solid: OpenCASCADE keeps a face's first tessellation
                volume = PARTS[name]()
                occ.synchronize()
                cad_volume = occ.getMass(3, volume)
                diagonal = float(np.linalg.norm(np.subtract(*np.reshape(occ.getBoundingBox(3, volume), (2, 3)))))
                path = out / f"{name}-{tessellation}.stl"
                _export(path, angle, linear * diagonal)
                mesh = _clean(path)
                paths[name][tessellation] = path
                manifest.append(
                    {
                        "name": name,
                        "tessellation": tessellation,
                        "path": path.name,
                        "cad_volume": cad_volume,
                        "stl_volume": float(mesh.volume),
                        "triangles": len(mesh.faces),
                    }
                )
    finally:
        gmsh.clear()
        if started:
            gmsh.finalize()
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    return paths


def gmsh_meshed(out_dir, name, size=1 / 50, per_circle=20) -> Path:
    """Write part ``name`` as an FE tool's STL into ``out_dir`` and return its path: Gmsh's own 2-D mesh of it
    (MeshSizeMax ``size`` x its diagonal, ``per_circle`` elements per turn of curvature) instead of
    OpenCASCADE's tessellation, its triangles spread over each face rather than ruled (a narrow chamfer's fold
    between two of them up to ~40 deg within a smooth patch). Gmsh's options are as before afterwards."""
    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(["-noenv"], readConfigFiles=False)
    options = ("General.Terminal", "Mesh.MeshSizeMax", "Mesh.MeshSizeFromCurvature", "Mesh.Binary")
    before = {option: gmsh.option.getNumber(option) for option in options}
    path = Path(out_dir) / f"{name}-gmsh.stl"
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.clear()
        volume = PARTS[name]()
        occ.synchronize()
        diagonal = float(np.linalg.norm(np.subtract(*np.reshape(occ.getBoundingBox(3, volume), (2, 3)))))
        gmsh.option.setNumber("Mesh.MeshSizeMax", size * diagonal)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", per_circle)
        gmsh.option.setNumber("Mesh.Binary", 1)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
        _clean(path)
    finally:
        gmsh.clear()
        for option, value in before.items():
            gmsh.option.setNumber(option, value)
        if started:
            gmsh.finalize()
    return path


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: python tests/parts/make_parts.py OUTDIR [NAME ...]")
    for name, files in make_parts(sys.argv[1], sys.argv[2:] or None).items():
        print(name, *(str(p) for p in files.values()))
