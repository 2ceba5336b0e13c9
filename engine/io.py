"""Writing meshes through meshio, atomically (temporary file + rename)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import meshio
import numpy as np

from .atomic import Target
from .fe import TET10_EDGES, row_index, side_cells, tet_boundary
from .hexdom import write_abaqus as _mixed_abaqus
from .hexdom import write_gmsh as _mixed_gmsh
from .hexdom import write_vtu as _mixed_vtu
from .mesh import TetMesh
from .plugins import Writer
from .registry import Registry
from .topology import face_owners

ABAQUS_FACE = {3: "S1", 2: "S2", 0: "S3", 1: "S4"}  # C3D4/C3D10 face by the local index of the opposite node
WRITERS = Registry(None, [], Writer, noun="writer")  # one per output format: @WRITERS.register("vtu") below


@dataclass(frozen=True, kw_only=True)
class FEModel:
    """What the files hold: nodes, linear or quadratic tets, the boundary and the named groups. A frozen value,
    built complete by :meth:`build`; a hex-dominant mesh's model is a ``dataclasses.replace`` copy of it."""

    points: np.ndarray
    tets: np.ndarray  # (m, 4) or (m, 10)
    boundary: np.ndarray  # (t, 3) or (t, 6): the tets' own faces, outward (engine.fe.tet_boundary)
    node_level: np.ndarray  # -1 for mid-edge nodes
    node_entity: np.ndarray
    groups: list = field(default_factory=list)
    cell_data: dict = field(default_factory=dict)  # per element (the audit)
    point_data: dict = field(default_factory=dict)  # per node (the audit; -1 / 0 on mid-edge nodes)
    legend: dict | None = None  # the audit legend, written as <name>.audit.json
    mixed: object | None = None  # a hex-dominant mesh's cells, data and groups (engine.hexdom.MixedModel)

    @staticmethod
    def build(mesh: TetMesh, *, groups=(), quadratic=None, audit=None, cell_data=None) -> "FEModel":
        """``quadratic``: (points, tets10, triangle6) from engine.fe.quadratic, or None for linear; ``cell_data``:
        more per-element fields, after the audit's."""
        if quadratic is None:
            quadratic = mesh.points, mesh.tets, side_cells(mesh.tets, *tet_boundary(mesh)[:2])
        points, tets, boundary = quadratic
        extra = len(points) - len(mesh.points)

        def pad(values):
            return np.r_[values, np.full(extra, -1 if values.dtype.kind in "iu" else 0, dtype=values.dtype)]

        point_data = {k: pad(v) for k, v in audit.nodes.items()} if audit else {}
        return FEModel(
            points=points,
            tets=tets,
            boundary=boundary,
            node_level=pad(mesh.node_level),
            node_entity=pad(mesh.node_entity),
            groups=list(groups),
            cell_data={**(audit.cells if audit else {}), **(cell_data or {})},
            point_data=point_data,
            legend=audit.legend if audit else None,
        )

    @property
    def quadratic(self) -> bool:
        return self.tets.shape[1] == 10


def to_meshio(model: FEModel, audit: bool = False) -> meshio.Mesh:
    """The tetrahedra with node tags (for VTU and Abaqus), and with ``audit`` the audit fields."""
    point_data = {"node_level": model.node_level.astype(np.int32), "node_entity": model.node_entity.astype(np.int32)}
    cell_data = {}
    if audit:
        point_data.update(model.point_data)
        cell_data = {name: [values] for name, values in model.cell_data.items()}
    return meshio.Mesh(
        model.points,
        [("tetra10" if model.quadratic else "tetra", model.tets.astype(np.int64))],
        point_data=point_data,
        cell_data=cell_data,
    )


def to_med(model: FEModel) -> meshio.Mesh:
    """The VTU's tetrahedra and fields with the element groups (``solid``, ``solid-1``, ...) as MED families, and
    the face groups (patches, named surfaces, an assembly's interfaces) as families of one triangle section (for
    boundary conditions in Code_Aster or Salome); a face carries the fields of a tet it bounds."""
    data = to_meshio(model, audit=True)
    solids = [g for g in model.groups if g.dim == 3]
    faces = [g for g in model.groups if g.dim == 2]
    tet_family, data.cell_tags = _families(solids, [g.cells for g in solids], len(model.tets), first=-1)
    if not faces:
        if solids:
            data.cell_data["cell_tags"] = [tet_family]
        return data
    cells = [_group_cells(model, g) for g in faces]
    every = np.concatenate(cells)
    _, first, which = np.unique(np.sort(every[:, :3], axis=1), axis=0, return_index=True, return_inverse=True)
    ends = np.cumsum([0] + [len(c) for c in cells])
    members = [which.ravel()[a:b] for a, b in zip(ends[:-1], ends[1:])]
    face_family, face_tags = _families(faces, members, len(first), first=-1 - len(data.cell_tags))
    data.cell_tags.update(face_tags)
    owner, _ = face_owners(model.tets[:, :4], len(model.points), every[first, :3])
    with_faces = meshio.Mesh(
        data.points,
        [*data.cells, ("triangle6" if model.quadratic else "triangle", every[first])],
        point_data=data.point_data,
        cell_data={"cell_tags": [tet_family, face_family]}
        | {name: [values[0], values[0][owner]] for name, values in data.cell_data.items()},
    )
    with_faces.cell_tags = data.cell_tags  # meshio's MED writer reads the family names from here
    return with_faces


def _families(groups: list, members: list[np.ndarray], count: int, first: int) -> tuple[np.ndarray, dict]:
    """MED families of ``count`` cells, ``members[k]`` (indices) the cells of ``groups[k]``: (count,) family
    numbers (``first``, ``first`` - 1, ... one per combination of groups, 0 for a cell in none) and
    {family number: its group names}."""
    member = np.zeros((count, len(groups)), dtype=bool)
    for k, cells in enumerate(members):
        member[cells, k] = True
    combinations, family = np.unique(member, axis=0, return_inverse=True)
    named = combinations.any(axis=1)
    numbers = np.where(named, first + 1 - np.cumsum(named), 0)
    tags = {
        int(numbers[f]): [g.name for g, m in zip(groups, row) if m] for f, row in enumerate(combinations) if named[f]
    }
    return numbers[family.ravel()], tags


def to_gmsh(model: FEModel) -> meshio.Mesh:
    """Tets and every group's cells, tagged with its physical group (named in field_data)."""
    q = model.quadratic
    kinds = {
        3: "tetra10" if q else "tetra",
        2: "triangle6" if q else "triangle",
        1: "line3" if q else "line",
        0: "vertex",
    }
    cells, physical, field_data = [], [], {}
    for tag, group in enumerate(model.groups or [], start=1):
        data = model.tets[group.cells] if group.dim == 3 else _group_cells(model, group)
        cells.append((kinds[group.dim], data.astype(np.int64)))
        physical.append(np.full(len(data), tag, dtype=np.int32))
        field_data[group.name] = np.array([tag, group.dim])
    if not cells:
        cells, physical = [(kinds[3], model.tets.astype(np.int64))], [np.ones(len(model.tets), np.int32)]
    return meshio.Mesh(
        model.points,
        cells,
        cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
        field_data=field_data,
        point_data={"node_level": model.node_level.astype(np.int32), "node_entity": model.node_entity.astype(np.int32)},
    )


def _group_cells(model: FEModel, group) -> np.ndarray:
    """A lower-dimensional group's cells, with mid-edge nodes for a quadratic model: a boundary face's from the
    boundary's triangle6, an inner face's (an assembly's interface) from its tets' edges, as given."""
    if not model.quadratic or group.dim == 0:
        return group.cells
    if group.dim == 2:
        rows = row_index(np.sort(model.boundary[:, :3], axis=1), np.sort(group.cells, axis=1))
        if (rows >= 0).all():
            return model.boundary[rows]
        ends = np.stack([group.cells, np.roll(group.cells, -1, axis=1)], axis=2).reshape(-1, 2)  # (a b), (b c), (c a)
        return np.column_stack([group.cells, _middles(model, ends).reshape(-1, 3)])
    return np.column_stack([group.cells, _middles(model, group.cells)])


def _middles(model: FEModel, ends: np.ndarray) -> np.ndarray:
    """The mid-edge node of each edge ``ends`` (k, 2) of a quadratic model's tets."""
    edges = np.sort(model.tets[:, TET10_EDGES].reshape(-1, 2), axis=1)
    rows = row_index(edges, np.sort(ends, axis=1))
    return model.tets[:, 4:].reshape(-1)[rows]


@WRITERS.register("vtu")
def write_vtu(path, model: FEModel) -> None:
    """VTU (ParaView): the tetrahedra with node tags and the audit fields."""
    if model.mixed is not None:
        return _mixed_vtu(path, model)
    meshio.write(path, to_meshio(model, audit=True), file_format="vtu")


@WRITERS.register("msh")
def write_gmsh(path, model: FEModel) -> None:
    """Gmsh 2.2 binary: tets and every group's cells with their physical groups."""
    if model.mixed is not None:
        return _mixed_gmsh(path, model)
    meshio.write(path, to_gmsh(model), file_format="gmsh22", binary=True)


@WRITERS.register("med")
def write_med(path, model: FEModel) -> None:
    """MED (Salome, code_aster): the VTU's tetrahedra and fields, the element groups as families."""
    meshio.write(path, to_med(model), file_format="med")


@WRITERS.register("inp")
def write_abaqus(path, model: FEModel) -> None:
    """Abaqus input: C3D4/C3D10 elements, a node set per group, the solid's element set, and an
    element-face surface per surface group (for loads and contact)."""
    if model.mixed is not None:
        return _mixed_abaqus(path, model, _abaqus_name)
    data = to_meshio(model)
    data.point_sets = {_abaqus_name(g.name): g.nodes for g in model.groups if g.dim < 3}
    data.cell_sets = {_abaqus_name(g.name): [g.cells] for g in model.groups if g.dim == 3}
    meshio.write(path, data, file_format="abaqus")
    corner_tets = model.tets[:, :4]
    lines = []
    for group in (g for g in model.groups if g.dim == 2):
        owner, opposite = face_owners(corner_tets, len(model.points), group.cells)
        name = _abaqus_name(group.name)
        for local, face in ABAQUS_FACE.items():
            elements = owner[opposite == local] + 1
            if len(elements):
                lines.append(f"*ELSET, ELSET=_{name}_{face}, INTERNAL")
                lines += [",".join(map(str, elements[i : i + 16])) for i in range(0, len(elements), 16)]
        lines.append(f"*SURFACE, TYPE=ELEMENT, NAME={name}")
        lines += [f"_{name}_{face}, {face}" for local, face in ABAQUS_FACE.items() if (opposite == local).any()]
    with open(path, "a") as handle:
        handle.write("\n".join(lines) + ("\n" if lines else ""))


@WRITERS.register("bdf")
def write_nastran(path, model: FEModel) -> None:
    """Nastran bulk data: GRID* (large field, 16-character reals) and CTETRA (4 or 10 nodes, PSOLID 1).

    Written here rather than by meshio, whose Nastran writer fails on negative
    reals with two-digit exponents (more than 16 characters).
    """
    ids = np.arange(1, len(model.points) + 1)
    with open(path, "w") as handle:
        handle.write("$ written by fuzzymesh\nBEGIN BULK\n")
        handle.writelines(
            f"GRID*   {i:>16d}{0:>16d}{x:>16.9E}{y:>16.9E}\n*       {z:>16.9E}\n"
            for i, (x, y, z) in zip(ids.tolist(), model.points.tolist())
        )
        nodes = model.tets + 1
        for e, row in enumerate(nodes.tolist(), start=1):
            head = "".join(f"{n:>8d}" for n in row[:6])
            tail = "".join(f"{n:>8d}" for n in row[6:])
            handle.write(f"CTETRA  {e:>8d}{1:>8d}{head}\n" + (f"+       {tail}\n" if tail else ""))
        handle.write("ENDDATA\n")


def _abaqus_name(name: str) -> str:
    return name.replace("-", "_").replace(" ", "_")


def mesh_targets(model: FEModel, directory: Path, name: str, formats: list[str]) -> list[Target]:
    """The files of ``model``: ``directory/name.<format>`` for each format and the audit legend
    ``name.audit.json``, as (path, write) targets for :func:`engine.atomic.write_all_or_nothing`."""
    targets = [(Path(directory) / f"{name}.{fmt}", partial(WRITERS.get(fmt), model=model)) for fmt in formats]
    if model.legend is not None:
        targets.append(
            (
                Path(directory) / f"{name}.audit.json",
                lambda tmp: Path(tmp).write_text(json.dumps(model.legend, indent=1)),
            )
        )
    return targets
