"""Touching solids of a CAD file (an assembly): each solid meshed, one conforming mesh.

OpenCASCADE's fragment (engine/cad.py) makes every face two solids touch along one face of both; each solid
has its own (Geometry, Features), the shared face a patch of both. The bodies are meshed one after another by
the ``delaunay`` mesher, all with the union's sizing field: the first body to mesh a shared face triangulates
it as any patch; a later body takes those triangles (reversed) and their nodes as they are
(``mesh_delaunay(prescribed=...)``: held through the improvement, its peels and collapses), so both sides of
the interface are the same triangles on the same nodes, merged into one node each. The merged mesh's nodes
and boundary faces are tagged with the union's features (by the CAD face and edge tags); the interface's
own nodes are volume nodes of the union. ``TetMesh.body`` holds each tet's body and ``TetMesh.interfaces``
the interface triangles by name.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from .fe import side_cells, tet_boundary
from .levels import CORNER, CURVE, PATCH, STEINER, VOLUME
from .mesh import TetMesh
from .packing import Packing

CLEARANCE = 0.5  # x h: a later body's volume nodes closer than this to a node of a prescribed interface go
SAME_POINT = 1e-9  # x the model size: two nodes this close are one


def mesh_assembly(packer, mesher, geometry, features, sizing, *, seed: int = 0, knowledge=None):
    """(TetMesh, Packing) of the assembly ``features.assembly`` (module docstring); ``geometry``, ``features``:
    the union's, ``sizing`` its sizing field; ``mesher`` the ``delaunay`` mesher."""
    assembly = features.assembly
    tol = SAME_POINT * geometry.scale
    merged = _Merged()
    done: dict = {}  # frozenset of CAD face tags -> (k, 3) merged node indices, outward for the body that meshed it
    packings, offset = [], 0
    corners = [np.array([g.vertices[c.vertex] for c in f.corners]).reshape(-1, 3) for g, f in assembly.bodies]
    for b, (body_geometry, body_features) in enumerate(assembly.bodies):
        patch_faces, curve_edges = assembly.patch_faces[b], assembly.curve_edges[b]
        packing = packer(body_geometry, body_features, sizing, seed=seed, knowledge=knowledge)
        packing = _on_corners(packing, body_geometry, body_features, corners[:b] + corners[b + 1 :], tol)
        keys = [frozenset(f) for f in patch_faces]
        imposed = [(p, done[k]) for p, k in enumerate(keys) if k in done]
        prescribed, held = None, np.zeros(0, np.int64)
        if imposed:
            packing, prescribed, held = _impose(
                packing, body_geometry, body_features, keys, curve_edges, imposed, merged
            )
        mesh = mesher(packing, body_geometry, body_features, seed=seed, prescribed=prescribed)
        index = merged.add(mesh, b, held, tol, body_geometry, body_features, keys, curve_edges, offset)
        owner, side, face_patch = tet_boundary(mesh)
        faces = index[side_cells(mesh.tets, owner, side)]  # the tets' own faces, which the next body takes
        for p, key in enumerate(keys):
            if key <= assembly.shared_faces:
                mine = faces[face_patch == p]
                if key in done:
                    if not _same_triangles(mine, done[key][:, ::-1]):
                        raise RuntimeError(f"the interface {sorted(key)} lost its prescribed triangles")
                else:
                    done[key] = mine
        offset += int(packing.ids.max()) + 1 if packing.ids is not None and len(packing.ids) else 0
        packings.append(packing)
    interfaces = {
        interface.name: np.concatenate(
            [t for key, t in done.items() if key <= set(interface.faces)] or [np.zeros((0, 3), np.int64)]
        )
        for interface in assembly.interfaces
    }
    return merged.mesh(geometry, features, assembly, interfaces), _packing(packings)


class _Merged:
    """The merged nodes, tets and boundary, body by body; each body's node tags by CAD face and edge tags."""

    def __init__(self):
        self.points = np.zeros((0, 3))
        self.tags = []  # per node: (level in its body, CAD tags: frozenset of face / edge tags, or None)
        self.bubble = np.zeros(0, np.int64)
        self.tets, self.body, self.boundary, self.boundary_tags = [], [], [], []
        self.stats = []

    def add(self, mesh, b, held, tol, geometry, features, keys, curve_edges, offset) -> np.ndarray:
        """Merged index of each of ``mesh``'s nodes (those at ``held``, merged nodes of a prescribed interface,
        found by position; the others new)."""
        index = np.full(len(mesh.points), -1, np.int64)
        if len(held):
            distance, nearest = cKDTree(mesh.points).query(self.points[held])
            if (distance > tol).any():
                raise RuntimeError(f"{int((distance > tol).sum())} interface nodes moved or left the mesh")
            index[nearest] = held
        new = np.flatnonzero(index < 0)
        index[new] = len(self.points) + np.arange(len(new))
        self.points = np.vstack([self.points, mesh.points[new]])
        for node in new:
            level, entity = int(mesh.node_level[node]), int(mesh.node_entity[node])
            key = None
            if level == PATCH and entity >= 0:
                key = keys[entity]
            elif level == CURVE and entity >= 0:
                key = frozenset(curve_edges[entity])
            self.tags.append((level, key))
        bubble = mesh.node_bubble[new] if mesh.node_bubble is not None else np.full(len(new), -1)
        self.bubble = np.concatenate([self.bubble, np.where(bubble >= 0, bubble + offset, -1)])
        self.tets.append(index[mesh.tets])
        self.body.append(np.full(len(mesh.tets), b, np.int64))
        self.boundary.append(index[mesh.boundary])
        self.boundary_tags.append([keys[p] for p in mesh.boundary_patch])
        self.stats.append(mesh.stats)
        return index

    def mesh(self, geometry, features, assembly, interfaces) -> TetMesh:
        """The merged TetMesh, tagged with the union's features; the interface triangles leave the boundary."""
        patch_of = {frozenset(f): p for p, f in enumerate(assembly.union_patch_faces)}
        edge_curve = {}
        for c, edges in enumerate(assembly.union_curve_edges):
            for edge in edges:
                edge_curve.setdefault(edge, c)
        corners = np.array([geometry.vertices[c.vertex] for c in features.corners]).reshape(-1, 3)
        corner_at = cKDTree(corners) if len(corners) else None
        tol = SAME_POINT * geometry.scale
        n = len(self.points)
        level, entity = np.full(n, VOLUME, np.int8), np.full(n, -1, np.int64)
        for node, (body_level, key) in enumerate(self.tags):
            if body_level == STEINER:
                level[node] = STEINER
            elif body_level == PATCH and key is not None and key in patch_of:
                level[node], entity[node] = PATCH, patch_of[key]
            elif body_level in (CURVE, CORNER):
                if corner_at is not None and (hit := corner_at.query(self.points[node]))[0] <= tol:
                    level[node], entity[node] = CORNER, hit[1]
                elif body_level == CURVE and (curves := {edge_curve[e] for e in key if e in edge_curve}):
                    level[node], entity[node] = CURVE, _nearest_curve(features, curves, self.points[node])
        # a node left in the volume that lies on the union's surface (a corner of one body only): its patch
        on_surface = np.flatnonzero((level == VOLUME) & (geometry.closest_point(self.points)[1] <= tol))
        if len(on_surface):
            face = geometry.closest_point(self.points[on_surface])[2]
            level[on_surface], entity[on_surface] = PATCH, features.face_patch[face]
        boundary = np.concatenate(self.boundary)
        keys = [k for tags in self.boundary_tags for k in tags]
        outer = np.array([k in patch_of for k in keys], bool)
        patch = np.array([patch_of.get(k, -1) for k in keys], np.int64)
        order = np.argsort(patch[outer], kind="stable")
        stats = {
            "bodies": len(self.stats),
            "interface_triangles": int(sum(len(t) for t in interfaces.values())),
            "boundary_triangles": int(outer.sum()),  # the outer ones (each body's include its interfaces)
            **{
                key: sum(s.get(key, 0) for s in self.stats)
                for key in ("steiner_points", "relocated_nodes", "nodes_collapsed")
            },
            "min_dihedral_before_improvement": min(s.get("min_dihedral_before_improvement", 180.0) for s in self.stats),
            "seconds": {
                key: round(sum(s.get("seconds", {}).get(key, 0.0) for s in self.stats), 3)
                for key in ("surface", "connect", "improve")
            },
        }
        return TetMesh(
            points=self.points,
            tets=np.concatenate(self.tets),
            node_level=level,
            node_entity=entity,
            stats=stats,
            boundary=boundary[outer][order],
            boundary_patch=patch[outer][order],
            node_bubble=self.bubble,
            body=np.concatenate(self.body),
            interfaces=interfaces,
        )


def _impose(packing, geometry, features, keys, curve_edges, imposed, merged):
    """The body's packing with its own nodes on the ``imposed`` patches (patch index, merged triangles), on the
    curves along them and at their corners replaced by the merged interface nodes, and its volume nodes
    within CLEARANCE h of those gone; the prescribed (triangles, patch) in the new packing's indices; the
    merged indices of the interface nodes."""
    held = np.unique(np.concatenate([t.ravel() for _, t in imposed]))
    x = merged.points[held]
    tol = SAME_POINT * geometry.scale
    corners = np.array([geometry.vertices[c.vertex] for c in features.corners]).reshape(-1, 3)
    corner_distance, corner_index = (
        cKDTree(corners).query(x) if len(corners) else (np.full(len(x), np.inf), np.zeros(len(x), np.int64))
    )
    edge_curve = {}
    for c, edges in enumerate(curve_edges):
        for edge in edges:
            edge_curve.setdefault(edge, c)
    patch_of_node = {}
    for p, triangles in imposed:
        for node in np.unique(triangles):
            patch_of_node[int(node)] = p
    level, entity = np.empty(len(held), np.int8), np.empty(len(held), np.int64)
    for k, node in enumerate(held):
        body_level, key = merged.tags[node]
        if corner_distance[k] <= tol:
            level[k], entity[k] = CORNER, corner_index[k]
        elif body_level in (CURVE, CORNER) and key and (curves := {edge_curve[e] for e in key if e in edge_curve}):
            level[k], entity[k] = CURVE, _nearest_curve(features, curves, x[k])
        elif body_level == CORNER and (curve := _curve_through(features, x[k], tol)) >= 0:
            level[k], entity[k] = CURVE, curve  # a corner of the body that meshed it, on a curve of this one
        elif body_level == PATCH:
            level[k], entity[k] = PATCH, patch_of_node[int(node)]
        else:
            raise RuntimeError(f"an interface node at {x[k]} is on no curve or corner of the next body")
    curves = np.unique(entity[level == CURVE])
    corner_nodes = np.unique(entity[level == CORNER])
    patches = [p for p, _ in imposed]
    h = 2 * packing.radius
    near = cKDTree(x).query(packing.points)[0] < CLEARANCE * h
    drop = (
        ((packing.level == PATCH) & np.isin(packing.entity, patches))
        | ((packing.level == CURVE) & np.isin(packing.entity, curves))
        | ((packing.level == CORNER) & np.isin(packing.entity, corner_nodes))
        | ((packing.level == VOLUME) & near)
    )
    kept = np.flatnonzero(~drop)
    given = Packing(
        points=packing.points[kept],
        level=packing.level[kept],
        entity=packing.entity[kept],
        radius=packing.radius[kept],
        stats=packing.stats,
        ids=packing.ids[kept] if packing.ids is not None else None,
        events=packing.events,
    )
    interface = Packing(points=x, level=level, entity=entity, radius=_radius(packing, x), ids=np.full(len(x), -1))
    out = Packing.concatenate([given, interface], packing.stats, events=packing.events)
    local = np.full(int(held.max()) + 1, -1, np.int64)
    local[held] = len(kept) + np.arange(len(held))
    triangles = np.concatenate([local[t][:, ::-1] for _, t in imposed])
    patch = np.concatenate([np.full(len(t), p) for p, t in imposed])
    return out, (triangles, patch), held


def _on_corners(packing, geometry, features, others: list, tol: float):
    """The packing with a node of each of its curves that passes through a corner of another body (``others``:
    their corner points), not one of its own, moved onto that corner: where a bolt head's rim touches the
    bracket's edge, the bracket has a corner on the rim and the head none; the interface both share must have a
    node there, whichever body meshes it first. The curve's node nearest to the corner moves."""
    own = np.array([geometry.vertices[c.vertex] for c in features.corners]).reshape(-1, 3)
    points, moved = packing.points.copy(), np.zeros(len(packing), bool)
    for x in np.unique(np.concatenate([np.zeros((0, 3)), *others]), axis=0):
        if len(own) and np.linalg.norm(own - x, axis=1).min() <= tol:
            continue
        curve = _curve_through(features, x, tol)
        nodes = np.flatnonzero((packing.level == CURVE) & (packing.entity == curve) & ~moved)
        if curve < 0 or not len(nodes):
            continue
        nearest = nodes[np.argmin(np.linalg.norm(points[nodes] - x, axis=1))]
        points[nearest], moved[nearest] = x, True
    return dataclasses.replace(packing, points=points) if moved.any() else packing


def _curve_through(features, x: np.ndarray, tol: float) -> int:
    """The first feature curve whose polyline passes within ``tol`` of the point ``x``, else -1 (a corner of
    one body where the other's curve runs straight on: the square rim of a face one body shares with a
    coplanar face of the other)."""
    for c, curve in enumerate(features.curves):
        if _distance(curve, x) <= tol:
            return c
    return -1


def _nearest_curve(features, curves: set, x: np.ndarray) -> int:
    """Of the ``curves`` (indices) a node's CAD edges map to, the one nearest to it: one body's curve may run
    along several CAD edges that are curves of their own in the other (a nut's rim, one closed curve of the
    plate it is pressed against, four sides of the nut)."""
    return min(sorted(curves), key=lambda c: _distance(features.curves[c], x))


def _distance(curve, x: np.ndarray) -> float:
    """The distance of the point ``x`` from the curve's polyline."""
    a = curve.points
    b = np.roll(a, -1, axis=0) if curve.closed else a[1:]
    a = a if curve.closed else a[:-1]
    if not len(a):
        return float(np.linalg.norm(curve.points - x, axis=1).min())
    span = b - a
    t = np.clip(((x - a) * span).sum(axis=1) / np.maximum((span * span).sum(axis=1), 1e-300), 0.0, 1.0)
    return float(np.linalg.norm(a + t[:, None] * span - x, axis=1).min())


def _radius(packing, x) -> np.ndarray:
    """Half the target size at ``x``: the packing's radius of the nearest node (the same sizing field)."""
    return packing.radius[cKDTree(packing.points).query(x)[1]]


def _same_triangles(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two sets of triangles are the same, orientation included (up to rotation of each)."""

    def canonical(t):
        t = np.asarray(t).reshape(-1, 3)
        shift = np.argmin(t, axis=1)
        rolled = np.stack([np.roll(row, -s) for row, s in zip(t, shift)]) if len(t) else t
        return np.unique(rolled, axis=0)

    return len(a) == len(b) and np.array_equal(canonical(a), canonical(b))


def _packing(packings: list) -> Packing:
    """The bodies' packings as one, bubble ids (and the events citing them) offset body by body."""
    parts, offset, events = [], 0, []
    for packing in packings:
        ids = packing.ids if packing.ids is not None else np.full(len(packing), -1)
        parts.append(
            Packing(
                points=packing.points,
                level=packing.level,
                entity=packing.entity,
                radius=packing.radius,
                ids=np.where(ids >= 0, ids + offset, -1),
            )
        )
        moved = packing.events.copy()
        moved.bubble = moved.bubble + offset
        events.append(moved)
        offset += int(ids.max()) + 1 if len(ids) else 0
    return Packing.concatenate(
        parts,
        {"bodies": [p.stats for p in packings]},
        events=np.concatenate(events).view(np.recarray) if events else None,
    )
