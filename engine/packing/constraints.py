"""Where bubbles of each level may move: along their curve, on their patch, inside the solid.

Each constraint projects positions back onto its entities after a step and
removes the normal part of forces and velocities (the tangent of a curve, the
tangent plane of a patch). Projection uses the entity's own segments or
triangles, so a bubble never crosses a feature curve onto another patch.
"""

from __future__ import annotations

import igl
import numpy as np


class _EntityProjection:
    """Closest points on each entity's simplices (segments or triangles), grouped by entity."""

    def __init__(self, vertices_by_entity: dict, simplices_by_entity: dict):
        self.vertices, self.simplices, self.trees = {}, {}, {}
        for key, simplices in simplices_by_entity.items():
            used, local = np.unique(simplices, return_inverse=True)
            self.vertices[key] = np.ascontiguousarray(vertices_by_entity[key][used], dtype=np.float64)
            self.simplices[key] = np.ascontiguousarray(local.reshape(simplices.shape), dtype=np.int64)

    def frame(self, x, entity):
        """Projected positions, and the per-simplex attribute (tangent or normal) where they land."""
        closest, simplex = self.closest(x, entity)
        attribute = np.empty_like(x)
        for key in np.unique(entity):
            rows = np.flatnonzero(entity == key)
            attribute[rows] = self.attribute[key][simplex[rows]]
        return closest, attribute

    def project(self, x, entity):
        return self.frame(x, entity)[0]

    def _tree(self, key):
        if key not in self.trees:  # built once per entity, reused at every step
            tree = igl.AABB()
            tree.init(self.vertices[key], self.simplices[key])
            self.trees[key] = tree
        return self.trees[key]

    def closest(self, x: np.ndarray, entity: np.ndarray):
        """Closest point on the bubble's own entity, and the index of the simplex it lies on."""
        out = np.empty_like(x)
        simplex = np.zeros(len(x), dtype=np.int64)
        order = np.argsort(entity, kind="stable")
        keys, starts = np.unique(entity[order], return_index=True)
        for key, rows in zip(keys, np.split(order, starts[1:])):
            _, index, closest = self._tree(key).squared_distance(
                self.vertices[key], self.simplices[key], np.ascontiguousarray(x[rows])
            )
            out[rows], simplex[rows] = closest, index
        return out, simplex


class CurveConstraint(_EntityProjection):
    """Bubbles slide along their feature curve."""

    def __init__(self, features):
        lines = {i: c.polyline for i, c in enumerate(features.curves) if c.on_surface}
        segments = {i: np.column_stack([np.arange(len(p) - 1), np.arange(1, len(p))]) for i, p in lines.items()}
        super().__init__(lines, segments)
        self.attribute = {}  # unit tangent of each segment
        for i, line in lines.items():
            d = np.diff(line, axis=0)
            self.attribute[i] = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)

    @staticmethod
    def tangential(vectors, tangent):
        return np.einsum("ij,ij->i", vectors, tangent)[:, None] * tangent


class PatchConstraint(_EntityProjection):
    """Bubbles slide on their surface patch."""

    def __init__(self, geometry, features):
        mesh = geometry.mesh
        faces = {i: mesh.faces[p.faces] for i, p in enumerate(features.patches)}
        super().__init__({i: mesh.vertices for i in faces}, faces)
        self.attribute = {i: mesh.face_normals[p.faces] for i, p in enumerate(features.patches)}  # unit normals

    @staticmethod
    def tangential(vectors, normal):
        return vectors - np.einsum("ij,ij->i", vectors, normal)[:, None] * normal


class VolumeConstraint:
    """Bubbles move freely but stay inside the solid (a move that leaves it is undone)."""

    def __init__(self, geometry):
        self.geometry = geometry

    def frame(self, x, entity):
        return x, None

    def project(self, x, entity):
        return x

    @staticmethod
    def tangential(vectors, frame):
        return vectors
