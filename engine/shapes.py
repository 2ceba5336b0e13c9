"""Built-in parametric solids with named features.

Each shape is built with manifold3d (exact booleans, outward-oriented closed
surfaces), faceted finely enough that the chordal error is at most 0.1 % of
the radius of every curved feature, and names its features through rules
applied to the detected features (e.g. the circle where the cylinder meets the
plate is ``junction``). A shape may also carry curves that are not surface
edges, such as a crack front inside a plate.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

import manifold3d as m3
import numpy as np

from .errors import JobError
from .geometry import Geometry, validate_surface
from .plugins import ShapeBuilder
from .registry import Registry
from .schema import NUMBER, STRING, Field, finite, non_negative, positive

CHORDAL_ERROR = 1e-3  # sagitta / radius
SHAPES = Registry(None, [], ShapeBuilder, noun="shape")  # @SHAPES.register(name, parameters={...}) below


def _p(default, doc, check=positive):
    return Field(NUMBER, default=default, check=check, doc=doc)


def segments_for(span_radians: float = 2 * math.pi) -> int:
    """Segments for an arc so that the sagitta is <= CHORDAL_ERROR x radius (multiple of 4 for a full circle)."""
    per_segment = 2 * math.acos(1 - CHORDAL_ERROR)
    n = math.ceil(span_radians / per_segment)
    return int(4 * math.ceil(n / 4)) if span_radians >= 2 * math.pi - 1e-9 else max(n, 1)


@dataclass(frozen=True)
class NameRule:
    """Gives ``name`` to every detected feature of ``kind`` for which ``test`` holds."""

    name: str
    kind: str  # "curve" | "patch"
    test: Callable


@dataclass
class GivenCurve:
    name: str
    points: np.ndarray
    closed: bool = False


@dataclass
class Shape:
    """A built parametric solid: its geometry, naming rules and characteristic lengths."""

    kind: str
    parameters: dict
    geometry: Geometry
    name_rules: list[NameRule]
    given_curves: list[GivenCurve] = field(default_factory=list)
    lengths: dict = field(default_factory=dict)
    face_groups: list[Callable] = field(default_factory=list)


def _tol(size: float) -> float:
    return 1e-6 * size


def plane_patch(axis: int, value: float, sign: int, tol: float) -> Callable:
    def test(patch):
        return patch.normal[axis] * sign > 0.999 and abs(patch.centroid[axis] - value) < tol

    return test


def circle_curve(centre, radius: float, tol: float) -> Callable:
    centre = np.asarray(centre, dtype=float)

    def test(curve):
        c = curve.circle
        return (
            c is not None
            and abs(c.radius - radius) < tol + CHORDAL_ERROR * radius
            and np.linalg.norm(c.centre - centre) < tol + CHORDAL_ERROR * radius
        )

    return test


def cylindrical_patch(point, axis, radius: float, tol: float) -> Callable:
    point, axis = np.asarray(point, float), np.asarray(axis, float) / np.linalg.norm(axis)

    def test(patch):
        if patch.planar:
            return False
        rel = patch.vertices - point
        dist = np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1)
        return bool(np.all(np.abs(dist - radius) < tol + CHORDAL_ERROR * radius))

    return test


def on_cylinder(point, axis, radius: float, tol: float) -> Callable:
    """Face selector: triangles whose three corners lie on the given cylinder."""
    point, axis = np.asarray(point, float), np.asarray(axis, float) / np.linalg.norm(axis)

    def select(triangles):
        rel = triangles - point
        dist = np.linalg.norm(rel - (rel @ axis)[..., None] * axis, axis=2)
        return np.all(np.abs(dist - radius) < tol + CHORDAL_ERROR * radius, axis=1)

    return select


def box_faces(lo, hi, prefix: str = "") -> list[NameRule]:
    """Rules naming the six planar faces of a box: x-min, x-max, ..., bottom (z-min), top (z-max)."""
    tol = _tol(float(np.max(np.subtract(hi, lo))))
    names = [
        ("x-min", 0, lo[0], -1),
        ("x-max", 0, hi[0], 1),
        ("y-min", 1, lo[1], -1),
        ("y-max", 1, hi[1], 1),
        ("bottom", 2, lo[2], -1),
        ("top", 2, hi[2], 1),
    ]
    return [NameRule(prefix + n, "patch", plane_patch(a, v, s, tol)) for n, a, v, s in names]


def _geometry(solid: m3.Manifold, kind: str, volume: float) -> Geometry:
    """The faceted ``solid`` as a Geometry that knows the exact ``volume`` of the shape it stands for."""
    mesh = solid.to_mesh()
    geometry = validate_surface(
        mesh.vert_properties[:, :3], mesh.tri_verts, f"shape '{kind}'", check_self_intersections=False
    )
    return dataclasses.replace(geometry, exact_volume=float(volume))


def _box(lx, ly, lz) -> m3.Manifold:
    return m3.Manifold.cube([lx, ly, lz]).translate([-lx / 2, -ly / 2, 0])


@SHAPES.register("cylinder", parameters={"radius": _p(25.0, "cylinder radius"), "height": _p(100.0, "cylinder height")})
def cylinder(radius: float, height: float) -> Shape:
    """Solid circular cylinder on the z=0 plane, axis z (the paper's Fig. 7)."""
    solid = m3.Manifold.cylinder(height, radius, radius, segments_for())
    tol = _tol(max(radius, height))
    rules = [
        NameRule("bottom", "patch", plane_patch(2, 0.0, -1, tol)),
        NameRule("top", "patch", plane_patch(2, height, 1, tol)),
        NameRule("side", "patch", cylindrical_patch([0, 0, 0], [0, 0, 1], radius, tol)),
        NameRule("bottom-edge", "curve", circle_curve([0, 0, 0], radius, tol)),
        NameRule("top-edge", "curve", circle_curve([0, 0, height], radius, tol)),
    ]
    return Shape(
        "cylinder",
        dict(radius=radius, height=height),
        _geometry(solid, "cylinder", math.pi * radius**2 * height),
        rules,
        lengths=dict(radius=radius, height=height),
    )


@SHAPES.register(
    "plate",
    parameters={
        "length": _p(200.0, "plate length (x)"),
        "width": _p(200.0, "plate width (y)"),
        "thickness": _p(20.0, "plate thickness (z)"),
    },
)
def plate(length: float, width: float, thickness: float) -> Shape:
    """Rectangular plate centred on the z axis, bottom face on z=0."""
    solid = _box(length, width, thickness)
    lo, hi = [-length / 2, -width / 2, 0], [length / 2, width / 2, thickness]
    return Shape(
        "plate",
        dict(length=length, width=width, thickness=thickness),
        _geometry(solid, "plate", length * width * thickness),
        box_faces(lo, hi),
        lengths=dict(thickness=thickness),
    )


@SHAPES.register(
    "plate_with_hole",
    parameters={
        "length": _p(200.0, "plate length (x)"),
        "width": _p(100.0, "plate width (y)"),
        "thickness": _p(10.0, "plate thickness (z)"),
        "hole_radius": _p(10.0, "hole radius"),
        "hole_x": _p(0.0, "hole centre x", finite),
        "hole_y": _p(0.0, "hole centre y", finite),
    },
)
def plate_with_hole(
    length: float, width: float, thickness: float, hole_radius: float, hole_x: float, hole_y: float
) -> Shape:
    """Plate with a circular through hole (named ``hole``: its wall and both rims)."""
    if hole_radius >= min(width / 2 - abs(hole_y), length / 2 - abs(hole_x)):
        raise JobError("the hole does not fit inside the plate", fix="make 'hole_radius' smaller or the plate larger")
    hole = m3.Manifold.cylinder(thickness * 3, hole_radius, hole_radius, segments_for()).translate(
        [hole_x, hole_y, -thickness]
    )
    solid = _box(length, width, thickness) - hole
    tol = _tol(max(length, width))
    lo, hi = [-length / 2, -width / 2, 0], [length / 2, width / 2, thickness]
    rules = box_faces(lo, hi) + [
        NameRule("hole", "patch", cylindrical_patch([hole_x, hole_y, 0], [0, 0, 1], hole_radius, tol)),
        NameRule("hole", "curve", circle_curve([hole_x, hole_y, 0], hole_radius, tol)),
        NameRule("hole", "curve", circle_curve([hole_x, hole_y, thickness], hole_radius, tol)),
    ]
    return Shape(
        "plate_with_hole",
        dict(length=length, width=width, thickness=thickness, hole_radius=hole_radius, hole_x=hole_x, hole_y=hole_y),
        _geometry(solid, "plate_with_hole", (length * width - math.pi * hole_radius**2) * thickness),
        rules,
        lengths=dict(thickness=thickness, hole_radius=hole_radius, width=width),
    )


@SHAPES.register(
    "plate_cylinder_junction",
    parameters={
        "length": _p(200.0, "plate length (x)"),
        "width": _p(200.0, "plate width (y)"),
        "thickness": _p(20.0, "plate thickness (z)"),
        "radius": _p(25.0, "cylinder radius"),
        "height": _p(100.0, "cylinder height above the plate"),
        "offset": _p(60.0, "cylinder axis x from the plate centre (0 = centre)", finite),
    },
)
def plate_cylinder_junction(
    length: float, width: float, thickness: float, radius: float, height: float, offset: float
) -> Shape:
    """Plate with a solid cylinder standing on its top face (the paper's Fig. 10).

    The cylinder axis is at x = ``offset`` from the plate centre: 0 stands it at
    the centre, a larger offset near the plate edge x = length/2. Names:
    ``junction`` (the circle where cylinder meets plate), ``plate-edge`` (the
    side face of the plate nearest the cylinder), ``cylinder`` (its side),
    ``cylinder-top``, ``top``/``bottom`` and the other plate faces.
    """
    gap = length / 2 - abs(offset) - radius
    if gap <= 0 or radius >= width / 2:
        raise JobError(
            "the cylinder does not stand inside the plate", fix="make 'radius' or 'offset' smaller, or the plate larger"
        )
    cyl = m3.Manifold.cylinder(height + thickness / 2, radius, radius, segments_for()).translate(
        [offset, 0, thickness / 2]
    )
    solid = _box(length, width, thickness) + cyl
    tol = _tol(max(length, width, height))
    lo, hi = [-length / 2, -width / 2, 0], [length / 2, width / 2, thickness]
    side = 1 if offset >= 0 else -1
    rules = box_faces(lo, hi) + [
        NameRule("junction", "curve", circle_curve([offset, 0, thickness], radius, tol)),
        NameRule("plate-edge", "patch", plane_patch(0, side * length / 2, side, tol)),
        NameRule("cylinder", "patch", cylindrical_patch([offset, 0, 0], [0, 0, 1], radius, tol)),
        NameRule("cylinder-top", "patch", plane_patch(2, thickness + height, 1, tol)),
    ]
    params = dict(length=length, width=width, thickness=thickness, radius=radius, height=height, offset=offset)
    return Shape(
        "plate_cylinder_junction",
        params,
        _geometry(solid, "plate_cylinder_junction", length * width * thickness + math.pi * radius**2 * height),
        rules,
        lengths=dict(thickness=thickness, radius=radius, edge_gap=gap),
    )


@SHAPES.register(
    "l_bracket",
    parameters={
        "leg_length": _p(80.0, "base leg length (x)"),
        "leg_height": _p(80.0, "upright leg height (z)"),
        "thickness": _p(15.0, "leg thickness"),
        "width": _p(40.0, "extrusion width (y)"),
        "fillet_radius": _p(8.0, "inner corner fillet radius (0 = sharp)", non_negative),
    },
)
def l_bracket(leg_length: float, leg_height: float, thickness: float, width: float, fillet_radius: float) -> Shape:
    """L-shaped bracket: a base leg along x, an upright leg along z, the inner corner filleted.

    The profile lies in the x-z plane and is extruded along y over ``width``
    (centred). Names: ``fillet`` (the filleted inner corner surface),
    ``base-bottom``, ``upright-top``, ``base-end``, ``upright-back``.
    """
    t, r = thickness, fillet_radius
    if t >= min(leg_length, leg_height) or r >= min(leg_length, leg_height) - t:
        raise JobError(
            "the bracket profile is inconsistent",
            fix="thickness must be less than both legs, and fillet_radius less than each leg minus thickness",
        )
    n = segments_for(math.pi / 2)
    centre = np.array([t + r, t + r])
    angles = np.linspace(1.5 * math.pi, math.pi, n + 1)  # counter-clockwise: from (t+r, t) to (t, t+r)
    arc = centre + r * np.column_stack([np.cos(angles), np.sin(angles)])
    profile = np.vstack([[0, 0], [leg_length, 0], [leg_length, t], arc, [t, leg_height], [0, leg_height]])
    if r == 0:
        profile = np.array([[0, 0], [leg_length, 0], [leg_length, t], [t, t], [t, leg_height], [0, leg_height]])
    section = m3.CrossSection([profile.tolist()])
    solid = m3.Manifold.extrude(section, width).rotate([90, 0, 0]).translate([0, width / 2, 0])
    tol = _tol(max(leg_length, leg_height, width))
    rules = [
        NameRule("base-bottom", "patch", plane_patch(2, 0, -1, tol)),
        NameRule("upright-top", "patch", plane_patch(2, leg_height, 1, tol)),
        NameRule("base-end", "patch", plane_patch(0, leg_length, 1, tol)),
        NameRule("upright-back", "patch", plane_patch(0, 0, -1, tol)),
    ]
    groups = []
    if r > 0:
        rules.append(NameRule("fillet", "patch", cylindrical_patch([t + r, 0, t + r], [0, 1, 0], r, tol)))
        groups.append(on_cylinder([t + r, 0, t + r], [0, 1, 0], r, tol))
    params = dict(
        leg_length=leg_length, leg_height=leg_height, thickness=thickness, width=width, fillet_radius=fillet_radius
    )
    return Shape(
        "l_bracket",
        params,
        _geometry(solid, "l_bracket", (leg_length * t + (leg_height - t) * t + (1 - math.pi / 4) * r**2) * width),
        rules,
        lengths=dict(thickness=t, fillet_radius=r),
        face_groups=groups,
    )


@SHAPES.register(
    "cracked_plate",
    parameters={
        "length": _p(200.0, "plate length (x)"),
        "width": _p(100.0, "plate width (y)"),
        "thickness": _p(20.0, "plate thickness (z)"),
        "crack": Field(
            STRING, default="semi-elliptical", choices=("straight", "semi-elliptical"), doc="crack front shape"
        ),
        "crack_length": _p(20.0, "crack length (straight) or half-length (semi-elliptical)"),
        "crack_depth": _p(10.0, "depth of the semi-elliptical crack into the thickness"),
    },
)
def cracked_plate(
    length: float, width: float, thickness: float, crack: str, crack_length: float, crack_depth: float
) -> Shape:
    """A plate with a crack front curve inside it (the solid is the uncracked plate).

    ``crack: straight`` is a through-thickness edge crack in the plane y=0 from
    the edge x=-length/2; its front is the straight line at x=-length/2+crack_length.
    ``crack: semi-elliptical`` is a surface crack in the plane y=0 at the plate
    centre, half-length ``crack_length`` along x and depth ``crack_depth`` into
    the thickness from the top face; its front is the half ellipse.
    The front is named ``crack-front``.
    """
    if crack == "straight":
        if crack_length >= length:
            raise JobError("the crack is longer than the plate", fix="make 'crack_length' smaller")
        x = -length / 2 + crack_length
        count = max(2, math.ceil(thickness / (0.05 * thickness)) + 1)
        z = np.linspace(0, thickness, count)
        front = np.column_stack([np.full_like(z, x), np.zeros_like(z), z])
    else:
        if crack_depth >= thickness or crack_length >= length / 2:
            raise JobError(
                "the semi-elliptical crack does not fit in the plate",
                fix="make 'crack_depth' less than the thickness and 'crack_length' less than half the length",
            )
        angles = np.linspace(0, math.pi, segments_for(math.pi) + 1)
        front = np.column_stack(
            [crack_length * np.cos(angles), np.zeros_like(angles), thickness - crack_depth * np.sin(angles)]
        )
    lo, hi = [-length / 2, -width / 2, 0], [length / 2, width / 2, thickness]
    params = dict(
        length=length, width=width, thickness=thickness, crack=crack, crack_length=crack_length, crack_depth=crack_depth
    )
    return Shape(
        "cracked_plate",
        params,
        _geometry(_box(length, width, thickness), "cracked_plate", length * width * thickness),
        box_faces(lo, hi),
        [GivenCurve("crack-front", front)],
        lengths=dict(thickness=thickness, crack_length=crack_length),
    )


def sphere_segments() -> int:
    """Segments for a manifold3d sphere whose triangles lie within CHORDAL_ERROR x radius of it.

    Its triangles are wider than the steps along its great circles, so the circle's count is raised
    (the sagitta falls as 1 / segments^2) until the measured deviation of the face centroids is small enough.
    """
    segments = segments_for()
    while True:
        mesh = m3.Manifold.sphere(1.0, segments).to_mesh()
        sagitta = 1 - np.linalg.norm(mesh.vert_properties[mesh.tri_verts, :3].mean(axis=1), axis=1).min()
        if sagitta <= CHORDAL_ERROR:
            return segments
        segments = int(4 * math.ceil(segments * math.sqrt(sagitta / CHORDAL_ERROR) / 4))


def spherical_patch(centre, radius: float, tol: float) -> Callable:
    centre = np.asarray(centre, float)

    def test(patch):
        dist = np.linalg.norm(patch.vertices - centre, axis=1)
        return not patch.planar and bool(np.all(np.abs(dist - radius) < tol + CHORDAL_ERROR * radius))

    return test


@SHAPES.register(
    "hollow_sphere_octant",
    parameters={"inner_radius": _p(50.0, "inner radius"), "outer_radius": _p(100.0, "outer radius")},
)
def hollow_sphere_octant(inner_radius: float, outer_radius: float) -> Shape:
    """One eighth (x, y, z >= 0) of a thick hollow sphere centred on the origin, for Lamé's problem.

    Names: ``inner`` and ``outer`` (the spherical surfaces), ``symmetry-x`` (the face on the plane
    x = 0), ``symmetry-y`` and ``symmetry-z``.
    """
    a, b = inner_radius, outer_radius
    if a >= b:
        raise JobError(
            "the inner radius is not smaller than the outer radius",
            fix="make 'inner_radius' smaller than 'outer_radius'",
        )
    segments = sphere_segments()
    shell = m3.Manifold.sphere(b, segments) - m3.Manifold.sphere(a, segments)
    solid = shell ^ m3.Manifold.cube([2 * b, 2 * b, 2 * b])
    tol = _tol(b)
    rules = [
        NameRule("inner", "patch", spherical_patch([0, 0, 0], a, tol)),
        NameRule("outer", "patch", spherical_patch([0, 0, 0], b, tol)),
        NameRule("symmetry-x", "patch", plane_patch(0, 0.0, -1, tol)),
        NameRule("symmetry-y", "patch", plane_patch(1, 0.0, -1, tol)),
        NameRule("symmetry-z", "patch", plane_patch(2, 0.0, -1, tol)),
    ]
    return Shape(
        "hollow_sphere_octant",
        dict(inner_radius=a, outer_radius=b),
        _geometry(solid, "hollow_sphere_octant", math.pi / 6 * (b**3 - a**3)),
        rules,
        lengths=dict(inner_radius=a, outer_radius=b, thickness=b - a),
    )


def build_shape(kind: str, parameters: dict) -> Shape:
    """Build shape ``kind`` from already validated ``parameters``."""
    return SHAPES.get(kind)(**parameters)
