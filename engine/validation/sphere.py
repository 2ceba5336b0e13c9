"""Case ``sphere``: Lamé's thick hollow sphere under internal pressure.

The solid is the shape ``hollow_sphere_octant`` (inner radius a = 50, outer radius b = 100), one
eighth of the sphere: on each symmetry plane the normal displacement is zero (u_x = 0 at every node
of the patch ``symmetry-x``, likewise y and z), which also removes the rigid-body motions. A pressure
p acts on the patch ``inner`` (traction -p n, n the outward normal of the solid); ``outer`` is free.
The mesh is the base pattern alone (uniform size h = (b - a) / 14 x scale).

Stress recovery: averaged nodal stresses at the nodes of the ``inner`` patch (vertices and mid-edge
nodes, which lie on the true surface); the hoop stress there is (trace - sigma_rr) / 2, the mean of
the two tangential normal stresses (equal in the exact solution), with r the direction from the
centre. Each node is compared with Lamé's solution at its own radius; the table gives the mean over
the patch's nodes and the largest deviation, relative to the exact value at r = a.
"""

from __future__ import annotations

import time

import numpy as np

from ..job import job_from_dict
from ..pipeline import run as mesh_job
from . import CaseResult, Row
from .elasticity import Material, build, displacement, nodal_stress, run_figures, solve, stiffness, surface_load

MATERIAL = Material(E=200e3, nu=0.3)  # MPa
PRESSURE = 100.0  # MPa on the inner surface
INNER, OUTER = 50.0, 100.0
LAYERS = 14  # default element size: the wall thickness / LAYERS


def lame(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lamé's thick sphere under internal pressure: radial displacement, radial and hoop stress at r."""
    a3, b3, r3 = INNER**3, OUTER**3, np.asarray(r, float) ** 3
    scale = PRESSURE * a3 / (b3 - a3)
    u = scale / MATERIAL.E * ((1 - 2 * MATERIAL.nu) * r + (1 + MATERIAL.nu) * b3 / (2 * r**2))
    return u, -scale * (b3 / r3 - 1), scale * (1 + b3 / (2 * r3))


def job(scale: float = 1.0, seed: int = 0) -> dict:
    """The octant's job: the base pattern alone, h = (b - a) / LAYERS x ``scale``."""
    return {
        "geometry": {"shape": "hollow_sphere_octant", "parameters": {"inner_radius": INNER, "outer_radius": OUTER}},
        "size": scale * (OUTER - INNER) / LAYERS,
        "seed": seed,
    }


def solve_sphere(result) -> dict:
    """Solve the octant of a pipeline result; displacement and stresses at the inner and outer nodes."""
    start = time.perf_counter()
    model = build(result)
    K = stiffness(model, MATERIAL)
    f = surface_load(model, ("inner",), lambda n: (-PRESSURE * n[0], -PRESSURE * n[1], -PRESSURE * n[2]))
    fixed = np.concatenate([model.dofs(model.patch_nodes(f"symmetry-{axis}"), k) for k, axis in enumerate("xyz")])
    assembled = time.perf_counter() - start
    start = time.perf_counter()
    u, solver = solve(model, K, f, fixed)
    solved = time.perf_counter() - start
    stress, moved = nodal_stress(model, u, MATERIAL), displacement(model, u)
    out = {"model": model, "solver": solver, "timings": {"assemble": assembled, "solve": solved}}
    for name in ("inner", "outer"):
        nodes = model.patch_nodes(name)
        x = model.points[nodes]
        r = np.linalg.norm(x, axis=1)
        radial = x / r[:, None]
        sigma_rr = np.einsum("ni,nij,nj->n", radial, stress[nodes], radial)
        out[name] = {
            "r": r,
            "u_r": np.einsum("ni,ni->n", moved[nodes], radial),
            "sigma_rr": sigma_rr,
            "hoop": (np.einsum("nii->n", stress[nodes]) - sigma_rr) / 2,
        }
    return out


def run(scale: float = 1.0, seed: int = 0) -> CaseResult:
    start = time.perf_counter()
    result = mesh_job(job_from_dict(job(scale, seed), source="<validate sphere>"), write=False)
    meshing = time.perf_counter() - start
    solved = solve_sphere(result)
    facts = run_figures(result, solved, meshing)
    title = (
        f"sphere: thick hollow sphere a = {INNER:g}, b = {OUTER:g} (octant, symmetry planes), internal "
        f"pressure {PRESSURE:g} MPa; uniform h = {job(scale)['size']:.3g}; 10-node tets"
    )
    rows = []
    for quantity, radius, surface, field, index in (
        ("u_r at r = a", INNER, "inner", "u_r", 0),
        ("hoop stress at r = a", INNER, "inner", "hoop", 2),
        ("u_r at r = b", OUTER, "outer", "u_r", 0),
        ("hoop stress at r = b", OUTER, "outer", "hoop", 2),
    ):
        values, exact = solved[surface][field], lame(solved[surface]["r"])[index]
        reference = float(lame(radius)[index])
        deviation = values - exact
        worst = deviation[np.argmax(np.abs(deviation))]
        rows += [
            Row(f"{quantity}, mean of the nodes", reference + float(deviation.mean()), reference, "Lamé"),
            Row(f"{quantity}, worst node", reference + float(worst), reference, "Lamé"),
        ]
    return CaseResult("sphere", title, facts, rows)
