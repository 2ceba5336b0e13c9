"""Analytic shapes fitted to a patch's facets: circles (of curves), cylinders and tori (of patches), and the
turn a set of points covers round an axis or a torus's tube. Values in, values out: every fit takes arrays
(points, or facet centres, normals and vertices, each (k, 3)) and returns a frozen shape or None."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

CIRCLE_TOLERANCE = 2e-3  # max radial deviation / radius for a curve to count as a circle
TILTED_NORMALS = 0.1  # a cylinder's facet normals: third singular value / first (Gmsh's STLs: 1.3e-2 to 4.7e-2)
AXIS_POINTS = 2000  # at most this many of a patch's vertices (every k-th) fit a cylinder's axis
TORUS_SAMPLES = 256  # facets (and vertices) a torus fit looks at, at most, ...
TORUS_NEIGHBOURS = 6  # ... guessing the tube radius from each one's curvature towards this many nearest, ...
TORUS_RANGE = (1e-3, 10.0)  # ... which lies between these x the patch's size (a sphere's circle, a cone's tube) ...
TORUS_START = (
    0.05  # ... and starting least squares from the best tube radius if the tube centres lie this near a circle
)
SPHERE_MAJOR = 0.05  # x the tube radius: a torus whose circle is smaller is a sphere
TORUS_TOLERANCE = 1e-4  # x the tube radius (or the patch's size if smaller): how far a vertex may lie off the
# torus (a CAD export's vertices lie on it but for rounding, 1e-6 on the corpus; a narrow chamfer, a cone, lies
# within 1e-3 of a torus of huge tube)
FLOAT32 = 1e-6  # x the largest coordinate: an STL's float32 rounding, added to that
TUBE_STEP = 1e-3  # radians round a torus's tube: its vertices lie on three circles this far apart or more
TORUS_STEPS = 30  # evaluations of a torus fit's least squares at most (corpus tori: 3-4; spherical corners: 8-25)
HALF_TURN = 170.0  # degrees round its tube: a concave torus turning less is a fillet, one turning more a bent bore


@dataclass(frozen=True)
class Circle:
    centre: np.ndarray
    axis: np.ndarray
    radius: float


@dataclass(frozen=True)
class Cylinder:
    """A patch that lies on a cylinder; ``concave`` when the material is outside it; ``sweep`` the angle round
    the axis it covers, degrees (360 less the widest gap between its facets' centres and vertices): a hole's
    wall 360, a keyed bore's about 330, a slot end's 180, a fillet's 180 less the angle its faces meet at."""

    point: np.ndarray
    axis: np.ndarray
    radius: float
    concave: bool
    sweep: float

    @property
    def full_turn(self) -> bool:
        """The cylinder goes all the way round (no gap of 30 degrees: a 7-sided hole's facets leave 26)."""
        return self.sweep > 330.0


@dataclass(frozen=True)
class Torus:
    """A patch that lies on a torus (an STL's rim fillet round a hole, a ring): the tube of radius ``minor``
    round the circle of radius ``major`` about ``axis`` through ``centre``; ``concave`` when the material is
    outside the tube (a fillet)."""

    centre: np.ndarray
    axis: np.ndarray
    major: float
    minor: float
    concave: bool


def fit_circle(points: np.ndarray) -> Circle | None:
    """Least-squares circle through ``points`` if they lie on one, else None."""
    centre0 = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre0)
    axis = vt[2]
    u, v = vt[0], vt[1]
    xy = np.column_stack([(points - centre0) @ u, (points - centre0) @ v])
    if np.abs((points - centre0) @ axis).max() > CIRCLE_TOLERANCE * np.ptp(xy):
        return None
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    rhs = (xy**2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(A, rhs, rcond=None)
    radius = float(np.sqrt(c + cx**2 + cy**2))
    deviation = np.abs(np.linalg.norm(xy - [cx, cy], axis=1) - radius).max()
    if len(points) < 6 or deviation > CIRCLE_TOLERANCE * radius:
        return None
    if axis[np.argmax(np.abs(axis))] < 0:
        axis = -axis
    return Circle(centre0 + cx * u + cy * v, axis, radius)


def fit_cylinder(face_centres: np.ndarray, face_normals: np.ndarray, vertices: np.ndarray) -> Cylinder | None:
    """The cylinder a patch lies on (normals perpendicular to one axis, points on one circle), or None."""
    if len(face_normals) < 3:
        return None
    _, singular, vt = np.linalg.svd(face_normals, full_matrices=False)
    axis = vt[2]
    if singular[2] > TILTED_NORMALS * singular[0]:
        return None
    if singular[2] > 1e-3 * singular[0]:  # facets across the axis lines tilt their normals: fit the vertices
        axis = _cylinder_axis(vertices, axis)
    return cylinder_about(axis, face_centres, face_normals, vertices)


def cylinder_about(axis: np.ndarray, face_centres: np.ndarray, face_normals: np.ndarray, vertices: np.ndarray):
    """The cylinder round unit ``axis`` that faces (centres and normals (k, 3)) and their ``vertices`` lie on,
    or None if a vertex strays from one circle seen along it."""
    circle = fit_circle_projected(vertices, axis)
    if circle is None:
        return None
    centre, radius = circle
    radial = face_centres - centre
    radial -= np.outer(radial @ axis, axis)
    concave = bool(np.mean(np.einsum("ij,ij->i", radial, face_normals)) < 0)
    around = np.vstack([radial, vertices - centre])  # a 7-sided hole's facet centres are 51 deg apart, with its
    around -= np.outer(around @ axis, axis)  # vertices 26: a full turn (it was a 'fillet' at feature angle 55)
    if axis[np.argmax(np.abs(axis))] < 0:
        axis = -axis
    return Cylinder(centre, axis, radius, concave, sweep(around, axis))


def fit_torus(face_centres: np.ndarray, face_normals: np.ndarray, vertices: np.ndarray) -> Torus | None:
    """The torus a patch lies on, or None: every vertex within TORUS_TOLERANCE x the smaller of its tube radius
    and the patch's size (and float32 rounding), on three circles round the axis or more (two, a narrow
    chamfer's, lie on tori of every tube radius), the tube no wider than TORUS_RANGE[1] x that size (a cone is
    the limit of ever larger tori) and its circle not shrunk to a point (a sphere).

    Its facets' centres moved along their normals by the tube radius, toward the tube's centre, make one
    circle. The tube radius is guessed from the facets' curvature (TORUS_SAMPLES of them), searched within a
    factor 2 of that for either side of the surface, and if the tube centres then lie within TORUS_START x
    the tube radius of their circle the torus is fitted to the vertices by least squares (scipy). Faces and
    vertices as for :func:`fit_cylinder`."""
    from scipy.optimize import least_squares, minimize_scalar

    if len(face_normals) < 9:
        return None
    size = float(np.ptp(vertices, axis=0).max())
    rng = np.random.default_rng(0)  # a random sample: every k-th facet of a torus's grid lies at one tube angle
    sample = np.sort(rng.choice(len(face_centres), min(TORUS_SAMPLES, len(face_centres)), replace=False))
    centres, normals = face_centres[sample], face_normals[sample]

    def ring(signed):  # (rms distance of the tube centres from their circle / tube radius, centre, axis, R)
        tube = centres - signed * normals
        axis = np.linalg.svd(tube - tube.mean(axis=0), full_matrices=False)[2][2]
        circle = fit_circle_projected(tube, axis, tolerance=np.inf)
        if circle is None or circle[1] < TORUS_RANGE[0] * size:  # tube centres in one point: a sphere
            return np.inf, None, None, None
        off = np.linalg.norm(_tube_section(tube, circle[0], axis, circle[1]), axis=1)
        return float(np.sqrt(np.mean(off**2)) / abs(signed)), circle[0], axis, circle[1]

    # the tube radius, about: the largest curvature between each facet and its nearest sampled neighbours
    near = cKDTree(centres).query(centres, k=min(TORUS_NEIGHBOURS + 1, len(centres)))[1][:, 1:]
    chord = np.linalg.norm(centres[near] - centres[:, None], axis=2)
    turn = np.linalg.norm(normals[near] - normals[:, None], axis=2)  # 2 sin(angle / 2)
    guess = 1.0 / np.median((turn / np.maximum(chord, 1e-300)).max(axis=1))
    if not np.isfinite(guess) or guess > TORUS_RANGE[1] * size:
        return None
    fits = {
        sign: minimize_scalar(lambda r, sign=sign: ring(sign * r)[0], bounds=(guess / 2, 2 * guess), method="bounded")
        for sign in (1.0, -1.0)
    }
    sign = min(fits, key=lambda k: fits[k].fun)
    best = sign * fits[sign].x
    misfit, centre, axis, major = ring(best)
    if not misfit < TORUS_START or _tube_circles(vertices, centre, axis, major) < 3:
        return None  # (on two circles, a narrow chamfer's vertices lie on tori of every tube radius)
    u = _any_perpendicular(axis)
    v = np.cross(axis, u)
    points = vertices[np.sort(rng.choice(len(vertices), min(TORUS_SAMPLES, len(vertices)), replace=False))]

    def unpack(x):
        a = axis + x[3] * u + x[4] * v
        return centre + x[:3], a / np.linalg.norm(a), x[5], x[6]

    def distances(x, at=points):
        c, a, big, small = unpack(x)
        return np.linalg.norm(_tube_section(at, c, a, big), axis=1) - small

    found = least_squares(distances, [0, 0, 0, 0, 0, major, abs(best)], x_scale="jac", max_nfev=TORUS_STEPS)
    torus_centre, torus_axis, major, minor = unpack(found.x)
    if not (SPHERE_MAJOR * minor < major and 0 < minor <= TORUS_RANGE[1] * size):
        return None
    tolerance = TORUS_TOLERANCE * min(minor, size) + FLOAT32 * np.abs(vertices).max()
    if np.abs(distances(found.x, vertices)).max() > tolerance:
        return None
    if torus_axis[np.argmax(np.abs(torus_axis))] < 0:
        torus_axis = -torus_axis
    return Torus(torus_centre, torus_axis, float(major), float(minor), concave=bool(best < 0))


def _tube_section(points: np.ndarray, centre: np.ndarray, axis: np.ndarray, major: float) -> np.ndarray:
    """(k, 2) where ``points`` (k, 3) lie in the tube's cross-section of a torus of circle ``major`` round unit
    ``axis`` through ``centre``: out from the circle (away from the axis) and along the axis."""
    rel = points - centre
    along = rel @ axis
    return np.column_stack([np.linalg.norm(rel - np.outer(along, axis), axis=1) - major, along])


def _tube_circles(vertices: np.ndarray, centre: np.ndarray, axis: np.ndarray, major: float) -> int:
    """On how many circles round ``axis`` ``vertices`` (k, 3) lie, told apart by their angle round the tube of a
    torus of circle ``major`` about ``centre`` (at least TUBE_STEP apart)."""
    out, along = _tube_section(vertices, centre, axis, major).T
    return len(np.unique(np.round(np.arctan2(along, out) / TUBE_STEP)))


def tube_sweep(torus, points: np.ndarray) -> float:
    """The angle (degrees) round the tube of ``torus`` (``centre``, ``axis``, ``major``) that ``points`` (k, 3)
    on it cover."""
    section = _tube_section(points, torus.centre, torus.axis, torus.major)
    return sweep(np.column_stack([section, np.zeros(len(points))]), np.array([0.0, 0.0, 1.0]))


def torus_kind(turn: float) -> str:
    """The kind of a concave torus turning ``turn`` degrees round its tube: less than HALF_TURN a fillet (a
    hole's rim rounded into a face), more a bent bore ('hole')."""
    return "hole" if turn > HALF_TURN else "fillet"


def sweep(radial: np.ndarray, axis: np.ndarray) -> float:
    """The angle (degrees) round ``axis`` that directions ``radial`` (k, 3), perpendicular to it, cover: 360 less
    the widest gap between them."""
    u = _any_perpendicular(axis)
    _, gap = widest_gap(np.arctan2(radial @ np.cross(axis, u), radial @ u))
    return float(360.0 - np.degrees(gap))


def widest_gap(angles: np.ndarray) -> tuple[float, float]:
    """The start and the width (radians) of the widest empty sector between ``angles`` (k,) round a circle."""
    ordered = np.sort(angles)
    gaps = np.diff(np.concatenate([ordered, ordered[:1] + 2 * np.pi]))
    k = int(np.argmax(gaps))
    return float(ordered[k]), float(gaps[k])


def seam(angles: np.ndarray, triangles: np.ndarray) -> tuple[float, bool]:
    """(the angle of a seam in the middle of the widest empty sector between ``angles`` (n,) (radians) round a
    circle, whether the ``triangles`` (t, 3) over them go round: one of them crosses that seam)."""
    start, gap = widest_gap(angles)
    middle = start + gap / 2
    across = np.angle(np.exp(1j * (angles[triangles] - middle - np.pi)))
    return middle, bool((np.ptp(across, axis=1) > np.pi).any())


def _cylinder_axis(vertices: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The axis (3,) of the cylinder through ``vertices`` (k, 3) nearest ``axis``: least squares over the axis
    direction, the centre and the radius (the facets' normals only start it: an STL's triangles that cross the
    cylinder's lines, as Gmsh's or most CAD exports', tilt them by up to a few degrees)."""
    from scipy.optimize import least_squares

    u = _any_perpendicular(axis)
    v = np.cross(axis, u)
    vertices = vertices[:: -(-len(vertices) // AXIS_POINTS)]
    x = vertices - vertices.mean(axis=0)

    def direction(p):
        a = axis + p[0] * u + p[1] * v
        return a / np.linalg.norm(a)

    def residuals(p):
        a = direction(p)
        e1 = u - (u @ a) * a
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(a, e1)
        return np.hypot(x @ e1 - p[2], x @ e2 - p[3]) - p[4]

    start = fit_circle_projected(vertices, axis, tolerance=np.inf)
    if start is None:
        return axis
    centre = start[0] - vertices.mean(axis=0)
    found = least_squares(residuals, [0.0, 0.0, centre @ u, centre @ v, start[1]], x_scale="jac")
    return direction(found.x)


def _any_perpendicular(axis: np.ndarray) -> np.ndarray:
    helper = np.eye(3)[np.argmin(np.abs(axis))]
    v = np.cross(axis, helper)
    return v / np.linalg.norm(v)


def fit_circle_projected(points: np.ndarray, axis: np.ndarray, tolerance: float = CIRCLE_TOLERANCE):
    """Centre (a point on the axis) and radius of the circle the points make seen along ``axis``; None if one
    strays from it by more than ``tolerance`` x the radius."""
    u = _any_perpendicular(axis)
    v = np.cross(axis, u)
    origin = points.mean(axis=0)
    xy = np.column_stack([(points - origin) @ u, (points - origin) @ v])
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    (cx, cy, c), *_ = np.linalg.lstsq(A, (xy**2).sum(axis=1), rcond=None)
    radius = float(np.sqrt(max(c + cx**2 + cy**2, 0.0)))
    if radius == 0 or np.abs(np.linalg.norm(xy - [cx, cy], axis=1) - radius).max() > tolerance * radius:
        return None
    return origin + cx * u + cy * v, radius
