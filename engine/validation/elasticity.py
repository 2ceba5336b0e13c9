"""Linear elasticity with quadratic tetrahedra (scikit-fem) on a fuzzymesh mesh.

The model is the mesh's 10-node form as ``fuzzymesh mesh`` writes it (``engine.fe.quadratic``: the nodes of
planes, cylinders, spheres and cones on their exact surfaces) as a curved scikit-fem ``MeshTet2`` with
``ElementVector(ElementTetP2())``: isoparametric quadratic tetrahedra. Boundary conditions are applied
by patch and corner names, through the mesh's boundary triangles tagged by patch, never by coordinates.
The system is solved by conjugate gradients preconditioned with smoothed-aggregation algebraic multigrid
(pyamg, rigid-body modes as near null space). Stresses are recovered at the nodes by averaging, over the
elements that share a node, each element's own stress at that node (the usual "averaged nodal stress"
of FE post-processors).

Needs the ``fe`` extra (scikit-fem, pyamg); :func:`engine.validation.require_fe` checks it first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fe import CORNER, quadratic, row_index, tet_boundary

QUADRATURE_ORDER = 2  # exact for the stiffness of straight quadratic tets (4 points); standard for C3D10
TOLERANCE = 1e-10  # relative residual of the conjugate gradients
CG_STEPS = 300  # conjugate-gradient steps before a direct solve takes over (40-60 converge)
AMG_SEED = 0  # numpy's global generator is seeded with this (and restored) while pyamg builds the preconditioner


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic material: Young's modulus and Poisson's ratio."""

    E: float
    nu: float

    @property
    def lame(self) -> tuple[float, float]:
        return self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu)), self.E / (2 * (1 + self.nu))

    def stress(self, grad: np.ndarray) -> np.ndarray:
        """Stress (3, 3, ...) from the displacement gradient (3, 3, ...)."""
        lam, mu = self.lame
        strain = (grad + np.swapaxes(grad, 0, 1)) / 2
        return 2 * mu * strain + lam * np.einsum("ii...->...", strain) * np.eye(3).reshape(3, 3, *[1] * (grad.ndim - 2))


@dataclass
class Model:
    """A meshed solid as quadratic finite elements.

    ``points``/``tets10``/``triangles6`` are the 10-node mesh (see :func:`build`; the linear mesh's
    nodes first); ``dof[k]`` is the scikit-fem scalar degree of freedom at node k, so component
    c of the displacement there is ``3 * dof[k] + c``.
    """

    result: object  # engine.pipeline.Result
    points: np.ndarray
    tets10: np.ndarray
    triangles6: np.ndarray  # the tets' own boundary faces (engine.fe.tet_boundary order)
    face_patch: np.ndarray  # the patch of each
    mesh: object  # skfem.MeshTet2
    basis: object  # skfem.CellBasis, vector P2
    dof: np.ndarray

    @property
    def nodes(self) -> int:
        """Nodes of the linear mesh (what fuzzymesh places)."""
        return len(self.result.mesh.points)

    def patch_indices(self, name: str) -> list[int]:
        """Indices of the solid's patches named (or with the id) ``name``."""
        return _patches(self.result, name)

    def patch(self, name: str) -> np.ndarray:
        """Indices of the boundary triangle6 (the tets' own faces) on the patch named ``name``."""
        return np.flatnonzero(np.isin(self.face_patch, self.patch_indices(name)))

    def facets(self, name: str) -> np.ndarray:
        """scikit-fem facet indices of the patch named ``name``."""
        faces = np.sort(self.triangles6[self.patch(name), :3], axis=1)
        return row_index(np.sort(self.mesh.facets.T, axis=1), faces)

    def patch_nodes(self, name: str) -> np.ndarray:
        """Nodes (vertices and mid-edge nodes) on the patch named ``name``."""
        return np.unique(self.triangles6[self.patch(name)])

    def corner(self, *patches: str) -> int:
        """The mesh node at the solid's corner shared by the named patches."""
        features, faces = self.result.features, self.result.geometry.faces
        vertices = [
            set(faces[np.concatenate([features.patches[i].faces for i in self.patch_indices(name)])].ravel().tolist())
            for name in patches
        ]
        corners = [c for c, corner in enumerate(features.corners) if all(corner.vertex in v for v in vertices)]
        mesh = self.result.mesh
        nodes = np.flatnonzero((mesh.node_level == CORNER) & np.isin(mesh.node_entity, corners))
        if len(nodes) != 1:
            raise KeyError(f"{len(nodes)} corner nodes shared by {', '.join(patches)}")
        return int(nodes[0])

    def dofs(self, nodes: np.ndarray, component: int) -> np.ndarray:
        return 3 * self.dof[nodes] + component


def _patches(result, name: str) -> list[int]:
    index = [i for i, p in enumerate(result.features.patches) if name in p.names or p.id == name]
    if not index:
        raise KeyError(f"no patch named '{name}'")
    return index


def build(result) -> Model:
    """The quadratic model of a pipeline result (``engine.pipeline.run``): exactly the 10-node elements
    ``fuzzymesh mesh`` writes at order 2 (``engine.fe.quadratic``: mid-edge nodes of planes, cylinders and
    spheres on the exact surfaces, like the vertices), no private snapping.
    """
    from skfem import Basis, ElementTetP2, ElementVector, MeshTet2

    boundary = tet_boundary(result.mesh)
    points, tets10, triangles6 = quadratic(result.mesh, result.geometry, result.features, boundary=boundary)
    mesh = MeshTet2(np.ascontiguousarray(points.T), np.ascontiguousarray(tets10.T))
    basis = Basis(mesh, ElementVector(ElementTetP2()), intorder=QUADRATURE_ORDER)
    dof = np.empty(len(points), np.int64)
    dof[tets10] = (basis.element_dofs[::3] // 3).T  # the element's local node order is tets10's
    return Model(result, points, tets10, triangles6, boundary[2], mesh, basis, dof)


def run_figures(result, solved: dict, meshing: float, load: float | None = None) -> dict:
    """The figures of a validation run: the mesh's and the model's sizes, the solver's iterations, with ``load``
    the largest reaction over it, and the stages' seconds (``meshing``; ``solved``: a case's solve, with its
    ``model``, ``solver`` figures and ``timings``)."""
    model, solver = solved["model"], solved["solver"]
    return {
        "nodes": model.nodes,
        "tetrahedra": len(result.mesh.tets),
        "quadratic nodes": len(model.points),
        "dofs": int(model.basis.N),
        "CG iterations": f"{solver['iterations']}, then a direct solve" if solver["direct"] else solver["iterations"],
        **({} if load is None else {"max reaction / load": solver["reaction"] / load}),
        "mesh s": round(meshing, 1),
        "assemble s": round(solved["timings"]["assemble"], 1),
        "solve s": round(solved["timings"]["solve"], 1),
    }


def stiffness(model: Model, material: Material):
    from skfem import asm
    from skfem.models.elasticity import linear_elasticity

    return asm(linear_elasticity(*material.lame), model.basis)


def surface_load(model: Model, patches: tuple[str, ...], traction) -> np.ndarray:
    """Load vector of the traction ``traction(n)`` -> 3 components, per unit area, over the named patches
    (n: the outward unit normal, (3, ...))."""
    from skfem import FacetBasis, LinearForm, asm

    @LinearForm
    def form(v, w):
        t = traction(w.n)
        return t[0] * v[0] + t[1] * v[1] + t[2] * v[2]

    return asm(
        form,
        FacetBasis(
            model.mesh,
            model.basis.elem,
            facets=np.concatenate([model.facets(p) for p in patches]),
            intorder=QUADRATURE_ORDER,
        ),
    )


def rigid_modes(locations: np.ndarray) -> np.ndarray:
    """The six rigid-body displacement vectors (n, 6) of dofs at ``locations`` (3, n), component = index % 3."""
    component = np.arange(locations.shape[1]) % 3
    modes = np.zeros((locations.shape[1], 6))
    modes[np.arange(len(component)), component] = 1.0
    for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):  # rotation in the (i, j) plane
        modes[component == i, 3 + k] = -locations[j, component == i]
        modes[component == j, 3 + k] = locations[i, component == j]
    return modes


def solve(model: Model, K, f: np.ndarray, fixed: np.ndarray) -> tuple[np.ndarray, dict]:
    """Displacements with ``fixed`` dofs at 0, and the solver's figures (iterations, residual, reactions; 'direct'
    where CG + AMG did not converge and a sparse LU solved it).

    pyamg's smoothed aggregation scales its prolongation smoother by a spectral radius estimated from a random
    start drawn from numpy's global generator: the solve depended on whatever had drawn from it before, and now
    and then CG diverged (a bracket mesh solved twice in one process: 57 steps to 1e-10, then 1,000 steps to 0.1;
    unsmoothed aggregation diverged on another). The generator is seeded while the preconditioner is built, and
    a solve CG does not finish is done directly."""
    import pyamg
    from scipy.sparse.linalg import spsolve
    from skfem import condense

    A, b, u, free = condense(K, f, D=np.unique(fixed))
    A = A.tocsr()
    state = np.random.get_state()
    np.random.seed(AMG_SEED)
    try:
        solver = pyamg.smoothed_aggregation_solver(
            A, B=rigid_modes(model.basis.doflocs)[free], max_levels=2, coarse_solver="splu"
        )
    finally:
        np.random.set_state(state)
    residuals: list = []
    u[free] = solver.solve(b, tol=TOLERANCE, accel="cg", maxiter=CG_STEPS, residuals=residuals)
    residual, direct = residuals[-1] / residuals[0], False
    if not residual <= 10 * TOLERANCE:
        u[free] = spsolve(A.tocsc(), b)
        residual, direct = np.linalg.norm(A @ u[free] - b) / np.linalg.norm(b), True
    reactions = (K @ u - f)[np.unique(fixed)]
    return u, {
        "iterations": len(residuals) - 1,
        "residual": float(residual),
        "direct": direct,
        "reaction": float(np.abs(reactions).max(initial=0.0)),
    }


def displacement(model: Model, u: np.ndarray) -> np.ndarray:
    """Displacement (n, 3) at every node of the 10-node mesh."""
    return u[3 * model.dof[:, None] + np.arange(3)]


def nodal_stress(model: Model, u: np.ndarray, material: Material) -> np.ndarray:
    """Stress (n, 3, 3) at every node: the mean of the stresses of the elements sharing it, there."""
    from skfem import Basis, ElementTetP2

    nodes = ElementTetP2().doflocs.T  # reference coordinates of the 10 local nodes
    at_nodes = Basis(model.mesh, model.basis.elem, quadrature=(nodes, np.full(10, 1 / 60)))
    stress = material.stress(at_nodes.interpolate(u).grad)  # (3, 3, elements, 10)
    values = stress.transpose(2, 3, 0, 1).reshape(-1, 9)
    index = model.tets10.ravel()
    count = np.bincount(index, minlength=len(model.points))
    summed = np.stack([np.bincount(index, weights=values[:, k], minlength=len(model.points)) for k in range(9)], 1)
    return (summed / count[:, None]).reshape(-1, 3, 3)
