"""The hex-dominant mesh as the files hold it (issue 23): the summary of its cells, its groups (boundary groups
with quads), and the VTU, Gmsh and Abaqus writers of its hexahedra, prisms, pyramids and tetrahedra."""

from __future__ import annotations

from dataclasses import dataclass, field

import meshio
import numpy as np

from .recombine import CELL_FACES, CELL_TYPES, PYRAMID, MixedMesh

ABAQUS_TYPES = ("C3D8", "C3D6", "C3D5", "C3D4")
# Abaqus element faces (S1, S2, ...) by their nodes (0-based, meshio order)
ABAQUS_FACES = (
    [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]],
    [[0, 1, 2], [3, 5, 4], [0, 3, 4, 1], [1, 4, 5, 2], [2, 5, 3, 0]],
    [[0, 1, 2, 3], [0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]],
    [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]],
)


def summary(mixed: MixedMesh) -> dict:
    """Per cell type: count, volume, share of the volume, scaled corner Jacobian (min, 1st percentile); the
    recombination's counts and times."""
    volumes, qualities = mixed.volumes(), mixed.qualities()
    total = sum(float(v.sum()) for v in volumes)
    out = {}
    for kind, name in enumerate(CELL_TYPES):
        q = qualities[kind]
        out[name] = {
            "cells": len(q),
            "volume": float(volumes[kind].sum()),
            "volume_share": float(volumes[kind].sum() / total),
            "scaled_jacobian": {"min": float(q.min()), "p01": float(np.percentile(q, 1))} if len(q) else None,
        }
    return {"cells": out, "hex_volume_share": out["hexahedron"]["volume_share"], "recombination": mixed.stats}


@dataclass
class MixedGroup:
    name: str
    dim: int
    cells: list  # dim 3: per cell type the cell indices; dim 2: [triangles (k, 3), quads (k, 4)]; else (k, d)

    @property
    def nodes(self) -> np.ndarray:
        if self.dim == 3:
            return np.array([], np.int64)
        if self.dim == 2:
            return np.unique(np.concatenate([c.ravel() for c in self.cells]))
        return np.unique(self.cells)


@dataclass
class MixedModel:
    cells: list  # per cell type (meshio order)
    cell_data: dict = field(default_factory=dict)  # name -> per cell type
    groups: list = field(default_factory=list)


def boundary_quads(mixed: MixedMesh) -> np.ndarray:
    """(q, 4) the quad faces of one cell only."""
    quads = []
    for kind, cells in enumerate(mixed.cells):
        for face in CELL_FACES[kind]:
            if face[3] >= 0:
                quads.append(cells[:, face])
    quads = np.concatenate(quads).reshape(-1, 4)
    _, index, counts = np.unique(np.sort(quads, axis=1), axis=0, return_index=True, return_counts=True)
    return quads[np.sort(index[counts == 1])]


def mixed_model(mixed: MixedMesh, groups, cell_data: dict) -> MixedModel:
    """The groups of the tet mesh (engine.fe.feature_groups) and its per-tet ``cell_data`` carried to the cells:
    a solid group holds the cells whose parent tet it holds; a surface group's two triangles of a boundary quad
    become the quad."""
    quads = boundary_quads(mixed)
    halves = np.sort(quads[:, [0, 1, 2, 0, 2, 3, 0, 1, 3, 1, 2, 3]].reshape(-1, 3), axis=1)
    owner = np.repeat(np.arange(len(quads)), 4)
    lookup = {tuple(t): q for t, q in zip(halves.tolist(), owner.tolist())}
    out = []
    for group in groups:
        if group.dim == 3:
            member = np.zeros(max(int(np.concatenate(mixed.parents).max()), int(group.cells.max(initial=0))) + 1, bool)
            member[group.cells] = True
            out.append(MixedGroup(group.name, 3, [np.flatnonzero(member[p]) for p in mixed.parents]))
        elif group.dim == 2:
            q = np.array([lookup.get(tuple(t), -1) for t in np.sort(group.cells, axis=1).tolist()], np.int64)
            on = np.unique(q[q >= 0])
            out.append(MixedGroup(group.name, 2, [group.cells[q < 0], quads[on]]))
        else:
            out.append(MixedGroup(group.name, group.dim, group.cells))
    data = {name: [values[p] for p in mixed.parents] for name, values in cell_data.items()}
    return MixedModel(mixed.cells, data, out)


def _blocks(model):
    """The non-empty cell blocks (meshio's VTU writer fails on an empty one: an all-hexahedra mesh)."""
    return [(CELL_TYPES[k], c.astype(np.int64)) for k, c in enumerate(model.mixed.cells) if len(c)]


def _point_data(model, audit: bool) -> dict:
    data = {"node_level": model.node_level.astype(np.int32), "node_entity": model.node_entity.astype(np.int32)}
    if audit:
        data.update(model.point_data)
    return data


def write_vtu(path, model) -> None:
    """VTU: hexahedron, wedge, pyramid and tetra blocks, the node tags and the audit fields per cell."""
    present = [k for k, c in enumerate(model.mixed.cells) if len(c)]
    cell_data = {
        name: [values[k].astype(np.int64) if values[k].dtype.kind in "iu" else values[k] for k in present]
        for name, values in model.mixed.cell_data.items()
    }
    mesh = meshio.Mesh(model.points, _blocks(model), point_data=_point_data(model, True), cell_data=cell_data)
    meshio.write(path, mesh, file_format="vtu")


def write_gmsh(path, model) -> None:
    """Gmsh 2.2 binary: every group's cells (hexahedra ... tetrahedra; triangles and quads; lines; vertices)
    with its physical group."""
    cells, physical, field_data = [], [], {}
    kinds = {1: "line", 0: "vertex"}
    for tag, group in enumerate(model.mixed.groups, start=1):
        if group.dim == 3:
            blocks = [(CELL_TYPES[k], model.mixed.cells[k][i]) for k, i in enumerate(group.cells)]
        elif group.dim == 2:
            blocks = [("triangle", group.cells[0]), ("quad", group.cells[1])]
        else:
            blocks = [(kinds[group.dim], group.cells)]
        for kind, data in blocks:
            if len(data):
                cells.append((kind, np.asarray(data, np.int64)))
                physical.append(np.full(len(data), tag, dtype=np.int32))
        field_data[group.name] = np.array([tag, group.dim])
    if not cells:
        cells = _blocks(model)
        physical = [np.ones(len(c), np.int32) for _, c in cells]
    mesh = meshio.Mesh(
        model.points,
        cells,
        cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
        field_data=field_data,
        point_data=_point_data(model, False),
    )
    meshio.write(path, mesh, file_format="gmsh22", binary=True)


def write_abaqus(path, model, name=lambda s: s) -> None:
    """Abaqus input: C3D8, C3D6, C3D5 and C3D4 elements (numbered in that order), a node set per group, an
    element set per solid group, and an element-face surface per surface group (quads on S-faces of four
    nodes)."""
    lines = ["*HEADING", "fuzzymesh hex-dominant mesh", "*NODE"]
    lines += [f"{i},{x:.17g},{y:.17g},{z:.17g}" for i, (x, y, z) in enumerate(model.points.tolist(), start=1)]
    first, offset = [], 1
    for kind, cells in enumerate(model.mixed.cells):
        first.append(offset)
        if len(cells):
            lines.append(f"*ELEMENT, TYPE={ABAQUS_TYPES[kind]}")
            rows = np.column_stack([np.arange(offset, offset + len(cells)), cells + 1])
            lines += [",".join(map(str, row)) for row in rows.tolist()]
        offset += len(cells)
    face_lookup = {}
    for kind, cells in enumerate(model.mixed.cells):
        for s, face in enumerate(ABAQUS_FACES[kind], start=1):
            keys = np.sort(cells[:, face], axis=1)
            for element, key in enumerate(keys.tolist()):
                face_lookup.setdefault(tuple(key), (first[kind] + element, s))
    for group in model.mixed.groups:
        label = name(group.name)
        if group.dim == 3:
            elements = np.concatenate([first[k] + np.asarray(i, np.int64) for k, i in enumerate(group.cells)])
            lines.append(f"*ELSET, ELSET={label}")
            lines += [",".join(map(str, elements[i : i + 16].tolist())) for i in range(0, len(elements), 16)]
            continue
        nodes = group.nodes + 1
        lines.append(f"*NSET, NSET={label}")
        lines += [",".join(map(str, nodes[i : i + 16].tolist())) for i in range(0, len(nodes), 16)]
        if group.dim == 2:
            faces = {}
            for part in group.cells:
                for key in np.sort(part, axis=1).tolist():
                    element, s = face_lookup[tuple(key)]
                    faces.setdefault(s, []).append(element)
            for s, elements in sorted(faces.items()):
                lines.append(f"*ELSET, ELSET=_{label}_S{s}, INTERNAL")
                lines += [",".join(map(str, elements[i : i + 16])) for i in range(0, len(elements), 16)]
            lines.append(f"*SURFACE, TYPE=ELEMENT, NAME={label}")
            lines += [f"_{label}_S{s}, S{s}" for s in sorted(faces)]
    with open(path, "w") as handle:
        handle.write("\n".join(lines) + "\n")


__all__ = ["summary", "mixed_model", "write_vtu", "write_gmsh", "write_abaqus", "PYRAMID"]
