"""Case ``plate-hole``: a finite-width plate with a central circular hole in uniaxial tension.

The solid is the shape ``plate_with_hole`` with its defaults: length 200 = 2 W, width W = 100,
thickness 10, hole diameter d = 20, so d/W = 0.2. A uniform traction S pulls the two end faces
(``x-min``, ``x-max``) apart; the load is self-equilibrated, so three corners of the ``bottom`` face
hold the plate statically determinately (3-2-1: all of u at the corner of x-min, y-min and bottom,
u_y and u_z at the corner of x-max, y-min, bottom, u_z at the corner of x-min, y-max, bottom) and
their reactions are zero up to the solver's tolerance (reported).

The nodes of the hole wall lie on the exact cylinder, as in the mesh written (``engine.exact``). Stress recovery:
averaged nodal stresses, interpolated with the quadratic boundary triangles of the ``hole`` patch at
the two roots of the hole (the hole wall's lines at 90 degrees from the load
axis), and averaged through the thickness. The reference is Peterson's Kt for a thin plate, a
plane-stress solution: the through-thickness average is the quantity plane stress describes (in 3D
the root stress is a little higher at the mid-plane and lower at the faces; both are reported).
Kt is on the net section: Kt = sigma_root / sigma_nom with sigma_nom = S W / (W - d).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..job import job_from_dict
from ..pipeline import SIZE_FROM_SCALE
from ..pipeline import run as mesh_job
from . import CaseResult, Row
from .elasticity import Material, build, nodal_stress, run_figures, solve, stiffness, surface_load

MATERIAL = Material(E=200e3, nu=0.3)  # steel, MPa
TENSION = 100.0  # MPa on the end faces
PLATE = dict(length=200.0, width=100.0, thickness=10.0, hole_radius=10.0)
HOLE_NEAR, HOLE_FAR = 0.125, 1.0  # the hole pattern's defaults (times the radius)
THROUGH = 2.0  # the thin-wall pattern's default: elements through the plate
PER_CIRCLE = 24.0  # the curvature pattern's default: elements around the hole
STUDY_SIZING = Path(__file__).with_name("study-sizing.yaml")  # the shipped sizing without always-placed rules
THICKNESS_SAMPLES = 201  # points along each root line for the through-thickness mean


def peterson_kt(d_over_w: float) -> float:
    """Peterson's net-section Kt of a finite-width plate with a central hole in tension."""
    r = d_over_w
    return 3.0 - 3.13 * r + 3.66 * r**2 - 1.53 * r**3


def default_size() -> float:
    """The global size the pipeline gives the plate when the job sets none (model size / 40)."""
    return float(np.linalg.norm([PLATE["length"], PLATE["width"], PLATE["thickness"]])) / SIZE_FROM_SCALE


def always_placed(scale: float) -> list[dict]:
    """The always-placed thin-wall and curvature patterns with their sizes (thickness / through, 2 pi r /
    per_circle) times ``scale``."""
    return [
        {"pattern": "thin-wall", "parameters": {"through": THROUGH / scale}},
        {"pattern": "curvature", "parameters": {"per_circle": PER_CIRCLE / scale}},
    ]


def graded_placements(scale: float, rules: bool = True) -> list[dict]:
    """The static-stress recipe's placements on the plate (its re-entrant-edge pattern finds no edge there)
    with the hole pattern's near and far sizes times ``scale``, and with ``rules`` the thin-wall and curvature
    patterns' too."""
    return [
        {"pattern": "uniform-domain"},
        {"pattern": "hole", "every": "hole", "parameters": {"near": HOLE_NEAR * scale, "far": HOLE_FAR * scale}},
        *(always_placed(scale) if rules else []),
    ]


def job(scale: float = 1.0, graded: bool = True, seed: int = 0, rules: bool = True) -> dict:
    """The plate's job. Graded: the static-stress recipe (scale 1), else its placements with every size times
    ``scale`` (the global size too). Uniform: the base pattern at ``scale`` x the default size, with the thin-wall
    and curvature patterns' sizes times ``scale`` (the plate is thin everywhere: 2 / scale elements through it;
    24 / scale around the hole). Without ``rules`` (the convergence study: the hole pattern against a uniform
    size, down to 0.4 elements through the plate) the job reads ``STUDY_SIZING``: no always-placed patterns."""
    data = {
        "geometry": {"shape": "plate_with_hole", "parameters": dict(PLATE)},
        "seed": seed,
        **({} if rules else {"knowledge": [str(STUDY_SIZING)]}),
    }
    if graded and scale == 1.0:
        return {**data, "recipe": "static-stress"}
    uniform = [{"pattern": "uniform-domain"}, *(always_placed(scale) if rules else [])]
    return {**data, "size": scale * default_size(), "place": graded_placements(scale, rules) if graded else uniform}


def solve_plate(result) -> dict:
    """Solve the plate of a pipeline result; Kt through-thickness mean, at mid-plane and at the faces."""
    timings = {}
    start = time.perf_counter()
    model = build(result)
    K = stiffness(model, MATERIAL)
    f = surface_load(model, ("x-min", "x-max"), lambda n: (TENSION * n[0], 0 * n[0], 0 * n[0]))  # S e_x e_x . n
    a, b, c = (
        model.corner("x-min", "y-min", "bottom"),
        model.corner("x-max", "y-min", "bottom"),
        model.corner("x-min", "y-max", "bottom"),
    )
    fixed = np.concatenate(
        [model.dofs(np.array([a]), k) for k in range(3)]
        + [model.dofs(np.array([b]), k) for k in (1, 2)]
        + [model.dofs(np.array([c]), 2)]
    )
    timings["assemble"] = time.perf_counter() - start
    start = time.perf_counter()
    u, solver = solve(model, K, f, fixed)
    timings["solve"] = time.perf_counter() - start
    stress = nodal_stress(model, u, MATERIAL)
    z = np.linspace(0.0, PLATE["thickness"], THICKNESS_SAMPLES)
    sigma_xx = root_profile(model, stress[:, 0, 0], z)  # (2 roots, samples)
    width, d = PLATE["width"], 2 * PLATE["hole_radius"]
    nominal = TENSION * width / (width - d)
    weights = np.gradient(z)  # the trapezoidal rule on even steps
    weights[[0, -1]] /= 2
    mean = sigma_xx @ weights / weights.sum()
    return {
        "model": model,
        "Kt": float(mean.mean() / nominal),
        "Kt_roots": (mean / nominal).tolist(),
        "Kt_mid": float(sigma_xx[:, THICKNESS_SAMPLES // 2].mean() / nominal),
        "Kt_faces": float(sigma_xx[:, [0, -1]].mean() / nominal),
        "solver": solver,
        "timings": timings,
        "load": TENSION * width * PLATE["thickness"],
    }


def root_profile(model, values: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Nodal ``values`` along the two root lines of the hole wall (angle +-90 degrees from the x axis) at
    heights ``z``: (2, len(z)), interpolated with the quadratic boundary triangles of the ``hole`` patch."""
    triangles = model.triangles6[model.patch("hole")]
    centre = np.array([model.result.job.shape_parameters["hole_x"], model.result.job.shape_parameters["hole_y"]])
    xyz = model.points[triangles[:, :3]]  # (k, 3, 3)
    angle = np.arctan2(xyz[..., 1] - centre[1], xyz[..., 0] - centre[0])
    out = np.empty((2, len(z)))
    for row, root in enumerate((np.pi / 2, -np.pi / 2)):
        offset = np.angle(np.exp(1j * (angle - root)))  # angle from the root, wrapped
        near = (np.abs(offset) < np.pi / 2).all(axis=1)  # unrolled without the seam
        corners = np.stack([offset[near], xyz[near, :, 2]], axis=-1)
        points = np.column_stack([np.zeros(len(z)), z])
        out[row] = p2_triangle_values(corners, values[triangles[near]], points)
    return out


def p2_triangle_values(corners: np.ndarray, values: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Quadratic interpolation at 2-D ``points`` (p, 2) in the triangles with ``corners`` (k, 3, 2) and six
    nodal ``values`` (k, 6) each (corners, then mid-edges 01, 12, 20); a point takes its first triangle."""
    edge1, edge2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    inverse = np.linalg.inv(np.stack([edge1, edge2], axis=2))  # (k, 2, 2)
    local = np.einsum("kij,kpj->kpi", inverse, points[None] - corners[:, None, 0])  # (k, p, 2)
    lam = np.concatenate([1 - local.sum(axis=2, keepdims=True), local], axis=2)  # (k, p, 3)
    inside = (lam >= -1e-9).all(axis=2)
    if not inside.any(axis=0).all():
        raise ValueError("a root point lies in no triangle of the hole wall")
    owner = inside.argmax(axis=0)
    l0, l1, l2 = lam[owner, np.arange(len(points))].T
    shape = np.stack(
        [l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1), 4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0], axis=1
    )
    return np.einsum("pi,pi->p", shape, values[owner])


def run(scale: float = 1.0, seed: int = 0) -> CaseResult:
    start = time.perf_counter()
    result = mesh_job(job_from_dict(job(scale, seed=seed), source="<validate plate-hole>"), write=False)
    meshing = time.perf_counter() - start
    solved = solve_plate(result)
    d_over_w = 2 * PLATE["hole_radius"] / PLATE["width"]
    reference = peterson_kt(d_over_w)
    facts = run_figures(result, solved, meshing, solved["load"])
    title = (
        f"plate-hole: plate {PLATE['length']:g} x {PLATE['width']:g} x {PLATE['thickness']:g}, central hole "
        f"d = {2 * PLATE['hole_radius']:g} (d/W = {d_over_w:g}), tension {TENSION:g} MPa; "
        + ("recipe static-stress" if scale == 1.0 else f"recipe static-stress sizes x {scale:g}")
        + "; 10-node tets"
    )
    rows = [
        Row("Kt net, through-thickness mean", solved["Kt"], reference, "Peterson (plane stress)"),
        Row("Kt net, mid-plane", solved["Kt_mid"], None, "3-D: above the mean"),
        Row("Kt net, faces", solved["Kt_faces"], None, "3-D: below the mean"),
    ]
    return CaseResult("plate-hole", title, facts, rows)
