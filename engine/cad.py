"""CAD input: STEP, IGES and BREP solids read through Gmsh's OpenCASCADE kernel.

:func:`load_cad` imports the file (STEP and IGES converted to millimetres, OpenCASCADE's default; a file
without a solid is healed: faces sewn, solids made), fragments several solids (touching ones, which share a
face after the fragment, are an assembly: see :class:`Assembly`) and tessellates
the CAD faces with OpenCASCADE's BRepMesh (Gmsh's 2-D mesher where that is not a valid solid) into one closed
surface whose triangles know their CAD face. The
:class:`Geometry` is that surface; the :class:`Features` are found on it with every CAD face a patch of its
own (adjacent faces of one cylinder, cone, sphere or torus, as exporters split periodic faces, make one
patch), so every CAD edge between two faces is a curve. Patches and curves are then named from the file (its
labels) or ``face-N`` / ``edge-N`` (N the CAD tag), get feature kinds from their face types (a concave torus
is a fillet of its minor radius, or a hole where it turns half round its tube: a bent bore; a narrow cone a
chamfer or, concave, a countersink; cylinders keep the shipped tests with the CAD's axis and radius), and
each an exact surface or curve (analytic for planes, cylinders, cones, spheres and tori, else the CAD entity's
closest point) onto which :mod:`engine.exact` moves the mesh nodes and 10-node mid-edge nodes; a face that is
neither a plane nor a cylinder is triangulated in its own parameters (:class:`engine.facechart.FaceChart`), not cut
into charts.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import logging
import re
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy import sparse
from scipy.sparse import csgraph

from .errors import GeometryError
from .exact import EXACT_TOLERANCE, Cone, CylinderSurface, Plane, Sphere, Torus, fit_analytic
from .facechart import FaceChart
from .features import NARROW_REGION, Features, detect_features, unit
from .fitting import Circle, Cylinder, sweep, torus_kind, tube_sweep
from .geometry import Geometry, validate_surface

log = logging.getLogger(__name__)

CAD_FORMATS = (".step", ".stp", ".iges", ".igs", ".brep")
TURN_ANGLE = 10.0  # tessellation: degrees of turn per facet of a curved face
RETRY_TURN = 15.0  # BRepMesh tried again at this turn (its folds depend on it) before Gmsh's mesher
DEFLECTION = 1e-3  # tessellation: largest sagitta, x the model size
MESHER_SIZE = 40  # Gmsh's 2-D mesh, where OpenCASCADE's tessellation fails: longest side = model size / this
HEAL_TOLERANCE = 1e-6  # x the model size: faces of a file without solids are sewn across gaps this wide
SLIVER = 1e-5  # x the model size: a face narrower than this on average is an artefact the model is healed of
SAME_SURFACE = 1e-6  # x the model size: two faces' parameters closer than this describe one surface
UNNAMED_PRODUCT = "Open CASCADE STEP translator"  # the product name OpenCASCADE writes for an unnamed solid
NARROW = 1.0  # a cone narrower along its slant than this x its mean radius is a chamfer
ANALYTIC = ("Plane", "Cylinder", "Cone", "Sphere", "Torus")  # the face types whose parameters Gmsh gives
FIT_POINTS = 23  # per parameter, a non-analytic face's points fitted (a prime: not all on a spline's knots)
FIT_TOLERANCE = 1e-4  # x the model size: a non-analytic face whose points lie this near one is that surface
BLEND_SPREAD = 0.02  # a non-analytic face whose larger principal curvature varies less than this is a rolling ball's
SEED_SPACING = 1 / 400  # x the model size: the grid of parameters closest points start from, ...
MAX_SEEDS = 400_000  # ... at most this many points per CAD face or edge
COARSE_SEEDS = 17  # parameter values per direction of the grid that measures the parameter lines' lengths
NEWTON_STEPS = 12  # Gauss-Newton steps towards a closest point, ...
NEWTON_TOLERANCE = 1e-11  # ... until a step moves the point less than this x the model size
PARAMETRIZED = 256  # CAD faces and edges whose seed grids are kept (each up to MAX_SEEDS points)
MASS_TRUST = 1e-3  # x the volume: OpenCASCADE's volume of the solids is trusted within this (plus twice the chords'
# share) of the tessellation's
CHORD_SAMPLES = 20_000  # the longest facets whose distance from the CAD faces measures the tessellation's


@dataclass(frozen=True)
class CadModel:
    """The OpenCASCADE model of ``path`` as Gmsh holds it, under ``name`` (:func:`load_cad`: the path and a digest
    of the file's bytes, so that a file written again at the same path is a model of its own); rebuilt the same
    way (same tags) whenever another user of Gmsh has removed it."""

    path: str
    name: str

    @contextmanager
    def current(self):
        import gmsh

        if not gmsh.isInitialized():
            gmsh.initialize(["-noenv"], readConfigFiles=False, interruptible=False)  # see tetra.gmsh_session
            gmsh.option.setNumber("General.Terminal", 0)
        previous = gmsh.model.getCurrent()
        if self.name in gmsh.model.list():
            gmsh.model.setCurrent(self.name)
        else:
            gmsh.model.add(self.name)
            _build(self.path)
        try:
            yield gmsh.model
        finally:
            if previous and previous in gmsh.model.list():
                gmsh.model.setCurrent(previous)

    def parametrized(self, gm, dim: int, tag: int) -> Parametrized:
        """The :class:`Parametrized` of entity ``tag`` of dimension ``dim`` (``gm``: Gmsh's model, this one current)."""
        return _parametrized(self.name, gm, dim, tag)

    def closest(self, dim: int, tags: tuple, points: np.ndarray) -> np.ndarray:
        """(k, 3) closest points to ``points`` (k, 3) on the entities ``tags`` of dimension ``dim``
        (:class:`Parametrized`)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) == 0:
            return points.copy()
        with self.current() as model:
            candidates = np.stack([self.parametrized(model, dim, tag).closest(model, points) for tag in tags])
        best = np.argmin(np.linalg.norm(candidates - points, axis=2), axis=0)
        return candidates[best, np.arange(len(points))]


@functools.lru_cache(maxsize=PARAMETRIZED)
def _parametrized(name: str, model, dim: int, tag: int) -> Parametrized:
    """The :class:`Parametrized` of an entity of the model ``name`` (``model``: Gmsh's, that model current)."""
    return Parametrized.of(model, dim, tag, _model_size(name, model))


@functools.lru_cache(maxsize=PARAMETRIZED)
def _model_size(name: str, model) -> float:
    """The diagonal of the bounding box of the model ``name`` (``model``: Gmsh's, that model current); Gmsh takes
    2 ms to compute it (a gear's 1,013 faces and edges: 2 s)."""
    lo, hi = np.reshape(model.getBoundingBox(-1, -1), (2, 3))
    return float(np.linalg.norm(hi - lo))


@dataclass(frozen=True)
class Parametrized:
    """A CAD edge's or face's parametrisation, for closest points: from the nearest of its points at a grid of
    parameters (SEED_SPACING x the model size apart in space, at most MAX_SEEDS), Gauss-Newton steps on the
    parameters (Gmsh's getValue and getDerivative), a periodic parameter wrapped, a bounded one clamped; a point
    where that does not converge takes Gmsh's getClosestPoint. That takes 4 ms a point on a spring's swept
    B-spline face (80k surface nodes: 5 minutes), getValue 1.5 us."""

    dim: int
    tag: int
    low: np.ndarray  # (dim,) parameter bounds
    high: np.ndarray
    periodic: np.ndarray  # (dim,) bool
    seeds: np.ndarray  # (s, dim) parameters of the grid
    tree: object  # cKDTree of the grid's points
    tolerance: float  # a Gauss-Newton step moving the point less than this ends it (NEWTON_TOLERANCE x model size)

    @classmethod
    def of(cls, model, dim: int, tag: int, size: float) -> Parametrized:
        """The entity ``tag`` of dimension ``dim`` of Gmsh's current ``model``, whose size (its bounding box's
        diagonal) is ``size``."""
        from scipy.spatial import cKDTree

        low, high = (np.asarray(b, float).reshape(dim) for b in model.getParametrizationBounds(dim, tag))

        def grid(counts):
            axes = [np.linspace(low[k], high[k], int(counts[k])) for k in range(dim)]
            return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)

        def points(parameters):
            return np.reshape(model.getValue(dim, tag, parameters.ravel()), (-1, 3))

        along = points(grid([COARSE_SEEDS] * dim)).reshape([COARSE_SEEDS] * dim + [3])  # the parameter lines
        lengths = [float(np.linalg.norm(np.diff(along, axis=k), axis=-1).sum(axis=k).max()) for k in range(dim)]
        counts = np.clip(np.ceil(np.array(lengths) / max(SEED_SPACING * size, 1e-300)) + 1, COARSE_SEEDS, None)
        counts = np.maximum(2, np.floor(counts * min(1.0, (MAX_SEEDS / counts.prod()) ** (1 / dim))))
        seeds = grid(counts)
        middle = (low + high) / 2
        periodic = np.zeros(dim, bool)
        for k in range(dim):  # the two ends of a parameter line through the middle meet: periodic
            ends = np.tile(middle, (2, 1))
            ends[:, k] = low[k], high[k]
            ends = points(ends)
            periodic[k] = np.linalg.norm(ends[0] - ends[1]) <= 1e-9 * size
        return cls(dim, tag, low, high, periodic, seeds, cKDTree(points(seeds)), NEWTON_TOLERANCE * size)

    @property
    def period(self) -> np.ndarray:
        """(dim,) the length of each parameter's range (1 where it is a point)."""
        return np.where(self.high > self.low, self.high - self.low, 1.0)

    def _wrapped(self, parameters: np.ndarray) -> np.ndarray:
        """``parameters`` (k, dim) with the periodic ones taken into their period, the others clamped to their
        bounds."""
        low, high = self.low, self.high
        return np.clip(np.where(self.periodic, low + np.mod(parameters - low, self.period), parameters), low, high)

    def closest(self, model, points: np.ndarray) -> np.ndarray:
        """(k, 3) the closest points to ``points`` (k, 3) on the entity."""
        parameters, converged = self._newton(model, points)
        out = np.reshape(model.getValue(self.dim, self.tag, parameters.ravel()), (-1, 3))
        if not converged.all():
            rest = np.flatnonzero(~converged)
            out[rest] = np.reshape(model.getClosestPoint(self.dim, self.tag, points[rest].ravel())[0], (-1, 3))
        return out

    def parameters(self, model, points: np.ndarray) -> np.ndarray:
        """(k, 2) the parameters of the closest points to ``points`` (k, 3) on the face (a face's only: Gmsh's
        getClosestPoint, where Gauss-Newton does not converge, gives no parameters on a curve)."""
        parameters, converged = self._newton(model, points)
        if not converged.all():
            rest = np.flatnonzero(~converged)
            parameters[rest] = np.reshape(model.getClosestPoint(2, self.tag, points[rest].ravel())[1], (-1, 2))
        return parameters

    def _newton(self, model, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(parameters (k, dim), converged (k,) bool): Gauss-Newton from the nearest seeds towards the closest
        points to ``points`` (k, 3)."""
        dim, tag = self.dim, self.tag
        parameters = self.seeds[self.tree.query(points)[1]].copy()
        period = self.period
        converged = np.zeros(len(points), bool)
        for _ in range(NEWTON_STEPS):
            active = np.flatnonzero(~converged)
            if len(active) == 0:
                break
            at = parameters[active]
            x = np.reshape(model.getValue(dim, tag, at.ravel()), (-1, 3))
            jacobian = np.reshape(model.getDerivative(dim, tag, at.ravel()), (-1, dim, 3))  # d x / d parameter
            residual = points[active] - x
            normal = np.einsum("kid,kjd->kij", jacobian, jacobian)
            normal += 1e-12 * np.trace(normal, axis1=1, axis2=2)[:, None, None] * np.eye(dim) + 1e-300 * np.eye(dim)
            step = np.linalg.solve(normal, np.einsum("kid,kd->ki", jacobian, residual)[..., None])[..., 0]
            new = self._wrapped(at + step)
            held = ~self.periodic & (new != at + step)  # at a bound: the other parameter steps alone (an edge)
            if dim == 2 and (one := held.sum(axis=1) == 1).any():
                rows = np.flatnonzero(one)
                free = np.argmin(held[rows], axis=1)
                along = jacobian[rows, free]
                alone = np.einsum("kd,kd->k", along, residual[rows]) / np.maximum(
                    np.einsum("kd,kd->k", along, along), 1e-300
                )
                trial = new[rows]
                trial[np.arange(len(rows)), free] = at[rows, free] + alone
                new[rows] = self._wrapped(trial)
            taken = new - at  # the step as taken (clamped), the shorter way round a period
            taken -= np.where(self.periodic, period * np.round(taken / period), 0.0)
            moved = np.linalg.norm(np.einsum("ki,kid->kd", taken, jacobian), axis=1)
            parameters[active] = new
            converged[active[moved <= self.tolerance]] = True
        return parameters, converged


@dataclass(frozen=True)
class CadEntity:
    """CAD faces (dim 2) or edges (dim 1) as an exact surface or curve: ``project(points)`` their closest points."""

    model: CadModel
    dim: int
    tags: tuple

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the entities."""
        return self.model.closest(self.dim, self.tags, x)


@dataclass
class Interface:
    """CAD faces two solids share (after OpenCASCADE's fragment): ``bodies`` (a, b), 0-based, a < b."""

    name: str
    bodies: tuple
    faces: tuple  # CAD face tags


@dataclass
class Assembly:
    """Touching solids of a CAD file: each body's own (Geometry, Features), its name (from the file, else
    ``solid-N``), its CAD volume, the CAD face tags of each of its patches and the CAD edge tags of each of its
    curves (the union's as ``union_patch_faces`` / ``union_curve_edges``), and the shared faces."""

    names: list
    bodies: list  # (Geometry, Features) per body
    patch_faces: list  # per body, per patch: tuple of CAD face tags
    curve_edges: list  # per body, per curve: tuple of CAD edge tags
    union_patch_faces: list
    union_curve_edges: list
    interfaces: list  # Interface
    shared_faces: frozenset
    volumes: list = dataclasses.field(default_factory=list)  # per body, its CAD solid's volume (OpenCASCADE's)


def load_cad(path: str | Path, feature_angle: float = 30.0, *, allow_multiple_solids: bool = False, assembly=True):
    """(Geometry, Features) of a STEP, IGES or BREP file (module docstring). Touching solids are an assembly
    (all the file's solids its bodies, ``allow_multiple_solids`` or not): the Geometry is their union's outer
    surface, each face's body the solid it bounds, and ``Features.assembly`` holds each solid's own (Geometry,
    Features, CAD volume) and the shared faces, for :func:`engine.assembly.mesh_assembly`; with ``assembly``
    False they are refused instead. Several solids none of which touch need ``allow_multiple_solids``."""
    path = Path(path)
    source = str(path)
    if path.suffix.lower() not in CAD_FORMATS:
        raise GeometryError(
            f"unknown CAD format '{path.suffix or '(none)'}'",
            where=source,
            fix=f"give one of: {', '.join(CAD_FORMATS)}",
        )
    if not path.is_file():
        raise GeometryError("file not found", where=source, fix="check the path")
    resolved = path.resolve()
    model = CadModel(str(resolved), f"fuzzymesh-cad:{resolved}:{hashlib.sha1(resolved.read_bytes()).hexdigest()}")
    with model.current() as gm:
        solids = np.array([tag for _, tag in gm.getEntities(3)])
        if not len(solids):
            raise GeometryError(
                "the file holds no solid (and its faces could not be sewn into one)",
                where=source,
                fix="export the part as a solid body",
            )
        faces = np.array([tag for _, tag in gm.getEntities(2)])
        size = _model_size(model.name, gm)
        face_solids = [tuple(sorted(np.searchsorted(solids, gm.getAdjacencies(2, tag)[0]).tolist())) for tag in faces]
        shared = [k for k, owners in enumerate(face_solids) if len(owners) > 1]
        touching = len({b for k in shared for b in face_solids[k]})
        if len(solids) > 1 and not shared and not allow_multiple_solids:
            raise GeometryError(
                f"the file holds {len(solids)} solids",
                where=source,
                fix="set 'allow_multiple_solids: true' in the job's geometry to mesh each solid as a body, or mesh "
                "them one at a time",
            )
        if shared and not assembly:
            raise GeometryError(
                f"{touching} of the file's {len(solids)} solids touch (they share {len(shared)} faces, the first "
                f"face-{faces[shared[0]]}): this caller does not mesh an assembly",
                where=source,
                fix="mesh the file through the pipeline (fuzzymesh mesh), fuse the touching solids into one in the "
                "CAD tool, or move them apart",
            )
        allow_multiple_solids = allow_multiple_solids or bool(shared)  # an assembly's solids are all bodies
        solid_volumes = [float(gm.occ.getMass(3, int(tag))) for tag in solids]
        solid_names = _numbered(
            [_solid_name(gm.getEntityName(3, tag)) or f"solid-{k + 1}" for k, tag in enumerate(solids)]
        )
        cad = _CadFaces(
            source,
            model,
            faces,
            [_face_surface(gm, tag, size) for tag in faces],
            [_label(gm.getEntityName(2, tag)) or f"face-{tag}" for tag in faces],
            face_solids,
            np.array([tag for _, tag in gm.getEntities(1)]),
            feature_angle,
        )
        cad.edge_names = [_label(gm.getEntityName(1, tag)) or f"edge-{tag}" for tag in cad.edges]
        cad.edge_faces = [np.searchsorted(faces, gm.getAdjacencies(1, tag)[0]).tolist() for tag in cad.edges]
    outer = np.array([len(owners) == 1 for owners in face_solids])
    for attempt, (mesher, turn) in enumerate(((False, TURN_ANGLE), (False, RETRY_TURN), (True, TURN_ANGLE))):
        if attempt == 1:  # BRepMesh again, on a fresh copy of the model (its first tessellation stays with it)
            with CadModel(model.path, f"{model.name}#retry").current() as gm:
                vertices, triangles, face_tag = _tessellate(gm, mesher, turn)
                gm.remove()
        else:
            with model.current() as gm:
                vertices, triangles, face_tag = _tessellate(gm, mesher, turn)
        try:
            if not mesher:
                _refuse_folds(vertices, triangles, face_tag, feature_angle, source)
            geometry, features, patch_faces, curve_edges = cad.solid(
                vertices, triangles, np.searchsorted(faces, face_tag), outer, allow_multiple_solids
            )
            bodies = (
                [
                    cad.solid(
                        vertices,
                        triangles,
                        np.searchsorted(faces, face_tag),
                        np.array([b in owners for owners in face_solids]),
                        False,
                    )
                    for b in range(len(solids))
                ]
                if shared
                else []
            )
            break
        except GeometryError as error:
            if mesher:
                raise
            if attempt == 0:
                log.info(
                    "%s: OpenCASCADE's tessellation at %g degrees a facet is no valid solid (%s): tessellating "
                    "again at %g degrees",
                    source,
                    TURN_ANGLE,
                    error.what,
                    RETRY_TURN,
                )
                continue
            log.warning(
                "%s: OpenCASCADE's tessellation is not a valid solid (%s): the faces are meshed by Gmsh "
                "instead, where a closed cylinder or cone (a hole) may be cut into charts and not recognised",
                source,
                error.what,
            )
    chord, missing = _chord(geometry, features)
    solid_volumes = _trusted(solid_volumes, geometry, missing, source)
    geometry = dataclasses.replace(geometry, chord=chord, exact_volume=sum(solid_volumes) if solid_volumes else None)
    if shared:
        face = np.searchsorted(faces, face_tag)
        kept = cad.kept(vertices, triangles, face, outer)
        geometry = dataclasses.replace(geometry, face_body=np.array([face_solids[k][0] for k in kept], np.int64))
        pairs = sorted({face_solids[k] for k in shared})
        features = dataclasses.replace(
            features,
            assembly=Assembly(
                solid_names,
                [(g, f) for g, f, _, _ in bodies],
                [pf for _, _, pf, _ in bodies],
                [ce for _, _, _, ce in bodies],
                patch_faces,
                curve_edges,
                [
                    Interface(
                        f"interface-{solid_names[a]}-{solid_names[b]}",
                        (a, b),
                        tuple(int(faces[k]) for k in shared if face_solids[k] == (a, b)),
                    )
                    for a, b in pairs
                ],
                frozenset(int(faces[k]) for k in shared),
                solid_volumes,
            ),
        )
    return geometry, features


@dataclass
class _CadFaces:
    """The CAD model's faces and edges, from which the solid of a subset of faces is built."""

    source: str
    model: CadModel
    faces: np.ndarray
    surfaces: list
    face_names: list
    face_solids: list  # per face, the indices of the solids it bounds
    edges: np.ndarray
    feature_angle: float
    edge_names: list = dataclasses.field(default_factory=list)
    edge_faces: list = dataclasses.field(default_factory=list)

    def _halved(self, geometry: Geometry, face: np.ndarray, group: np.ndarray) -> np.ndarray:
        """``group`` (per triangle, 1-based) with each group that is one CAD face periodic both ways (a whole
        torus) halved across its first parameter, the second half a new group: each half goes round one way
        only, so that its own parameters chart it (:class:`FaceChart`)."""
        out = group.copy()
        for g in range(1, group.max() + 1):
            rows = np.flatnonzero(group == g)
            tag = self._curved_face(face[rows])
            if tag is None:
                continue
            with self.model.current() as gm:
                parametrized = self.model.parametrized(gm, 2, tag)
                if not parametrized.periodic.all():
                    continue
                u = parametrized.parameters(gm, geometry.mesh.triangles_center[rows])[:, 0]
            low, period = parametrized.low[0], parametrized.period[0]
            out[rows[np.mod(u - low, period) >= period / 2]] = out.max() + 1
        return out

    def _curved_face(self, face: np.ndarray) -> int | None:
        """The CAD tag of the one face that triangles of ``face`` (indices of self.faces) all lie on when it is
        neither a plane nor a cylinder (those have exact charts of their own), else None."""
        members = np.unique(face)
        if len(members) != 1 or self.surfaces[members[0]].form in ("Plane", "Cylinder"):
            return None
        return int(self.faces[members[0]])

    def _chart(self, geometry: Geometry, face: np.ndarray, triangles: np.ndarray) -> FaceChart | None:
        """The :class:`FaceChart` of the ``triangles`` (mask over ``geometry``'s, ``face`` per triangle) when they
        lie on one curved CAD face (:meth:`_curved_face`), else None."""
        tag = self._curved_face(face[triangles])
        if tag is None:
            return None
        mesh = geometry.mesh
        used, local = np.unique(mesh.faces[triangles], return_inverse=True)
        return FaceChart.of(self.model, tag, mesh.vertices[used], local.reshape(-1, 3), mesh.face_normals[triangles])

    @staticmethod
    def kept(vertices, triangles, face, keep) -> np.ndarray:
        """The face index of each triangle on a ``keep`` face."""
        return face[keep[face]]

    def solid(self, vertices, triangles, face, keep, allow_multiple_solids):
        """(Geometry, Features, CAD face tags per patch, CAD edge tags per curve) of the surface made of the
        faces marked ``keep`` (per face)."""
        source, model, faces, edges = self.source, self.model, self.faces, self.edges
        triangles, face = triangles[keep[face]], face[keep[face]]
        used = np.unique(triangles)
        vertices, triangles = vertices[used], np.searchsorted(used, triangles)
        geometry = validate_surface(
            vertices, _oriented(vertices, triangles, face), source, allow_multiple_solids=allow_multiple_solids
        )
        if len(geometry.faces) != len(face):
            raise GeometryError(
                "the CAD faces' tessellation has degenerate triangles",
                where=source,
                fix="heal the model in the CAD tool",
            )
        edge_faces = [[k for k in pair if keep[k]] for pair in self.edge_faces]
        strips = _tangent_strips(geometry, face, self.face_solids, self.feature_angle)
        group = _groups(self.surfaces, edge_faces, geometry.scale, self.face_solids, strips)
        group = np.unique(group[face], return_inverse=True)[1] + 1  # per triangle, numbered among the kept faces
        group = self._halved(geometry, face, group)
        area = np.bincount(face, geometry.mesh.area_faces, minlength=len(faces))
        order = np.lexsort((area[face], group))  # by group, then by the area of the triangle's face
        main = face[order[np.flatnonzero(np.diff(group[order], append=group.max() + 1))]]  # per group, its largest face
        charts = [self._chart(geometry, face, group == g) for g in range(1, group.max() + 1)]
        features = detect_features(  # a cylinder's faces, whose facets may fit none (B-spline, short), stay whole
            geometry,
            self.feature_angle,
            [lambda _, g=g: group == g for g in range(1, group.max() + 1)],
            [self.surfaces[k].form == "Cylinder" or c is not None for k, c in zip(main, charts)],
            tori=False,
        )
        patch_main = [int(main[group[p.faces[0]] - 1]) for p in features.patches]
        patch_faces = [np.unique(face[group == group[p.faces[0]]]) for p in features.patches]
        patch_charts = tuple(
            charts[group[p.faces[0]] - 1] if len(p.faces) == (group == group[p.faces[0]]).sum() else None
            for p in features.patches
        )
        patches = [
            _face_kinds(
                dataclasses.replace(patch, names=[self.face_names[k] for k in members], surface=self.surfaces[k].label),
                self.surfaces[k],
                geometry,
                np.flatnonzero(group == group[patch.faces[0]]),
            )
            for patch, members, k in zip(features.patches, patch_faces, patch_main)
        ]
        curve_edges = _curve_edges(features, geometry, face, edge_faces, model, edges)
        curves = [
            dataclasses.replace(curve, names=[self.edge_names[k] for k in members])
            for curve, members in zip(features.curves, curve_edges)
        ]
        exact_patches = [  # a strip's group: the closest point on its faces, not its largest face's surface
            (None if np.isin(m, strips).any() else self.surfaces[k].exact)
            or CadEntity(model, 2, tuple(faces[m].tolist()))
            for m, k in zip(patch_faces, patch_main)
        ]
        exact_curves = [
            CadEntity(model, 1, tuple(edges[m].tolist()))
            if len(m)
            else CadEntity(model, 2, tuple(faces[np.unique(face[_beside(geometry, curve)])].tolist()))
            for curve, m in zip(features.curves, curve_edges)
        ]
        features = dataclasses.replace(
            features, patches=patches, curves=curves, exact=(exact_patches, exact_curves), charts=patch_charts
        )
        return (
            geometry,
            features,
            [tuple(faces[m].tolist()) for m in patch_faces],
            [tuple(edges[m].tolist()) for m in curve_edges],
        )


def _build(path: str) -> None:
    """Import ``path`` into the current Gmsh model: millimetres, healed when it holds no solid, solids fragmented."""
    import gmsh

    occ = gmsh.model.occ
    previous = gmsh.option.getString("Geometry.OCCTargetUnit")
    # STEP: millimetres asked for; IGES: OpenCASCADE's default, millimetres (its reader refuses the option)
    gmsh.option.setString("Geometry.OCCTargetUnit", "MM" if Path(path).suffix.lower() in (".step", ".stp") else "")
    try:
        shapes = occ.importShapes(path)
    except Exception as exc:  # Gmsh raises a bare Exception with its last error
        raise GeometryError(
            f"not a readable CAD file ({exc})",
            where=path,
            fix="check that the file is a valid STEP, IGES or BREP model",
        ) from None
    finally:
        gmsh.option.setString("Geometry.OCCTargetUnit", previous)
    occ.synchronize()
    lo, hi = np.reshape(gmsh.model.getBoundingBox(-1, -1), (2, 3))
    size = float(np.linalg.norm(hi - lo))
    if not any(dim == 3 for dim, _ in shapes):  # all entities: given the imported faces, OpenCASCADE makes no solid
        occ.healShapes(tolerance=HEAL_TOLERANCE * size)
    elif (narrowest := _narrowest_face(gmsh)) < SLIVER * size:
        # a zero-width face along an edge (an exporter's artefact): its two edges are feature curves a few
        # micrometres apart, and OpenCASCADE's tessellation of the solid is not closed there
        faces = len(occ.getEntities(2))
        occ.healShapes(tolerance=SLIVER * size)
        log.info(
            "%s: a face %.2g wide (%.2g of the model size) removed by OpenCASCADE's healing: %d faces -> %d",
            path,
            narrowest,
            narrowest / size,
            faces,
            len(occ.getEntities(2)),
        )
    solids = occ.getEntities(3)
    if len(solids) > 1:
        occ.synchronize()  # the model takes the file's names now: a fragment before that blanks some of them
        occ.fragment(solids, [])
    occ.synchronize()


def _narrowest_face(gmsh) -> float:
    """The smallest mean width (area over half the perimeter) of the current model's faces; inf for none."""
    occ = gmsh.model.occ
    widths = [np.inf]
    for _, face in occ.getEntities(2):
        edges = {abs(tag) for _, tag in gmsh.model.getBoundary([(2, face)], combined=False, oriented=False)}
        perimeter = sum(occ.getMass(1, edge) for edge in edges)
        if perimeter > 0:
            widths.append(2 * occ.getMass(2, face) / perimeter)
    return float(min(widths))


def _solid_name(name: str) -> str:
    """A solid's name from the file (its STEP product or entity name, a Gmsh physical name), '' for none or for
    the product name OpenCASCADE's STEP writer gives every solid; spaces as dashes."""
    label = _label(name)
    return "" if label.startswith(UNNAMED_PRODUCT) else re.sub(r"\s+", "-", label)


def _numbered(names: list[str]) -> list[str]:
    """``names`` with each name that repeats numbered in file order (``nut-1``, ``nut-2``), so that every body's
    group and interface name is its own (an assembly's STEP file names every instance of a part alike)."""
    counts = {name: names.count(name) for name in names}
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(f"{name}-{seen[name]}" if counts[name] > 1 else name)
    return out


def _label(name: str) -> str:
    """The last part of a Gmsh entity name (``Shapes/Part/hole-wall`` -> ``hole-wall``), '' for none."""
    return name.rsplit("/", 1)[-1].strip()


@dataclass(frozen=True)
class Surface:
    """A CAD face's type (Gmsh's name: Plane, Cylinder, Cone, Sphere, Torus, BSpline surface, ...), its
    parameters (``gmsh.model.getEntityProperties``, or for a non-analytic face the same parameters of the
    analytic surface it lies on) and its analytic exact surface, if it has one. ``shape``: the analytic type
    (Plane, Cylinder, Cone, Sphere, Torus) of a non-analytic face that lies on one (:func:`_face_surface`)."""

    kind: str
    parameters: np.ndarray
    exact: object | None
    shape: str | None = None
    fitted: object | None = None  # the analytic surface a non-analytic face's points fit
    blend: float | None = None  # a non-analytic face's one steady principal radius (a rolling ball blend's)

    @property
    def label(self) -> str:
        """The face's type for a user: its own, and the analytic type it lies on when that differs ('Unknown on
        Cylinder': a face of a type Gmsh does not name whose points fit a cylinder)."""
        return f"{self.kind} on {self.shape}" if self.shape and self.shape != self.kind else self.kind

    @property
    def form(self) -> str:
        """The analytic type the face is (its own type, or the one its points fit), else its own type."""
        return self.shape or self.kind

    @property
    def analytic(self):
        """The face's analytic surface (its own, or the one its points fit), or None."""
        return self.fitted if self.fitted is not None else self.exact


def _surface(kind: str, parameters) -> Surface:
    p = np.asarray(parameters, dtype=float)
    exact = None
    if kind == "Plane" and len(p) == 4:
        normal = p[:3] / np.linalg.norm(p[:3])
        exact = Plane(-p[3] * normal / np.linalg.norm(p[:3]), normal)
    elif kind == "Cylinder" and len(p) == 7:
        exact = CylinderSurface(p[:3], unit(p[3:6]), p[6])
    elif kind == "Cone" and len(p) == 8:  # OCC: radius p[6] at p[:3], growing along the axis by semi-angle p[7]
        axis = unit(p[3:6]) * np.sign(p[7])
        exact = Cone(p[:3] - axis * p[6] / np.tan(abs(p[7])), axis, abs(float(p[7])))
    elif kind == "Sphere" and len(p) == 4:
        exact = Sphere(p[:3], p[3])
    elif kind == "Torus" and len(p) == 8:
        exact = Torus(p[:3], unit(p[3:6]), p[6], p[7])
    return Surface(kind, p, exact)


def _face_surface(gm, tag: int, size: float) -> Surface:
    """The Surface of CAD face ``tag`` (``size``: the model's). A face of another type (B-spline, Bezier,
    surface of revolution or extrusion, offset: exporters write many cylinders and fillets so) whose own
    points, on a FIT_POINTS x FIT_POINTS grid of its parameters, lie within FIT_TOLERANCE x ``size`` of a
    plane, sphere, cylinder, cone or torus (:func:`engine.exact.fit_analytic`) is that surface for its kinds,
    radius and patch grouping, and its exact surface where they lie within EXACT_TOLERANCE x ``size`` (as
    near as an STL's vertices, engine/exact.py), else the CAD face itself. One that fits none but whose
    smaller principal radius stays within BLEND_SPREAD of one value is a rolling ball's blend of that
    radius (a fillet along a curve that is not a circle, as where two pipes meet)."""
    kind = gm.getType(2, tag)
    surface = _surface(kind, gm.getEntityProperties(2, tag)[1])
    if kind in ANALYTIC:
        return surface
    try:
        (u0, v0), (u1, v1) = gm.getParametrizationBounds(2, tag)
        u, v = np.meshgrid(np.linspace(u0, u1, FIT_POINTS), np.linspace(v0, v1, FIT_POINTS))
        uv = np.column_stack([u.ravel(), v.ravel()]).ravel()
        points = np.reshape(gm.getValue(2, tag, uv), (-1, 3))
        normals = np.reshape(gm.getNormal(tag, uv), (-1, 3))
        curvatures = np.abs(gm.getPrincipalCurvatures(tag, uv)[:2])
    except Exception:  # Gmsh raises a bare Exception: a face it cannot evaluate keeps its own type
        return surface
    good = np.isfinite(points).all(axis=1) & (np.abs(np.linalg.norm(normals, axis=1) - 1) < 1e-6)
    radii = [1 / np.median(k[good]) for k in curvatures if np.median(k[good]) > 0]
    fitted = fit_analytic(points[good], normals[good], FIT_TOLERANCE * size, radii)
    if fitted is None:
        ball = 1 / curvatures[:, good].max(axis=0)  # the smaller principal radius at each point
        steady = len(ball) and np.isfinite(ball).all() and np.ptp(ball) <= BLEND_SPREAD * np.median(ball)
        return dataclasses.replace(surface, blend=float(np.median(ball))) if steady else surface
    shape, parameters = _parameters(fitted)
    off = float(np.linalg.norm(fitted.project(points[good]) - points[good], axis=1).max())
    return Surface(kind, parameters, fitted if off <= EXACT_TOLERANCE * size else None, shape, fitted)


def _parameters(surface) -> tuple[str, np.ndarray]:
    """An analytic surface's type and parameters as Gmsh gives an analytic CAD face's (see :func:`_surface`)."""
    if isinstance(surface, Plane):
        return "Plane", np.r_[surface.normal, -surface.normal @ surface.point]
    if isinstance(surface, CylinderSurface):
        return "Cylinder", np.r_[surface.point, surface.axis, surface.radius]
    if isinstance(surface, Cone):
        point = surface.apex + surface.axis  # unit distance along the axis from the apex
        return "Cone", np.r_[point, surface.axis, np.tan(surface.angle), surface.angle]
    if isinstance(surface, Sphere):
        return "Sphere", np.r_[surface.centre, surface.radius]
    return "Torus", np.r_[surface.centre, surface.axis, surface.major, surface.minor]


@contextmanager
def _options(numbers: dict):
    import gmsh

    saved = {key: gmsh.option.getNumber(key) for key in numbers}
    for key, value in numbers.items():
        gmsh.option.setNumber(key, value)
    try:
        yield
    finally:
        for key, value in saved.items():
            gmsh.option.setNumber(key, value)


def _chord(geometry: Geometry, features: Features) -> tuple[float, float]:
    """How far the tessellation strays from the CAD faces: the largest distance of the centroids of its
    CHORD_SAMPLES longest facets from their patches' exact surfaces, and at least DEFLECTION x the model size,
    what BRepMesh is asked for (a spring's swept B-spline face strays 1.6x that, and a mesh on the CAD face was
    refused for lying 0.28 h from the facets); and the volume its chords leave out, from the same facets (area
    x signed distance to the faces, scaled to the whole area: an over-estimate, the longest facets stray most)."""
    mesh = geometry.mesh
    corners = mesh.triangles
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    sample = np.argsort(-longest, kind="stable")[:CHORD_SAMPLES]
    centres, patch = mesh.triangles_center[sample], features.face_patch[sample]
    deviation, missing = [], 0.0
    for p in np.unique(patch):
        if (surface := features.exact[0][p]) is not None:
            at = np.flatnonzero(patch == p)
            off = surface.project(centres[at]) - centres[at]
            deviation.append(float(np.linalg.norm(off, axis=1).max()))
            outward = np.einsum("ij,ij->i", off, mesh.face_normals[sample[at]])
            missing += float(outward @ mesh.area_faces[sample[at]])
    missing *= mesh.area / mesh.area_faces[sample].sum()
    return max([DEFLECTION * geometry.scale, *deviation]), missing


def _trusted(volumes: list[float], geometry: Geometry, missing: float, source: str) -> list[float]:
    """OpenCASCADE's ``volumes`` of the solids, or none where their sum is off the tessellation's volume by more
    than MASS_TRUST x it plus twice what the chords leave out (``missing``): a lofted blade's was 1.5 % low,
    while every tessellation and mesh of it agreed to 0.03 %."""
    error = sum(volumes) - geometry.volume
    if abs(error - missing) <= abs(missing) + MASS_TRUST * geometry.volume:
        return volumes
    log.warning(
        "%s: OpenCASCADE's volume of the %s, %.6g, is %+.2f %% off its faces' tessellation's (whose chords "
        "explain %+.3f %%): not reported as the exact volume; check the solid in the CAD tool",
        source,
        "solid" if len(volumes) == 1 else f"{len(volumes)} solids",
        sum(volumes),
        100 * error / geometry.volume,
        100 * missing / geometry.volume,
    )
    return []


def _tessellate(gm, mesher: bool = False, turn: float = TURN_ANGLE):
    """The CAD faces as triangles: (vertices (n, 3), triangles (t, 3), CAD face tag per triangle (t,)), each
    face's triangles as the tessellator orients it, degenerate ones left out, faces sharing their edges' points.
    OpenCASCADE's tessellation (BRepMesh, as Gmsh exports STL: ``turn`` degrees, sagitta at most DEFLECTION x
    the model size; made once per model, so another turn needs a fresh model), whose strips along cylinders
    and cones the feature detection recognises; or, with ``mesher``, Gmsh's 2-D mesh (as many elements per
    turn, sides of at most the model size / MESHER_SIZE)."""
    import gmsh

    lo, hi = np.reshape(gm.getBoundingBox(-1, -1), (2, 3))
    diagonal = float(np.linalg.norm(hi - lo))
    if mesher:
        with _options(
            {
                "Mesh.MeshSizeFromCurvature": 360 / TURN_ANGLE,
                "Mesh.MeshSizeMax": diagonal / MESHER_SIZE,
                "Mesh.MeshSizeMin": 0,
                "Mesh.Algorithm": 6,
            }
        ):
            gm.mesh.clear()
            gm.mesh.generate(2)
        tags, xyz, _ = gm.mesh.getNodes()
        xyz = xyz.reshape(-1, 3)[np.argsort(tags)]
        blocks = [(tag, gm.mesh.getElements(2, tag)) for _, tag in gm.getEntities(2)]
        blocks = [
            (tag, xyz[np.searchsorted(np.sort(tags), nodes[list(types).index(2)].reshape(-1, 3))])
            for tag, (types, _, nodes) in blocks
        ]
        gm.mesh.clear()
    else:
        for name in {gm.getEntityName(2, tag) for _, tag in gm.getEntities(2)} - {""}:
            gm.removeEntityName(name)  # the STL names each face's solid by its name, if any, else by its tag
        with (
            tempfile.TemporaryDirectory() as folder,
            _options(
                {
                    "Mesh.Binary": 0,
                    "Mesh.StlOneSolidPerSurface": 1,
                    "Mesh.StlLinearDeflectionRelative": 0,
                    "Mesh.StlLinearDeflection": DEFLECTION * diagonal,
                    "Mesh.StlAngularDeflection": np.radians(turn),
                }
            ),
        ):
            gm.mesh.clear()
            gmsh.write(str(Path(folder) / "faces.stl"))
            text = (Path(folder) / "faces.stl").read_text()
        blocks = [
            (int(tag), np.array(re.findall(r"vertex\s+(\S+)\s+(\S+)\s+(\S+)", body), float).reshape(-1, 3, 3))
            for tag, body in re.findall(r"solid Gmsh Surface (\d+)(.*?)endsolid", text, re.S)
        ]
    face_tag = np.repeat([tag for tag, _ in blocks], [len(c) for _, c in blocks])
    corners = np.concatenate([c for _, c in blocks])
    vertices, index = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    triangles = index.reshape(-1, 3)
    double_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    kept = double_area > 2e-12 * diagonal * longest  # validate_surface's test: height above 1e-12 x size
    return vertices, triangles[kept], face_tag[kept]


def _refuse_folds(vertices: np.ndarray, triangles: np.ndarray, face_tag: np.ndarray, angle: float, source: str):
    """A GeometryError where two triangles of one CAD face meet at more than ``angle`` degrees: a smooth face's
    tessellation turns by about TURN_ANGLE between neighbours, so such an edge is a fold of the tessellator's
    (BRepMesh folds the corner of a B-spline fillet under a B-spline face), a feature curve the CAD has not."""
    mesh = trimesh.Trimesh(vertices, triangles, process=False)
    pairs = mesh.face_adjacency
    folded = (face_tag[pairs[:, 0]] == face_tag[pairs[:, 1]]) & (mesh.face_adjacency_angles > np.radians(angle))
    if folded.any():
        where = mesh.vertices[mesh.face_adjacency_edges[folded][0]].mean(axis=0)
        raise GeometryError(
            f"{int(folded.sum())} edges inside CAD faces turn by more than {angle:g} degrees, the first inside "
            f"face-{int(face_tag[pairs[folded][0, 0]])} at ({', '.join(f'{x:.4g}' for x in where)})",
            where=source,
        )


def _oriented(vertices: np.ndarray, triangles: np.ndarray, face: np.ndarray) -> np.ndarray:
    """``triangles`` with whole CAD faces (``face``: per triangle) reversed so that neighbours walk their shared
    edges in opposite directions (Gmsh meshes each face along its own parametrisation) and every connected
    shell encloses a positive volume (so that validate_surface, which would do the same triangle by triangle,
    has nothing to turn and warns of nothing); as they are where the surface is not closed, which
    validate_surface refuses."""
    n = int(face.max()) + 1
    directed = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(directed, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    if len(order) % 2 or (key[order[0::2]] != key[order[1::2]]).any():
        return triangles  # not closed: validate_surface says where
    first, second = order[0::2], order[1::2]
    a, b = np.repeat(face, 3)[first], np.repeat(face, 3)[second]
    flip_pair = directed[first, 0] == directed[second, 0]  # walked the same way: one of the two flips
    rows = np.unique(np.column_stack([a, b, flip_pair])[a != b], axis=0)
    graph = sparse.coo_matrix((rows[:, 2] + 1, (rows[:, 0], rows[:, 1])), shape=(n, n)).tocsr()
    graph = graph.maximum(graph.T)  # weight 1: same way round, 2: opposite
    shells = csgraph.connected_components(graph, directed=False)[1]
    flip = np.zeros(n, bool)
    for root in np.unique(shells, return_index=True)[1]:
        nodes, parents = csgraph.breadth_first_order(graph, root, directed=False)
        for node in nodes[1:]:  # parents come first in breadth-first order
            flip[node] = flip[parents[node]] ^ (graph[parents[node], node] == 2)
    out = np.where(flip[face][:, None], triangles[:, ::-1], triangles)
    corners = vertices[out]
    volume = np.bincount(
        shells[face],
        np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])),
        minlength=shells.max() + 1,
    )
    return np.where((volume[shells[face]] < 0)[:, None], out[:, ::-1], out)


def _groups(surfaces: list, edge_faces: list, scale: float, face_solids: list, joined: np.ndarray) -> np.ndarray:
    """Per CAD face, its patch group (1-based): faces joined by an edge (``edge_faces``: the face indices of
    each edge) that lie on one cylinder, cone, sphere or torus and bound the same solids (``face_solids``: so
    that a face two solids share is a patch of its own) share one; faces that fit one (:func:`_face_surface`)
    within FIT_TOLERANCE x ``scale``. So do the face pairs ``joined`` (k, 2) (:func:`_tangent_strips`)."""
    pairs = np.array([pair for pair in edge_faces if len(pair) == 2], np.int64).reshape(-1, 2)
    same = [
        face_solids[i] == face_solids[j]
        and surfaces[i].form == surfaces[j].form
        and surfaces[i].form in ("Cylinder", "Cone", "Sphere", "Torus")
        and np.allclose(
            _canonical(surfaces[i]),
            _canonical(surfaces[j]),
            atol=(FIT_TOLERANCE if surfaces[i].shape or surfaces[j].shape else SAME_SURFACE) * scale,
        )
        for i, j in pairs
    ]
    pairs = np.vstack([pairs[np.asarray(same, bool)] if len(pairs) else pairs, joined])
    graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(surfaces),) * 2)
    labels = csgraph.connected_components(graph, directed=False)[1]
    return np.unique(labels, return_inverse=True)[1] + 1


def _tangent_strips(geometry: Geometry, face: np.ndarray, face_solids: list, feature_angle: float) -> np.ndarray:
    """(k, 2) CAD face indices (strip, neighbour): each face narrower on average (twice its area over its
    perimeter, on the tessellation ``face``: per triangle) than NARROW_REGION x the model size (as a coplanar
    region of an STL's chart must be wider, engine/features.py), whose normals
    turn less than ``feature_angle`` (degrees) over it, with the neighbour of the same solids it meets most
    smoothly where that is under ``feature_angle`` all along their edge, a wider one before another strip (two
    strips side by side, each the other's smoothest, stayed a strip). An exporter's strip 0.14 mm wide
    between a gear's flank and its root, tangent to both, is otherwise a patch of its own, its two edges curves
    0.14 mm apart that the narrow-face rule sizes for (30x the elements); from an STL it is part of a
    neighbour's patch, as now. A fillet or round turns more than the feature angle and stays a patch."""
    mesh = geometry.mesh
    count = len(face_solids)
    sides = face[mesh.face_adjacency]
    across = sides[:, 0] != sides[:, 1]
    sides, angle = sides[across], mesh.face_adjacency_angles[across]
    ends = mesh.vertices[mesh.face_adjacency_edges[across]]
    perimeter = np.bincount(sides.ravel(), np.repeat(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), 2), count)
    area = np.bincount(face, mesh.area_faces, count)
    width = np.divide(2 * area, perimeter, out=np.full(count, np.inf), where=perimeter > 0)
    mean = np.zeros((count, 3))
    np.add.at(mean, face, mesh.face_normals * mesh.area_faces[:, None])
    spread = np.arccos(np.clip(np.einsum("ij,ij->i", mesh.face_normals, unit(mean)[face]), -1.0, 1.0))
    turn = np.zeros(count)
    np.maximum.at(turn, face, 2 * spread)  # at most twice the largest angle from the mean normal
    limit = np.radians(feature_angle)
    strip = (width < NARROW_REGION * geometry.scale) & (turn < limit)
    owners = {}
    solids = np.array([owners.setdefault(s, len(owners)) for s in face_solids])
    one, other = np.concatenate([sides, sides[:, ::-1]]).T
    angle = np.concatenate([angle, angle])
    mine = strip[one] & (solids[one] == solids[other])
    pair, at = np.unique(one[mine] * count + other[mine], return_inverse=True)
    worst = np.zeros(len(pair))
    np.maximum.at(worst, at, angle[mine])  # the sharpest turn along the pair's edges
    pair, worst = pair[worst < limit], worst[worst < limit]
    best = np.lexsort((worst, strip[pair % count], pair // count))  # per strip, its smoothest wider neighbour first
    best = best[np.unique(pair[best] // count, return_index=True)[1]]
    return np.column_stack([pair[best] // count, pair[best] % count])


def _canonical(surface: Surface) -> np.ndarray:
    """Parameters of a surface of revolution with its axis pointing one way and its centre moved to the axis
    point nearest the origin (two faces of one cylinder may carry different centres along it)."""
    p = surface.parameters.copy()
    if surface.form in ("Cylinder", "Cone", "Torus"):
        axis = unit(p[3:6])
        axis = axis if axis[np.argmax(np.abs(axis))] > 0 else -axis
        if surface.form == "Cylinder":
            p[:3] -= (p[:3] @ axis) * axis
        p[3:6] = axis
    return p


def _face_kinds(patch, surface: Surface, geometry: Geometry, group: np.ndarray):
    """The patch with its CAD-given shape (the face's own or, for a non-analytic face, the analytic surface its
    points fit): a cylinder's exact axis and radius (concave and sweep as its facets show, where they did not
    fit one and the patch is the whole face, not a piece of a chart cut), a concave torus's fillet or hole kind
    (by the turn round the tube of the whole face) and tube circle, a rolling ball blend's fillet kind and
    circle, a narrow cone's chamfer or countersink kind. ``group``: the triangles of the faces the patch is of.
    A piece of a face of another type keeps no cylinder its facets fit (a lofted blade's scraps of 0.01 mm2 were
    'fillet's of radius 1.7 to 3.5)."""
    exact = surface.analytic
    normals = geometry.mesh.face_normals[patch.faces]
    centres = geometry.mesh.triangles_center[patch.faces]
    if surface.form != "Cylinder" and patch.cylinder is not None and len(patch.faces) < len(group):
        patch = dataclasses.replace(patch, cylinder=None)
    if surface.form == "Cylinder" and (patch.cylinder is not None or len(patch.faces) == len(group)):
        cylinder = patch.cylinder or _cylinder(exact, centres, normals, patch.vertices)
        axis = exact.axis if exact.axis @ cylinder.axis > 0 else -exact.axis  # the fit's sign convention
        cylinder = dataclasses.replace(cylinder, point=exact.point, axis=axis, radius=float(exact.radius))
        return dataclasses.replace(patch, cylinder=cylinder)
    if surface.form == "Torus":
        tube = exact.tube_centre(centres)
        concave = np.mean(np.einsum("ij,ij->i", centres - tube, normals)) < 0
        face_points = geometry.mesh.vertices[np.unique(geometry.mesh.faces[group])]
        kind = (torus_kind(tube_sweep(exact, face_points)),)
        return dataclasses.replace(
            patch,
            kinds=[*patch.kinds, *kind] if concave else patch.kinds,
            circle=Circle(exact.centre, exact.axis, float(exact.minor)),
        )
    if surface.blend is not None:
        mesh = geometry.mesh
        inside = np.isin(mesh.face_adjacency, patch.faces).all(axis=1)
        turn = mesh.face_adjacency_angles[inside]
        if turn[~mesh.face_adjacency_convex[inside]].sum() > turn[mesh.face_adjacency_convex[inside]].sum():
            # a concave blend: a fillet; its tube radius is the ball's (it has no one axis: the patch's normal)
            circle = Circle(patch.centroid, patch.normal, surface.blend)
            return dataclasses.replace(patch, kinds=[*patch.kinds, "fillet"], circle=circle)
        return patch
    if surface.form == "Cone":
        rel = centres - exact.apex
        radial = rel - np.outer(rel @ exact.axis, exact.axis)
        radius = np.linalg.norm(radial, axis=1)
        if np.ptp(np.linalg.norm(rel, axis=1)) < NARROW * radius.mean():  # its width along the generators
            concave = np.mean(np.einsum("ij,ij->i", radial, normals)) < 0
            return dataclasses.replace(patch, kinds=[*patch.kinds, "countersink" if concave else "chamfer"])
    return patch


def _cylinder(exact: CylinderSurface, centres: np.ndarray, normals: np.ndarray, vertices: np.ndarray) -> Cylinder:
    """The patch cylinder of triangles (``centres``, ``normals``, their ``vertices``) on ``exact``, concave when
    their normals point to its axis, its sweep the turn their centres and vertices cover (as
    :func:`engine.fitting.fit_cylinder` tells from the facets)."""
    axis = exact.axis if exact.axis[np.argmax(np.abs(exact.axis))] > 0 else -exact.axis

    def radial(points):
        rel = points - exact.point
        return rel - np.outer(rel @ axis, axis)

    concave = bool(np.mean(np.einsum("ij,ij->i", radial(centres), normals)) < 0)
    turn = sweep(np.vstack([radial(centres), radial(vertices)]), axis)
    return Cylinder(exact.point, axis, float(exact.radius), concave, turn)


def _curve_edges(
    features: Features, geometry: Geometry, face: np.ndarray, edge_faces: list, model: CadModel, edges: np.ndarray
) -> list[np.ndarray]:
    """Per curve, the indices into ``edges`` of the CAD edges it runs along: each chord goes to the nearest of
    the edges between the CAD faces on its two sides (``face``: per triangle, ``edge_faces``: per edge);
    empty for a curve inside one CAD face (a chart's cut)."""
    mesh = geometry.mesh
    n = len(mesh.vertices)
    shared = np.sort(mesh.face_adjacency_edges, axis=1)
    keys = shared[:, 0] * n + shared[:, 1]
    order = np.argsort(keys)
    between = {}
    for k, pair in enumerate(edge_faces):
        between.setdefault(frozenset(pair), []).append(k)
    out = []
    for curve in features.curves:
        if curve.vertices is None:
            out.append(np.zeros(0, np.int64))
            continue
        ends = np.column_stack([curve.vertices, np.roll(curve.vertices, -1)])
        ends = np.sort(ends if curve.closed else ends[:-1], axis=1)
        at = order[np.clip(np.searchsorted(keys, ends[:, 0] * n + ends[:, 1], sorter=order), 0, len(keys) - 1)]
        sides = face[mesh.face_adjacency[at]]  # (chords, 2) CAD face indices
        chosen = []
        for pair in np.unique(np.sort(sides, axis=1), axis=0):
            candidates = between.get(frozenset(pair.tolist()), []) if pair[0] != pair[1] else []
            if not candidates:
                continue
            mine = (np.sort(sides, axis=1) == pair).all(axis=1)
            middles = mesh.vertices[ends[mine]].mean(axis=1)
            distance = np.stack(
                [np.linalg.norm(model.closest(1, (int(edges[k]),), middles) - middles, axis=1) for k in candidates]
            )
            chosen += [candidates[k] for k in np.unique(np.argmin(distance, axis=0))]
        out.append(np.unique(np.asarray(chosen, np.int64)))
    return out


def _beside(geometry: Geometry, curve) -> np.ndarray:
    """The triangles at a curve's middle point."""
    return geometry.closest_point(curve.points[len(curve.points) // 2][None])[2]
