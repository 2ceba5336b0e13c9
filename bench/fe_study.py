"""Issue 15 item 4: does the shipped recipe beat a plain Gmsh distance field at equal node counts?

Extends the plate-hole convergence study (engine/validation/study.py, bench/fe_convergence.md) to
several geometries and three series, all solved by the same solver (engine/validation/elasticity.py:
isoparametric 10-node tets in scikit-fem, CG + smoothed-aggregation AMG, averaged nodal stresses):

* ``recipe``  - fuzzymesh, the static-stress recipe as shipped (base pattern + hole pattern + the
  always-placed thin-wall / curvature rules), every target size times a scale s.
* ``uniform`` - fuzzymesh, the base pattern alone at s x the default size H (model diagonal / 40),
  without the always-placed rules (engine/validation/study-sizing.yaml), as the existing study.
* ``gmsh``    - Gmsh 4 (OpenCASCADE geometry, order 2, high-order nodes on the exact surfaces) with a
  Distance field on the same feature (the hole wall; the bracket's fillet; the sphere's inner surface) and
  a Threshold field: SizeMin = the recipe's near size, SizeMax = the recipe's far size (capped at H),
  growing linearly over the same extent (DistMin 0, DistMax = extent); every size times s. The sphere has
  no recipe pattern: its field goes from 0.5 H at the inner surface to H over half the wall.

Every series goes through one code path: (points, 10-node tets) -> :class:`FEModel` (boundary
facets and boundary conditions found geometrically, the same for every mesher) -> stiffness, solve,
nodal stress (engine.validation.elasticity). The fuzzymesh 10-node meshes are exactly what
``fuzzymesh mesh`` writes (engine.fe.quadratic: nodes on the exact surfaces).

Quantities: plates - the through-thickness mean of sigma_xx at the hole root(s) (both roots for a
central hole, divided by the net-section nominal stress: Peterson's Kt_n; the root next to the plate
edge for the edge hole, divided by the applied traction); the filleted L-bracket (end of its base leg
clamped, a shear traction on the top of its upright that opens the inner corner) - the peak over the
fillet's arc of the across-the-width mean of the stress along the arc, divided by the upright's nominal
bending stress at the base leg's top face; sphere - the hoop stress at r = a, mean of the inner nodes and
worst node, against Lame.  References: a very fine Gmsh distance-field run of each plate and of the
bracket, computed once (``--reference``) and stored in bench/fe_reference.json (next to Peterson's value
for a plate); Lame for the sphere.

    python bench/fe_study.py --reference --reference-scale 0.6     # the fine runs (once)
    python bench/fe_study.py --seeds 0 1 --scales "recipe=6,5,4,3,2,1.5;uniform=3,2,1.5,1;gmsh=6,5,4,3,2,1.5" \
        --cases ...                                  # appends every mesh to bench/fe_study_rows.jsonl
    python bench/fe_study.py --cases --out bench/fe_study --tag A B   # tables of the tags' rows -> .json / .md
    python bench/fe_study.py --series recipe --extent 2 --tag extent-2 ...   # a variant of the hole pattern

A mesh is counted as reaching a target from the node count where the |error| of every seed stays within
it (the mean over the seeds is tabulated too); meshes refused by fuzzymesh's acceptance gate are
counted and left out of their series.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine.fe import SIDE_NODES, TET10_EDGES, quadratic  # noqa: E402
from engine.job import job_from_dict  # noqa: E402
from engine.pipeline import SIZE_FROM_SCALE  # noqa: E402
from engine.pipeline import run as mesh_job  # noqa: E402
from engine.validation.elasticity import Material, nodal_stress, solve, stiffness  # noqa: E402
from engine.validation.plate_hole import STUDY_SIZING, p2_triangle_values, peterson_kt  # noqa: E402
from engine.validation.sphere import lame  # noqa: E402

MATERIAL = Material(E=200e3, nu=0.3)
TENSION = 100.0
PRESSURE = 100.0
SAMPLES = 101  # heights along a root line for the through-thickness mean (widths across the bracket's fillet)
UNSOLVED = 1e-6  # relative residual above which a solve is a failed data point, not a value
ARC_SAMPLES = 181  # angles round the bracket's fillet where its peak is sought
KNOWLEDGE = ROOT / "knowledge"
PATTERNS = ROOT / "patterns"
RECIPE = "static-stress"
# How the recipe series scales a pattern's parameters by s so that every size it asks for is s times its own:
# sizes multiply, counts ('elements through', 'per circle') divide, a tolerance on h^2 (curvature's
# volume_change) multiplies by s^2; sizes in units of H scale with the job's size.
SCALED = {
    "hole": {"near": 1, "far": 1},
    "fillet": {"near": 1, "far": 1},
    "thin-wall": {"through": -1},
    "narrow-gap": {"across": -1},
    "narrow-face": {"stretch": 1},
    "curvature": {"per_circle": -1, "volume_change": 2},
}


def _yaml(path: Path) -> dict:
    import yaml

    return yaml.safe_load(path.read_text())


def _defaults(pattern: str) -> dict:
    return {k: v["default"] for k, v in _yaml(PATTERNS / f"{pattern}.yaml").get("parameters", {}).items()}


def _sizes(pattern: str) -> dict:
    """A stress-raiser pattern's near / far / extent defaults (times the feature's radius)."""
    return {k: _defaults(pattern)[k] for k in ("near", "far", "extent")}


REFERENCE_FILE = Path(__file__).with_name("fe_reference.json")


@dataclass
class Case:
    name: str
    shape: str
    parameters: dict
    kind: str  # "plate", "bracket" or "sphere"
    roots: tuple = (90.0, -90.0)  # root angles (degrees from +x) for a plate
    nominal: str = "net"  # "net" (Peterson) or "gross"
    note: str = ""
    pattern: str | None = "hole"  # the recipe's pattern on the stress raiser, whose sizes the Gmsh field takes
    sizes: dict = field(default_factory=dict)  # its near / far / extent (times the radius): the YAML's unless set

    def __post_init__(self):
        if self.pattern and not self.sizes:
            self.sizes = _sizes(self.pattern)

    @property
    def radius(self) -> float:
        """The stress raiser's radius, the pattern's length L."""
        return self.parameters["hole_radius" if self.kind == "plate" else "fillet_radius"]

    @property
    def diagonal(self) -> float:
        p = self.parameters
        if self.kind == "sphere":
            return float(np.linalg.norm([p["outer_radius"]] * 3))
        if self.kind == "bracket":
            return float(np.linalg.norm([p["leg_length"], p["leg_height"], p["width"]]))
        return float(np.linalg.norm([p["length"], p["width"], p["thickness"]]))

    @property
    def H(self) -> float:
        return self.diagonal / SIZE_FROM_SCALE


def plate(name, radius, thickness=10.0, width=100.0, hole_y=0.0, **kw) -> Case:
    return Case(
        name,
        "plate_with_hole",
        dict(length=200.0, width=width, thickness=thickness, hole_radius=radius, hole_x=0.0, hole_y=hole_y),
        "plate",
        **kw,
    )


CASES = {
    c.name: c
    for c in [
        plate("hole d/W 0.1, t 10", 5.0, note="central hole, Peterson 2.722"),
        plate("hole d/W 0.3, t 10", 15.0, note="central hole, Peterson 2.349"),
        plate("hole d/W 0.5, t 10", 25.0, note="central hole, Peterson 2.159"),
        plate("hole d/W 0.3, t 30", 15.0, thickness=30.0, note="thick plate (t = 2 r)"),
        plate(
            "edge hole",
            10.0,
            hole_y=30.0,
            roots=(90.0,),
            nominal="gross",
            note="r 10 at y = 30 of W 100: ligament 10 to the edge; root next to the edge, sigma / S",
        ),
        Case(
            "filleted bracket",
            "l_bracket",
            dict(leg_length=80.0, leg_height=80.0, thickness=15.0, width=40.0, fillet_radius=4.0),
            "bracket",
            nominal="bending",
            pattern="fillet",
            note="L-bracket, fillet r 4 (r / t 0.27) in its inner corner, base end clamped, shear on the upright's top",
        ),
        Case(
            "sphere",
            "hollow_sphere_octant",
            dict(inner_radius=50.0, outer_radius=100.0),
            "sphere",
            pattern=None,
            note="Lame, hoop stress at r = a",
        ),
    ]
}


# ----------------------------------------------------------------------------------------------- model
class FEModel:
    """A 10-node tet mesh (VTK edge order) as the duck-typed model engine.validation.elasticity solves."""

    def __init__(self, points: np.ndarray, tets10: np.ndarray, vertices: int):
        from skfem import Basis, ElementTetP2, ElementVector, MeshTet2

        self.points, self.tets10, self.vertices = points, tets10, vertices
        self.mesh = MeshTet2(np.ascontiguousarray(points.T), np.ascontiguousarray(tets10.T))
        self.basis = Basis(self.mesh, ElementVector(ElementTetP2()), intorder=2)
        self.dof = np.zeros(len(points), np.int64)
        self.dof[tets10] = (self.basis.element_dofs[::3] // 3).T
        sides = np.concatenate([tets10[:, SIDE_NODES[k]] for k in range(4)])  # (4m, 6)
        key = np.sort(sides[:, :3], axis=1)
        _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        self.triangles6 = sides[count[inverse.ravel()] == 1]

    def facets(self, test) -> np.ndarray:
        """Boundary facets whose three corners satisfy test(xyz (3, n)) -> bool (n,)."""
        f = self.mesh.boundary_facets()
        corners = self.mesh.p[:, self.mesh.facets[:, f]]  # (3, 3 corners, k)
        ok = np.all([test(corners[:, i]) for i in range(3)], axis=0)
        return f[ok]

    def triangles(self, test) -> np.ndarray:
        xyz = self.points[self.triangles6[:, :3]]  # (t, 3, 3)
        ok = np.all([test(xyz[:, i].T) for i in range(3)], axis=0)
        return self.triangles6[ok]

    def nearest(self, xyz) -> int:
        return int(np.argmin(np.linalg.norm(self.points[: self.vertices] - np.asarray(xyz), axis=1)))

    def dofs(self, nodes, component):
        return 3 * self.dof[np.atleast_1d(nodes)] + component


def _load(model: FEModel, facets: np.ndarray, traction) -> np.ndarray:
    from skfem import FacetBasis, LinearForm, asm

    @LinearForm
    def form(v, w):
        t = traction(w.n)
        return t[0] * v[0] + t[1] * v[1] + t[2] * v[2]

    return asm(form, FacetBasis(model.mesh, model.basis.elem, facets=facets, intorder=2))


def solve_plate(case: Case, model: FEModel) -> dict:
    p = case.parameters
    L, W, t, R = p["length"], p["width"], p["thickness"], p["hole_radius"]
    tol = 1e-6 * L
    K = stiffness(model, MATERIAL)
    ends = model.facets(lambda x: np.abs(np.abs(x[0]) - L / 2) < tol)
    f = _load(model, ends, lambda n: (TENSION * n[0], 0 * n[0], 0 * n[0]))
    a, b, c = (model.nearest((-L / 2, -W / 2, 0)), model.nearest((L / 2, -W / 2, 0)), model.nearest((-L / 2, W / 2, 0)))
    fixed = np.concatenate(
        [model.dofs(a, k) for k in range(3)] + [model.dofs(b, k) for k in (1, 2)] + [model.dofs(c, 2)]
    )
    u, info = solve(model, K, f, fixed)
    sxx = nodal_stress(model, u, MATERIAL)[:, 0, 0]
    centre = np.array([p["hole_x"], p["hole_y"]])
    wall = model.triangles(lambda x: np.abs(np.hypot(x[0] - centre[0], x[1] - centre[1]) - R) < 1e-4 * R)
    xyz = model.points[wall[:, :3]]
    angle = np.arctan2(xyz[..., 1] - centre[1], xyz[..., 0] - centre[0])
    z = np.linspace(0.0, t, SAMPLES)
    weights = np.gradient(z)
    weights[[0, -1]] /= 2
    means = []
    for root in np.radians(case.roots):
        offset = np.angle(np.exp(1j * (angle - root)))
        near = (np.abs(offset) < np.pi / 2).all(axis=1)
        corners = np.stack([offset[near], xyz[near, :, 2]], axis=-1)
        values = p2_triangle_values(corners, sxx[wall[near]], np.column_stack([np.zeros(len(z)), z]))
        means.append(values @ weights / weights.sum())
    nominal = TENSION * W / (W - 2 * R) if case.nominal == "net" else TENSION
    return {"value": float(np.mean(means) / nominal), "iterations": info["iterations"], "residual": info["residual"]}


def solve_sphere(case: Case, model: FEModel) -> dict:
    a = case.parameters["inner_radius"]
    K = stiffness(model, MATERIAL)
    r_of = lambda x: np.sqrt((x**2).sum(axis=0))  # noqa: E731
    inner = model.facets(lambda x: np.abs(r_of(x) - a) < 1e-5 * a)
    f = _load(model, inner, lambda n: (-PRESSURE * n[0], -PRESSURE * n[1], -PRESSURE * n[2]))
    fixed = []
    for k in range(3):
        plane = model.triangles(lambda x, k=k: np.abs(x[k]) < 1e-6 * a)
        fixed.append(model.dofs(np.unique(plane), k))
    u, info = solve(model, K, f, np.concatenate(fixed))
    stress = nodal_stress(model, u, MATERIAL)
    nodes = np.unique(model.triangles(lambda x: np.abs(r_of(x) - a) < 1e-5 * a))
    x = model.points[nodes]
    r = np.linalg.norm(x, axis=1)
    radial = x / r[:, None]
    srr = np.einsum("ni,nij,nj->n", radial, stress[nodes], radial)
    hoop = (np.einsum("nii->n", stress[nodes]) - srr) / 2
    exact = lame(r)[2]
    deviation = (hoop - exact) / lame(a)[2]
    return {
        "value": float(1 + deviation.mean()),
        "worst": float(1 + deviation[np.argmax(np.abs(deviation))]),
        "iterations": info["iterations"],
        "residual": info["residual"],
    }


def solve_bracket(case: Case, model: FEModel) -> dict:
    """The filleted L-bracket: the end face of the base leg clamped, a shear traction -TENSION / 10 along x on
    the upright's top face (it opens the inner corner: the fillet in tension); the value is the peak over the
    fillet's arc of the across-the-width mean of the stress along the profile (sigma_tt, from the P2
    interpolation of the averaged nodal stresses on the 6-node boundary triangles of the fillet and of the two
    faces it is tangent to, developed flat: arc length along the profile x width; ARC_SAMPLES angles x SAMPLES
    widths), divided by the upright's nominal bending stress at the base leg's top face, 6 M / (w t^2)."""
    p = case.parameters
    L, top, t, w, r = p["leg_length"], p["leg_height"], p["thickness"], p["width"], p["fillet_radius"]
    tol = 1e-6 * L
    traction = TENSION / 10
    K = stiffness(model, MATERIAL)
    loaded = model.facets(lambda x: np.abs(x[2] - top) < tol)
    f = _load(model, loaded, lambda n: (-traction + 0 * n[0], 0 * n[0], 0 * n[0]))
    clamped = np.unique(model.triangles(lambda x: np.abs(x[0] - L) < tol))
    u, info = solve(model, K, f, np.concatenate([model.dofs(clamped, k) for k in range(3)]))
    stress = nodal_stress(model, u, MATERIAL)
    axis = t + r  # the fillet's axis at x = z = t + r, along y

    def developed(x):
        """(n,) arc length along the profile (upright face, fillet, base face) and (n, 3) its direction."""
        angle = np.mod(np.arctan2(x[:, 2] - axis, x[:, 0] - axis), 2 * np.pi)  # pi .. 3 pi / 2 on the fillet
        up, base = x[:, 2] > axis, x[:, 0] > axis
        along = np.where(up, np.pi * r - (x[:, 2] - axis), np.where(base, 1.5 * np.pi * r + x[:, 0] - axis, angle * r))
        direction = np.stack([-np.sin(angle), 0 * angle, np.cos(angle)], axis=1)
        direction[up], direction[base] = (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)
        return along, direction

    def beside(x):  # (n,) on the fillet or on a face it is tangent to, within 2 r of it
        on_fillet = (
            (np.abs(np.hypot(x[0] - axis, x[2] - axis) - r) < 1e-4 * r) & (x[0] < axis + tol) & (x[2] < axis + tol)
        )
        upright = (np.abs(x[0] - t) < tol) & (x[2] > axis - tol) & (x[2] < axis + 2 * r)
        base = (np.abs(x[2] - t) < tol) & (x[0] > axis - tol) & (x[0] < axis + 2 * r)
        return on_fillet | upright | base

    faces = model.triangles(beside)
    along, direction = developed(model.points[faces].reshape(-1, 3))
    along, direction = along.reshape(faces.shape), direction.reshape(*faces.shape, 3)
    s_tt = np.einsum("kni,knij,knj->kn", direction, stress[faces], direction)
    arc = np.linspace(np.pi, 1.5 * np.pi, ARC_SAMPLES)
    y = np.linspace(-w / 2, w / 2, SAMPLES)
    grid = np.stack(np.meshgrid(arc * r, y, indexing="ij"), axis=-1).reshape(-1, 2)
    corners = np.stack([along[:, :3], model.points[faces[:, :3], 1]], axis=-1)
    values = p2_triangle_values(corners, s_tt, grid).reshape(len(arc), len(y))
    weights = np.gradient(y)
    weights[[0, -1]] /= 2
    mean = values @ weights / weights.sum()
    nominal = 6 * traction * t * w * (top - t) / (w * t * t)
    peak = int(np.argmax(mean))
    return {
        "value": float(mean[peak] / nominal),
        "angle": float(np.degrees(arc[peak])),
        "iterations": info["iterations"],
        "residual": info["residual"],
    }


def solve_case(case: Case, model: FEModel) -> dict:
    solver = {"plate": solve_plate, "bracket": solve_bracket, "sphere": solve_sphere}[case.kind]
    return solver(case, model)


# ---------------------------------------------------------------------------------------------- meshes
def recipe_placements(case: Case, scale: float) -> list[dict]:
    """The shipped recipe's placements and the always-placed rules of knowledge/sizing.yaml, every size they ask
    for times ``scale`` (SCALED); the case's pattern's near / far / extent from case.sizes (the YAML's unless a
    variant sets them)."""
    place = [dict(p) for p in _yaml(KNOWLEDGE / "recipes" / f"{RECIPE}.yaml")["place"]]
    placed = {p["pattern"] for p in place}
    place += [
        {"pattern": p["pattern"]}
        for p in _yaml(KNOWLEDGE / "sizing.yaml")["always_place"]
        if p["pattern"] not in placed
    ]
    out = []
    for p in place:
        parameters = {**_defaults(p["pattern"]), **p.get("parameters", {})}
        if p["pattern"] == case.pattern:
            parameters.update(case.sizes)
        for key, power in SCALED.get(p["pattern"], {}).items():
            parameters[key] = parameters[key] * scale**power
        out.append({k: v for k, v in {**p, "parameters": parameters}.items() if k != "id"})
    return out


@functools.cache
def _scratch() -> Path:
    """This process's own folder for the scaled sizing files (two studies run side by side wrote one shared
    /tmp file: one of them read it empty)."""
    import tempfile

    return Path(tempfile.mkdtemp(prefix="fe_study-"))


def scaled_sizing(scale: float, fixed_gradation: bool = False) -> Path:
    """knowledge/sizing.yaml with the gradation limit scaled with the sizes: h(y) <= h(x) + (g - 1)|x - y| holds
    for s h with (g - 1) s, so the recipe series at scale s is exactly s times the recipe's graded field (as the
    Gmsh series is s times its Threshold field); ``fixed_gradation`` keeps the shipped g at every scale."""
    import yaml

    sizing = _yaml(KNOWLEDGE / "sizing.yaml")
    if not fixed_gradation:
        sizing["gradation"] = min(3.0, round(1 + (sizing["gradation"] - 1) * scale, 6))
    sizing["always_place"] = []  # the recipe series places them itself, scaled
    path = _scratch() / f"sizing_{sizing['gradation']:g}.yaml"
    path.write_text(yaml.safe_dump(sizing))
    return path


def fuzzymesh_model(case: Case, series: str, scale: float, seed: int, fixed_gradation: bool = False) -> FEModel:
    data = {
        "geometry": {"shape": case.shape, "parameters": dict(case.parameters)},
        "seed": seed,
        "size": scale * case.H,
    }
    if series == "recipe":
        data["knowledge"] = [str(scaled_sizing(scale, fixed_gradation))]
        data["place"] = recipe_placements(case, scale)
    else:
        data["knowledge"] = [str(STUDY_SIZING)]
        data["place"] = [{"pattern": "uniform-domain"}]
    result = mesh_job(job_from_dict(data, source="<fe_study>"), write=False)
    points, tets10, _ = quadratic(result.mesh, result.geometry, result.features)
    return FEModel(points, tets10, len(result.mesh.points))


def _bracket(occ, p: dict) -> int:
    """engine.shapes.l_bracket's solid in OpenCASCADE (its x-z profile with the fillet's arc, extruded along y over
    the width, centred); returns the fillet's surface tag."""
    import gmsh

    L, top, t, w, r = p["leg_length"], p["leg_height"], p["thickness"], p["width"], p["fillet_radius"]
    y = -w / 2
    corners = [(0, 0), (L, 0), (L, t), (t + r, t), (t, t + r), (t, top), (0, top)]
    points = [occ.addPoint(x, y, z) for x, z in corners]
    centre = occ.addPoint(t + r, y, t + r)
    sides = [
        occ.addLine(points[k], points[k + 1]) if k != 3 else occ.addCircleArc(points[3], centre, points[4])
        for k in range(6)
    ] + [occ.addLine(points[6], points[0])]
    occ.extrude([(2, occ.addPlaneSurface([occ.addCurveLoop(sides)]))], 0, w, 0)
    occ.synchronize()
    box = np.array([t, t, t + r, t + r])  # the fillet's x and z extent
    (fillet,) = [
        s
        for _, s in gmsh.model.getEntities(2)
        if np.allclose(np.take(gmsh.model.getBoundingBox(2, s), [0, 2, 3, 5]), box, atol=1e-6 * L)
    ]
    return fillet


GMSH_TO_VTK = [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]  # gmsh tet10: edges 01 12 20 30 32 31 -> VTK 01 12 02 03 13 23


def gmsh_model(case: Case, scale: float, seed: int = 0) -> FEModel:
    import gmsh

    if gmsh.isInitialized():  # fuzzymesh's mesher leaves its session (HXT, optimiser options) open: start afresh
        gmsh.finalize()
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", seed + 1)
        occ = gmsh.model.occ
        p = case.parameters
        if case.kind == "plate":
            L, W, t, R = p["length"], p["width"], p["thickness"], p["hole_radius"]
            box = occ.addBox(-L / 2, -W / 2, 0, L, W, t)
            cyl = occ.addCylinder(p["hole_x"], p["hole_y"], -t, 0, 0, 3 * t, R)
            occ.cut([(3, box)], [(3, cyl)])
            occ.synchronize()
            feature = [s for _, s in gmsh.model.getEntities(2) if gmsh.model.getType(2, s) == "Cylinder"]
        elif case.kind == "bracket":
            feature = [_bracket(occ, p)]
        else:
            a, b = p["inner_radius"], p["outer_radius"]
            outer, inner = occ.addSphere(0, 0, 0, b), occ.addSphere(0, 0, 0, a)
            shell, _ = occ.cut([(3, outer)], [(3, inner)])
            box = occ.addBox(0, 0, 0, 2 * b, 2 * b, 2 * b)
            occ.intersect(shell, [(3, box)])
            occ.synchronize()
            feature = [
                s
                for _, s in gmsh.model.getEntities(2)
                if gmsh.model.getType(2, s) == "Sphere" and max(gmsh.model.getBoundingBox(2, s)[3:]) < a * 1.01
            ]
            near, far, extent = 0.5 * case.H, case.H, (b - a) / 2
        if case.pattern:
            sizes, R = case.sizes, case.radius
            near, far, extent = sizes["near"] * R, min(sizes["far"] * R, case.H), sizes["extent"] * R
        assert feature, "no feature surface found"
        fields = gmsh.model.mesh.field
        d = fields.add("Distance")
        fields.setNumbers(d, "SurfacesList", feature)
        fields.setNumber(d, "Sampling", 40)
        th = fields.add("Threshold")
        fields.setNumber(th, "InField", d)
        fields.setNumber(th, "SizeMin", near * scale)
        fields.setNumber(th, "SizeMax", far * scale)
        fields.setNumber(th, "DistMin", 0.0)
        fields.setNumber(th, "DistMax", extent)
        fields.setAsBackgroundMesh(th)
        for option in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
            gmsh.option.setNumber(option, 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", case.H * scale)
        gmsh.model.mesh.generate(3)
        gmsh.model.mesh.setOrder(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        types, _, nodes = gmsh.model.mesh.getElements(3)
        tets = np.asarray(nodes[list(types).index(11)], np.int64).reshape(-1, 10)
    finally:
        gmsh.finalize()
    index = np.full(int(tags.max()) + 1, -1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    points = coords.reshape(-1, 3)
    tets10 = index[tets][:, GMSH_TO_VTK]
    used = np.unique(tets10)  # drop nodes of no tet, vertices first
    vertex = np.unique(tets10[:, :4])
    order = np.concatenate([vertex, np.setdiff1d(used, vertex)])
    renumber = np.full(len(points), -1, np.int64)
    renumber[order] = np.arange(len(order))
    points, tets10 = points[order], renumber[tets10]
    mid = points[tets10[:, 4:]]
    ends = points[tets10[:, TET10_EDGES]].mean(axis=2)
    assert np.abs(mid - ends).max() < 0.25 * case.H * scale, "tet10 edge order"
    return FEModel(points, tets10, len(vertex))


def measure(case: Case, series: str, scale: float, seed: int = 0, fixed_gradation: bool = False) -> dict:
    start = time.perf_counter()
    if series == "gmsh":
        model = gmsh_model(case, scale, seed)
    else:
        model = fuzzymesh_model(case, series, scale, seed, fixed_gradation)
    meshed = time.perf_counter() - start
    solved = solve_case(case, model)
    if not solved["residual"] <= UNSOLVED:  # a wrong value must not enter the tables (elasticity.solve's guard too)
        raise RuntimeError(f"the solver did not converge: relative residual {solved['residual']:.3g}")
    return {
        "case": case.name,
        "series": series,
        "scale": scale,
        "seed": seed,
        "nodes": model.vertices,
        "quadratic_nodes": len(model.points),
        "tetrahedra": len(model.tets10),
        **solved,
        "seconds": {"mesh": round(meshed, 2), "solve": round(time.perf_counter() - start - meshed, 2)},
    }


# ------------------------------------------------------------------------------------------- analysis
def reference(case: Case, stored: dict) -> float:
    if case.kind == "sphere":
        return 1.0  # values are hoop / Lame's hoop at r = a
    return stored[case.name]["value"]


def nodes_at(points: list[dict], target: float, key: str = "error") -> float | None:
    """Node count from which the series' |error| stays within target (log-log interpolation between its last
    point above and the next); the coarsest count if it never leaves; None if its finest is above."""
    points = sorted(points, key=lambda r: r["nodes"])
    error = np.abs([r[key] for r in points])
    above = np.flatnonzero(error > target)
    if len(above) == 0:
        return -float(points[0]["nodes"])  # negative: already within at the coarsest (an upper bound)
    if above[-1] == len(points) - 1:
        return None
    k = above[-1]
    (n0, e0), (n1, e1) = (points[k]["nodes"], error[k]), (points[k + 1]["nodes"], error[k + 1])
    if e1 <= 0:
        return float(n1)
    s = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
    return float(math.exp(math.log(n0) + s * (math.log(n1) - math.log(n0))))


def summarise(rows: list[dict], stored: dict, failures: list[dict] = ()) -> dict:
    """Per geometry and series: the per-scale points and the node counts from which every seed's |error| stays
    within 1 % and 3 % (at_1, at_3; the sphere: the worst inner node of every seed), and the same for the mean
    over the seeds (at_1_mean, at_3_mean)."""
    out = {}
    for case in CASES.values():
        ref = reference(case, stored)
        for series in ("recipe", "uniform", "gmsh"):
            group = [r for r in rows if r["case"] == case.name and r["series"] == series]
            if not group:
                continue
            points = []
            for scale in sorted({r["scale"] for r in group}, reverse=True):
                g = [r for r in group if r["scale"] == scale]
                errors = [(r["value"] - ref) / ref for r in g]
                point = {
                    "scale": scale,
                    "nodes": float(np.mean([r["nodes"] for r in g])),
                    "meshes": len(g),
                    "value": float(np.mean([r["value"] for r in g])),
                    "error": float(np.mean(errors)),
                    "worst_seed": float(max(errors, key=abs)),
                }
                if case.kind == "sphere":
                    point["worst_node"] = float(max((r["worst"] - 1 for r in g), key=abs))
                points.append(point)
            key = "worst_node" if case.kind == "sphere" else "worst_seed"
            failed = [r for r in failures if r["case"] == case.name and r["series"] == series]
            out.setdefault(case.name, {})[series] = {
                "points": points,
                "reference": ref,
                "rejected": len(failed),
                "meshes": len(group) + len(failed),
                "at_1": nodes_at(points, 0.01, key),
                "at_3": nodes_at(points, 0.03, key),
                "at_1_mean": nodes_at(points, 0.01, "error"),
                "at_3_mean": nodes_at(points, 0.03, "error"),
            }
    return out


def _count(value) -> str:
    if value is None:
        return "not reached"
    if value < 0:
        return f"≤ {-value:,.0f}"
    return f"{value:,.0f}"


def markdown(study: dict) -> str:
    stored, summary = study["references"], study["summary"]
    lines = [
        "# Recipe vs uniform vs Gmsh distance field: nodes to reach 1 % and 3 % (issue 15, item 4)",
        "",
        "Made by `python bench/fe_study.py` (see its docstring and docs/validation.md). One solver for all "
        "three series (10-node tets, scikit-fem, CG + AMG, averaged nodal stresses). Node counts are the "
        "linear mesh's vertices. Seeds: "
        + ", ".join(map(str, study["seeds"]))
        + " for fuzzymesh, "
        + ", ".join(map(str, study.get("gmsh_seeds", [0])))
        + " for Gmsh (its Mesh.RandomSeed; means over the seeds). Rows (bench/fe_study_rows.jsonl) of the tags "
        + ", ".join(f"`{t}`" for t in study["tags"])
        + " (a geometry's series from the first that has it).",
        "",
        "## Nodes from which the error of every seed stays within 1 % and 3 %",
        "",
        "| geometry | reference | recipe 1 % | uniform 1 % | gmsh field 1 % "
        "| recipe 3 % | uniform 3 % | gmsh field 3 % |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, per in summary.items():
        case = CASES[name]
        ref = "Lamé (worst inner node)" if case.kind == "sphere" else f"{stored[name]['value']:.4f}"
        cells = [_count(per.get(s, {}).get("at_1")) if s in per else "-" for s in ("recipe", "uniform", "gmsh")]
        cells += [_count(per.get(s, {}).get("at_3")) if s in per else "-" for s in ("recipe", "uniform", "gmsh")]
        lines.append(f"| {name} | {ref} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Same, for the mean over the seeds instead of every seed:",
        "",
        "| geometry | recipe 1 % | uniform 1 % | gmsh field 1 % | recipe 3 % | uniform 3 % | gmsh field 3 % |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, per in summary.items():
        cells = [_count(per[s]["at_1_mean"]) if s in per else "-" for s in ("recipe", "uniform", "gmsh")]
        cells += [_count(per[s]["at_3_mean"]) if s in per else "-" for s in ("recipe", "uniform", "gmsh")]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    refused = "; ".join(
        f"{name}: " + ", ".join(f"{s} {d['rejected']} of {d['meshes']}" for s, d in per.items() if d["rejected"])
        for name, per in summary.items()
        if any(d["rejected"] for d in per.values())
    )
    lines += [
        "",
        "Meshes refused by fuzzymesh's acceptance gate (min dihedral 5 deg, Hausdorff) and so missing "
        f"from the series: {refused or 'none'}.",
    ]
    lines += [
        "",
        "'≤ n': already within at the series' coarsest mesh (n nodes); 'not reached': not within at its "
        "finest. Crossings are interpolated log-log between the last mesh outside and the next.",
        "",
        "## Every scale",
        "",
        "| geometry | series | scale | nodes | value | error (mean over seeds) | worst seed |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, per in summary.items():
        for series, data in per.items():
            for p in data["points"]:
                extra = f" (worst node {100 * p['worst_node']:+.2f} %)" if "worst_node" in p else ""
                lines.append(
                    f"| {name} | {series} | {p['scale']:g} | {p['nodes']:,.0f} | {p['value']:.4f} | "
                    f"{100 * p['error']:+.2f} %{extra} | {100 * p['worst_seed']:+.2f} % |"
                )
    lines += ["", "## References", ""]
    for name, ref in stored.items():
        lines.append(f"- {name}: {ref['value']:.4f} ({ref['source']})")
    lines.append(
        "- sphere: Lamé's hoop stress at r = a (71.43 MPa); the table's value is hoop / Lamé, mean of the "
        "inner nodes; the 1 % / 3 % crossings use the worst inner node"
    )
    return "\n".join(lines) + "\n"


SCALES = {"recipe": (4.0, 3.0, 2.0, 1.5, 1.0), "uniform": (2.0, 1.5, 1.0, 0.75), "gmsh": (4.0, 3.0, 2.0, 1.5, 1.0)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reference", action="store_true", help="compute the fine reference runs")
    parser.add_argument("--reference-scale", type=float, default=0.3)
    parser.add_argument("--cases", nargs="*", default=list(CASES))
    parser.add_argument("--series", nargs="*", default=["recipe", "uniform", "gmsh"])
    parser.add_argument("--seeds", type=int, nargs="*", default=[0])
    parser.add_argument("--scales", type=str, default="", help="series=s1,s2;series=... overrides SCALES")
    parser.add_argument("--near", type=float, default=None, help="the case pattern's near (times r) for the recipe")
    parser.add_argument("--extent", type=float, default=None)
    parser.add_argument("--far", type=float, default=None)
    parser.add_argument(
        "--rows",
        type=Path,
        default=Path(__file__).with_name("fe_study_rows.jsonl"),
        help="every measured mesh appended here (resumable)",
    )
    parser.add_argument(
        "--fixed-gradation",
        action="store_true",
        help="the recipe series keeps the shipped gradation at every scale (not s times the recipe's field)",
    )
    parser.add_argument(
        "--tag",
        nargs="+",
        default=["shipped"],
        help="label of this run's rows (e.g. a tuned variant); with --out, the tags whose rows to tabulate: a "
        "(geometry, series) from the first tag that has rows of it",
    )
    parser.add_argument("--out", type=Path, default=None, help="write OUT.json / OUT.md from the rows of --tag")
    args = parser.parse_args(argv)
    stored = json.loads(REFERENCE_FILE.read_text()) if REFERENCE_FILE.exists() else {}
    if args.reference:
        for name in args.cases:
            case = CASES[name]
            if case.kind == "sphere" or name in stored:
                continue
            row = measure(case, "gmsh", args.reference_scale)
            p = case.parameters
            pet = peterson_kt(2 * p["hole_radius"] / p["width"]) if case.nominal == "net" else None
            stored[name] = {
                "value": row["value"],
                "nodes": row["nodes"],
                "quadratic_nodes": row["quadratic_nodes"],
                "scale": args.reference_scale,
                "peterson": pet,
                "seconds": row["seconds"],
                "source": f"Gmsh distance field x {args.reference_scale:g}, {row['nodes']:,} nodes "
                f"({row['quadratic_nodes']:,} quadratic)" + (f"; Peterson {pet:.4f}" if pet else ""),
            }
            REFERENCE_FILE.write_text(json.dumps(stored, indent=1) + "\n")
            print(name, stored[name], flush=True)
        return
    scales = dict(SCALES)
    for item in filter(None, args.scales.split(";")):
        key, values = item.split("=")
        scales[key] = tuple(float(v) for v in values.split(","))
    for name in args.cases:
        case = CASES[name]
        for key in ("near", "far", "extent"):
            if getattr(args, key) is not None and case.pattern:
                case.sizes[key] = getattr(args, key)
        for series in args.series:
            for scale in scales[series]:
                for seed in args.seeds:
                    try:
                        row = measure(case, series, scale, seed, args.fixed_gradation)
                    except Exception as error:  # a refused or failed mesh is a data point too
                        row = {"case": name, "series": series, "scale": scale, "seed": seed, "failed": str(error)[:200]}
                    row["tag"] = args.tag[0]
                    row["sizes"] = dict(case.sizes)
                    row["gradation"] = "fixed" if args.fixed_gradation else "scaled"
                    with args.rows.open("a") as f:
                        f.write(json.dumps(row) + "\n")
                    print(json.dumps(row), flush=True)
    if args.out:
        write(args.rows, args.tag, args.out, stored)


def write(rows_path: Path, tags: list[str], out: Path, stored: dict) -> None:
    """OUT.json / OUT.md from the rows of ``tags``: each (geometry, series) from the first tag with rows of it."""
    every = [json.loads(line) for line in rows_path.read_text().splitlines() if line.strip()]
    rows, taken = [], set()
    for tag in tags:
        own = [r for r in every if r.get("tag") == tag and (r["case"], r["series"]) not in taken]
        taken |= {(r["case"], r["series"]) for r in own}
        rows += own
    failures = [r for r in rows if "failed" in r]
    rows = [r for r in rows if "failed" not in r]
    study = {
        "tags": tags,
        "seeds": sorted({r["seed"] for r in rows if r["series"] != "gmsh"}),
        "gmsh_seeds": sorted({r["seed"] for r in rows if r["series"] == "gmsh"}),
        "references": stored,
        "summary": summarise(rows, stored, failures),
        "rows": rows,
        "failures": failures,
    }
    out.parent.joinpath(out.name + ".json").write_text(json.dumps(study, indent=1) + "\n")
    out.parent.joinpath(out.name + ".md").write_text(markdown(study))


if __name__ == "__main__":
    main()
