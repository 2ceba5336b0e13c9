"""The acceptance gate: no mesh leaves the pipeline unless it is a valid model of the input solid.

Run after meshing, the same for every packer and mesher (built-in or plug-in). The checks, in order:

1. every tetrahedron has a positive volume;
2. the tets' own boundary faces form a closed two-manifold (every edge in exactly two faces, with
   opposite orientations, and the faces round every node one fan); the mesher's declared boundary
   triangles only name patches (:func:`engine.fe.tet_boundary`);
3. an assembly's (touching solids of a CAD file, engine/assembly.py): every interface triangle is a face of
   exactly two tets, of different bodies (the interface conforms, its nodes are merged);
4. the mesh volume is within ``volume`` (a fraction) of the input solid's, and each body of an assembly
   within it of its CAD solid's;
5. the two-sided Hausdorff distance between the mesh boundary and the input surface, over the target
   size h at each sample point, is at most ``hausdorff`` in both directions;
6. the smallest dihedral angle is at least ``min_dihedral`` degrees, or ``cusp_min_dihedral`` for a tet next to a
   cusp (:func:`cusps`) or across a face narrower than a quarter of it (:func:`next_to_narrow_faces`), where the
   geometry forces flat elements (such tets are reported, not refused);
7. for 10-node elements, the smallest scaled Jacobian is at least ``quadratic_jacobian``.

The tolerances are expert knowledge: ``acceptance:`` in the sizing defaults (knowledge/sizing.yaml), which a
job's own knowledge files may replace. A failed check raises :class:`~engine.errors.MeshRejected`: one line
naming the check, where it fails (a point and the nearest patch) and what to do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import MeshRejected
from .quadratic import QUADRATIC_FLOOR

CUSP_ANGLE = 10.0  # degrees: two feature curves that leave a corner closer than this make a cusp
NEAR_CUSP = 10.0  # longest edges of a tet: how far from a cusp's corner its face may stay narrower than the tet
NARROW = 0.25  # a face narrower than this x a tet's longest edge, within that edge of it, forces it flat
KEEP_INVALID = "run again with --keep-invalid to write the mesh as <name>.invalid.* for inspection"


@dataclass(frozen=True)
class Tolerances:
    """The gate's limits; see knowledge/sizing.yaml ``acceptance:``."""

    min_dihedral: float = 5.0  # degrees
    cusp_min_dihedral: float = 1.0  # degrees, next to a cusp or a narrow face, where the geometry forces flat tets
    volume: float = 0.02  # |V_mesh / V_input - 1|
    hausdorff: float = 0.25  # x the target size h, each direction
    quadratic_jacobian: float = QUADRATIC_FLOOR  # min scaled Jacobian of a 10-node tet
    hex_jacobian: float = 0.2  # min scaled corner Jacobian of a hexahedron, prism or pyramid (hex-dominant)


def boundary_topology(tets: np.ndarray, sides: tuple | None = None) -> dict:
    """Topology of the tets' boundary faces (faces of one tet only; ``sides`` their (owner, side) when known,
    :func:`engine.mesh.single_faces`): counts of edges not in exactly two faces (``open_edges``), of edges
    whose two faces run the same way (``misoriented``) and of nodes whose faces are not one fan (``pinched``:
    two sheets of the boundary touch there, as where two tets meet at a node only); ``faces`` the (b, 3)
    outward boundary faces; ``bad_node`` a node on a defect or -1."""
    import igl

    from .mesh import FACES, distinct_pairs, single_faces

    owner, side = single_faces(tets) if sides is None else sides
    boundary = tets[owner[:, None], FACES[side]]
    directed = boundary[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    undirected, edge_counts = distinct_pairs(np.sort(directed, axis=1), counts=True)
    open_edges = undirected[edge_counts != 2]
    same_way, way_counts = distinct_pairs(directed, counts=True)
    misoriented = same_way[way_counts > 1]
    used = np.unique(boundary)
    pinched = used[~igl.is_vertex_manifold(np.ascontiguousarray(boundary, dtype=np.int64))[used]]
    bad = next((d[:1].ravel() for d in (open_edges, misoriented, pinched) if len(d)), [])
    return {
        "faces": boundary,
        "open_edges": int(len(open_edges)),
        "misoriented": int(len(misoriented)),
        "pinched": int(len(pinched)),
        "bad_node": int(bad[0]) if len(bad) else -1,
    }


def check_mesh(
    mesh,
    geometry,
    features,
    quality,
    boundary: dict,
    tolerances: Tolerances,
    quadratic_jacobian: np.ndarray | None = None,
) -> list[str]:
    """Raise MeshRejected at the first check the mesh fails (module docstring); ``quality`` is the
    TetQuality of ``mesh``, ``boundary`` the :func:`engine.quality.boundary_report` of it, and
    ``quadratic_jacobian`` (m,) the scaled Jacobians of its 10-node elements, if any. Returns the warnings of a
    mesh that passes (flat tets kept next to cusps)."""
    tets = mesh.tets

    def where(point) -> str:
        return _locate(np.asarray(point, dtype=float), geometry, features)

    flat = np.flatnonzero(quality.volume <= 0)
    if len(flat):
        raise MeshRejected(
            f"{len(flat)} tetrahedra of zero or negative volume, the first at "
            f"{where(mesh.points[tets[flat[0]]].mean(axis=0))}",
            check="positive volumes",
            fix=f"mesh again with another seed and report the input; {KEEP_INVALID}",
        )
    if not boundary["two_manifold"]:
        what = (
            f"{boundary['boundary_edges']} boundary edges not shared by exactly two faces"
            if boundary["boundary_edges"]
            else f"{boundary['misoriented_edges']} boundary edges with inconsistently oriented faces"
            if boundary["misoriented_edges"]
            else f"{boundary['pinched_nodes']} boundary nodes where two sheets of the boundary touch at a point"
        )
        raise MeshRejected(
            f"the boundary is not a closed two-manifold: {what}, e.g. at {where(mesh.points[boundary['bad_node']])}",
            check="closed two-manifold boundary",
            fix=f"use the default mesher 'delaunay', or another seed; {KEEP_INVALID}",
        )
    assembly = getattr(features, "assembly", None) if mesh.body is not None else None
    if assembly is not None and mesh.interfaces:
        triangles = np.concatenate([np.asarray(t, np.int64).reshape(-1, 3) for t in mesh.interfaces.values()])
        names = np.repeat(list(mesh.interfaces), [len(t) for t in mesh.interfaces.values()])
        count, different = interface_sides(tets, mesh.body, triangles)
        bad = np.flatnonzero((count != 2) | ~different)
        if len(bad):
            first = bad[0]
            how = f"a face of {count[first]} tets" if count[first] != 2 else "a face of two tets of the same body"
            raise MeshRejected(
                f"{len(bad)} of the {len(triangles)} interface triangles are not shared by two tets of different "
                f"bodies, the first on {names[first]} ({how}) at {where(mesh.points[triangles[first]].mean(axis=0))}",
                check="assembly interface",
                fix=f"mesh again with another seed and report the input; {KEEP_INVALID}",
            )
    error = mesh.volume / geometry.volume - 1
    if not abs(error) <= tolerances.volume:
        worst = boundary["hausdorff_mesh_to_input"] if error > 0 else boundary["hausdorff_input_to_mesh"]
        raise MeshRejected(
            f"the mesh volume is {100 * error:+.2f} % of the input's (tolerance "
            f"{100 * tolerances.volume:g} %); the boundary strays most at {where(worst['at'])}",
            check="volume",
            fix="refine there (a smaller size, or a pattern placed on that feature) "
            f"or raise acceptance.volume in the sizing defaults; {KEEP_INVALID}",
        )
    if assembly is not None:
        body_volume = np.bincount(mesh.body, quality.volume, minlength=len(assembly.bodies))
        cad_volume = assembly.volumes or [g.volume for g, _ in assembly.bodies]
        for b, (name, cad) in enumerate(zip(assembly.names, cad_volume)):
            error = body_volume[b] / cad - 1
            if not abs(error) <= tolerances.volume:
                centre = mesh.points[tets[mesh.body == b]].mean(axis=(0, 1))
                raise MeshRejected(
                    f"the body '{name}' has {100 * error:+.2f} % of its CAD solid's volume (tolerance "
                    f"{100 * tolerances.volume:g} %); its tets' centre is at {where(centre)}",
                    check="body volume",
                    fix="refine that body (a smaller size, or a pattern placed on its features) or raise "
                    f"acceptance.volume in the sizing defaults; {KEEP_INVALID}",
                )
    for direction, text in (
        ("hausdorff_input_to_mesh", "the input surface is"),
        ("hausdorff_mesh_to_input", "the mesh boundary is"),
    ):
        far = boundary[direction]
        if not far["max_over_h"] <= tolerances.hausdorff:
            raise MeshRejected(
                f"{text} {far['max_over_h']:.3g} h ({far['at_distance']:.4g}) from the other at "
                f"{where(far['at'])} (tolerance {tolerances.hausdorff:g} h)",
                check="Hausdorff distance",
                fix="refine there (a smaller size, or a pattern placed on that feature) or raise "
                f"acceptance.hausdorff in the sizing defaults; {KEEP_INVALID}",
            )
    notes = []
    low = np.flatnonzero(~(quality.min_dihedral >= tolerances.min_dihedral))
    if len(low):
        found = cusps(features)
        cusp, facet, width = forced_flat(mesh.points[tets[low]], geometry, features, found)
        excused = ((cusp >= 0) | (facet >= 0)) & (quality.min_dihedral[low] >= tolerances.cusp_min_dihedral)
        failing = low[~excused] if not excused.all() else low
        first = int(np.flatnonzero(low == failing[np.argmin(quality.min_dihedral[failing])])[0])
        worst = int(low[first])
        clause = forced_flat_clause(
            mesh.points[tets[worst]], geometry, features, found, (cusp[first], facet[first], width[first])
        )
        line = (
            f"{len(failing)} tetrahedra have a dihedral angle below {tolerances.min_dihedral:g} deg"
            + (
                f" (and {int(excused.sum())} more next to cusps or narrow faces, down to "
                f"{quality.min_dihedral[low[excused]].min():.3g} deg, which acceptance.cusp_min_dihedral allows)"
                if excused.any() and not excused.all()
                else ""
            )
            + f", the smallest {quality.min_dihedral[worst]:.3g} deg at "
            f"{where(mesh.points[tets[worst]].mean(axis=0))}{clause}"
        )
        if excused.all():
            notes.append(
                f"{line}: all next to cusps or faces narrower than the elements, where the geometry forces flat "
                f"elements; kept, as acceptance.cusp_min_dihedral ({tolerances.cusp_min_dihedral:g} deg) allows there"
            )
        else:
            raise MeshRejected(
                line,
                check="minimum dihedral angle",
                fix=(
                    "remove the cusp or the narrow face in the model (let the face end on an edge at an angle, or "
                    "cut the sliver off), or accept flatter elements there with a lower "
                    "acceptance.cusp_min_dihedral in a knowledge file"
                    if clause
                    else "mesh again with another seed or a size that resolves the feature there, or lower "
                    "acceptance.min_dihedral in the sizing defaults"
                )
                + f"; {KEEP_INVALID}",
            )
    if quadratic_jacobian is not None and len(quadratic_jacobian):
        worst = int(np.argmin(quadratic_jacobian))
        if not quadratic_jacobian[worst] >= tolerances.quadratic_jacobian:
            raise MeshRejected(
                f"a 10-node element has a scaled Jacobian of {quadratic_jacobian[worst]:.3g} (floor "
                f"{tolerances.quadratic_jacobian:g}) at {where(mesh.points[tets[worst]].mean(axis=0))}",
                check="10-node element validity",
                fix="refine the curved surface there (more elements per circle) or lower "
                f"acceptance.quadratic_jacobian in the sizing defaults; {KEEP_INVALID}",
            )
    return notes


def interface_sides(tets: np.ndarray, body: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``triangles`` (k, 3): how many of ``tets`` have it as a face, and whether those tets' bodies
    (``body``: per tet) differ."""
    from .mesh import FACES

    if len(triangles) == 0:
        return np.zeros(0, np.int64), np.zeros(0, bool)
    on = np.zeros(int(max(tets.max(), triangles.max())) + 1, bool)
    on[triangles.ravel()] = True
    near = np.flatnonzero(on[tets].sum(axis=1) >= 3)  # tets with a face on the interface's nodes
    faces = tets[near][:, FACES].reshape(-1, 3)
    owner = np.repeat(near, 4)
    inside = on[faces].all(axis=1)
    faces, owner = faces[inside], owner[inside]
    keys = np.sort(np.vstack([faces, triangles]), axis=1)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    face_key, triangle_key = inverse[: len(faces)], inverse[len(faces) :]
    size = int(inverse.max()) + 1
    count = np.bincount(face_key, minlength=size)
    low, high = np.full(size, np.iinfo(np.int64).max), np.full(size, -1)
    np.minimum.at(low, face_key, body[owner])
    np.maximum.at(high, face_key, body[owner])
    return count[triangle_key], (high > low)[triangle_key]


def cusps(features) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The corners that two feature curves leave less than CUSP_ANGLE apart: (point (k, 3), curve (k,), other
    curve (k,), angle (k,) degrees). There the face between the curves is narrower than the elements for several
    element sizes, and flat elements are forced (the cause of most minimum-angle rejections of real parts: a
    fillet dying into a face, a bolt's washer face tangent to its hexagon's flats; Gmsh gives 1-4 deg there)."""
    from .features import leaving_angles

    curve, end, other, _, angle = leaving_angles(features)
    cusp = np.flatnonzero(angle < CUSP_ANGLE)
    at = np.array([features.curves[c].points[0 if e == 0 else -1] for c, e in zip(curve[cusp], end[cusp])])
    return at.reshape(-1, 3), curve[cusp], other[cusp], angle[cusp]


def longest_edges(corners: np.ndarray) -> np.ndarray:
    """(t,) the longest edge of each tetrahedron (``corners`` (t, 4, 3))."""
    return np.linalg.norm(corners[:, :, None] - corners[:, None], axis=3).max(axis=(1, 2))


def next_to_cusps(corners: np.ndarray, features, found: tuple) -> np.ndarray:
    """(t,) for each tetrahedron (``corners`` (t, 4, 3)) the index of the cusp in ``found`` (:func:`cusps`) it is
    next to, -1 if none: its centre is within one of its longest edges of both curves that leave the cusp's corner
    (it spans the face between them, narrower than it there) and within NEAR_CUSP longest edges of the corner.
    (A ball of three edges around the corner missed a flat tet 3 edges along a circle tangent to a line, whose
    face is 0.007 mm wide there; a ball of L / sin(angle) took in a hex bolt head's tets at its axis.)"""
    from .anchors import curve_distance

    at, curve, other, _ = found
    which = np.full(len(corners), -1)
    if len(at) == 0 or len(corners) == 0:
        return which
    centre = corners.mean(axis=1)
    longest = longest_edges(corners)
    for k in range(len(at)):
        near = np.flatnonzero((which < 0) & (np.linalg.norm(centre - at[k], axis=1) <= NEAR_CUSP * longest))
        if len(near):
            spread = np.maximum(
                curve_distance(features.curves[curve[k]], 0.0)(centre[near]),
                curve_distance(features.curves[other[k]], 0.0)(centre[near]),
            )
            which[near[spread <= longest[near]]] = k
    return which


def next_to_narrow_faces(corners: np.ndarray, geometry, features) -> tuple[np.ndarray, np.ndarray]:
    """(facet (t,), width (t,)): for each tetrahedron (``corners`` (t, 4, 3)) an input facet within its longest
    edge of its centre where the face is narrower than NARROW x that edge (:func:`engine.facewidth.facet_widths`:
    two feature curves bounding one face, that far apart), and that width; facet -1 where none. No element
    size the rules allow resolves such a face (a recess 3 um deep in a plate's bottom: its rim is a 0.003 wide
    strip at h 0.07)."""
    import igl

    from .facewidth import facet_widths

    which, width = np.full(len(corners), -1), np.full(len(corners), np.inf)
    if len(corners) == 0:
        return which, width
    centre = corners.mean(axis=1)
    longest = longest_edges(corners)
    widths = facet_widths(geometry, features, float(longest.max()))
    narrow = np.flatnonzero(widths < NARROW * longest.max())
    if len(narrow) == 0:
        return which, width
    squared, nearest, _ = igl.point_mesh_squared_distance(
        np.ascontiguousarray(centre, dtype=np.float64),
        np.asarray(geometry.mesh.vertices, np.float64),
        np.ascontiguousarray(geometry.mesh.faces[narrow], dtype=np.int64),
    )
    facet = narrow[nearest]
    near = (np.sqrt(squared) <= longest) & (widths[facet] < NARROW * longest)
    which[near], width[near] = facet[near], widths[facet[near]]
    return which, width


def forced_flat(corners: np.ndarray, geometry, features, found: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cusp (t,), narrow facet (t,), its width (t,)): for each tetrahedron (``corners`` (t, 4, 3)) the cusp in
    ``found`` (:func:`cusps`) it is next to (:func:`next_to_cusps`) and the facet of a narrow face next to it
    (:func:`next_to_narrow_faces`, looked for only where there is no cusp), -1 where none."""
    cusp = next_to_cusps(corners, features, found)
    narrow, width = np.full(len(corners), -1), np.full(len(corners), np.inf)
    alone = np.flatnonzero(cusp < 0)
    if len(alone):
        narrow[alone], width[alone] = next_to_narrow_faces(corners[alone], geometry, features)
    return cusp, narrow, width


def forced_flat_clause(corners: np.ndarray, geometry, features, found: tuple, cause: tuple | None = None) -> str:
    """A clause naming the cusp (:func:`cusps`' ``found``) or the narrow face a tetrahedron (``corners`` (4, 3))
    is next to; ``cause`` its (cusp, facet, width) from :func:`forced_flat`, found here when not given; '' if
    none."""
    from .features import coordinates, describe

    cusp, facet, width = (
        (c[0] for c in forced_flat(corners[None], geometry, features, found)) if cause is None else cause
    )
    if cusp >= 0:
        at, curve, other, angle = found
        return (
            f", next to a cusp: {features.curves[curve[cusp]].id} and {features.curves[other[cusp]].id} leave the "
            f"corner at ({coordinates(at[cusp], float(np.abs(corners).max()))}) {angle[cusp]:.2g} deg apart, and "
            "the face between them is narrower than the elements there"
        )
    if facet >= 0:
        patch = features.patches[int(features.face_patch[facet])]
        return f", next to {describe(patch)}, {width:.3g} wide there: narrower than the elements"
    return ""


def _locate(point: np.ndarray, geometry, features) -> str:
    """``(x, y, z), near <patch description>``: the point and the patch of the input face nearest to it."""
    import igl

    from .features import describe

    _, face, _ = igl.point_mesh_squared_distance(
        point.reshape(1, 3), np.asarray(geometry.mesh.vertices, float), np.asarray(geometry.mesh.faces, np.int64)
    )
    patch = features.patches[int(features.face_patch[int(face[0])])]
    scale = max(float(np.abs(point).max()), geometry.scale)
    digits = max(3, int(np.ceil(np.log10(scale / (1e-4 * geometry.scale)))) if scale > 0 else 3)
    coordinates = ", ".join(f"{c:.{digits}g}" for c in point)
    return f"({coordinates}) near {describe(patch)}"


def mixed_faces(mixed) -> tuple[np.ndarray, np.ndarray]:
    """(faces (f, 4) outward, -1 as the 4th node of a triangle; owner type (f,)) of every cell of a hex-dominant
    mesh (engine/recombine.py ``MixedMesh``)."""
    from .recombine import CELL_FACES

    faces, kinds = [], []
    for kind, cells in enumerate(mixed.cells):
        for face in CELL_FACES[kind]:
            f = np.where(face >= 0, cells[:, np.maximum(face, 0)], -1)
            faces.append(f)
            kinds.append(np.full(len(f), kind))
    return np.concatenate(faces).reshape(-1, 4), np.concatenate(kinds)


def check_mixed(mixed, tet_volume: float, geometry, features, tolerances: Tolerances) -> dict:
    """The hex-dominant mesh's gate, after :func:`check_mesh` passed its tets: every cell's corner Jacobians
    positive and, for hexahedra, prisms and pyramids, its scaled Jacobian at least ``hex_jacobian``; conforming
    (every face of at most two cells, no triangle on a quad face: no hanging faces); the boundary (its quads split
    along a diagonal) a closed two-manifold; the volume the tets' to 1e-9. Returns the boundary's figures."""
    from .recombine import CELL_TYPES

    def where(point) -> str:
        return _locate(np.asarray(point, dtype=float), geometry, features)

    for kind, (cells, quality) in enumerate(zip(mixed.cells, mixed.qualities())):
        floor = tolerances.hex_jacobian if kind < 3 else 0.0
        if len(quality) and not quality.min() > 0 or len(quality) and not quality.min() >= floor:
            worst = int(np.argmin(quality))
            raise MeshRejected(
                f"a {CELL_TYPES[kind]} has a scaled corner Jacobian of {quality[worst]:.3g} (floor {floor:g}) at "
                f"{where(mixed.points[cells[worst]].mean(axis=0))}",
                check="cell validity",
                fix=f"lower acceptance.hex_jacobian in the sizing defaults, or mesh tetrahedra; {KEEP_INVALID}",
            )
    faces, _ = mixed_faces(mixed)
    key = np.sort(faces, axis=1)  # a triangle's -1 sorts first
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    problem = None
    if (counts > 2).any():
        problem = f"{int((counts > 2).sum())} faces shared by more than two cells", faces[counts[inverse] > 2][0]
    quads = faces[faces[:, 3] >= 0]
    triangles = faces[faces[:, 3] < 0][:, :3]
    halves = np.sort(quads[:, [0, 1, 2, 0, 1, 3, 0, 2, 3, 1, 2, 3]].reshape(-1, 3), axis=1)
    sorted_triangles = np.sort(triangles, axis=1)
    if problem is None and len(halves) and len(triangles):
        both = np.vstack([halves, sorted_triangles])
        _, first = np.unique(both, axis=0, return_inverse=True)
        first = first.ravel()
        hanging = np.isin(first[len(halves) :], first[: len(halves)])
        if hanging.any():
            problem = f"{int(hanging.sum())} triangles lying on quad faces (hanging)", triangles[hanging][0]
    if problem is not None:
        raise MeshRejected(
            f"the hex-dominant mesh does not conform: {problem[0]}, e.g. at "
            f"{where(mixed.points[problem[1][problem[1] >= 0]].mean(axis=0))}",
            check="conforming cells",
            fix=f"mesh tetrahedra (output.elements) and report the input; {KEEP_INVALID}",
        )
    single = faces[counts[inverse] == 1]
    quad = single[:, 3] >= 0
    boundary = np.vstack([single[~quad, :3], single[quad][:, [0, 1, 2]], single[quad][:, [0, 2, 3]]])
    directed = boundary[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    undirected, edge_counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    same_way, way_counts = np.unique(directed, axis=0, return_counts=True)
    if (edge_counts != 2).any() or (way_counts > 1).any():
        bad = undirected[edge_counts != 2][:1, 0] if (edge_counts != 2).any() else same_way[way_counts > 1][:1, 0]
        raise MeshRejected(
            f"the hex-dominant mesh's boundary is not a closed two-manifold, e.g. at {where(mixed.points[bad[0]])}",
            check="closed two-manifold boundary",
            fix=f"mesh tetrahedra (output.elements) and report the input; {KEEP_INVALID}",
        )
    volume = sum(float(v.sum()) for v in mixed.volumes())
    if not abs(volume / tet_volume - 1) <= 1e-9:
        raise MeshRejected(
            f"the hex-dominant mesh's volume is {100 * (volume / tet_volume - 1):+.3g} % of its tets'",
            check="volume",
            fix=f"mesh tetrahedra (output.elements) and report the input; {KEEP_INVALID}",
        )
    return {"boundary_quads": int(quad.sum()), "boundary_triangles": int((~quad).sum()), "volume": volume}
