"""Regions a pattern can be placed in (a box, a sphere or a cylinder), checked and measured with numpy alone,
so that the knowledge base and lint validate them without a geometry library."""

from __future__ import annotations

import numpy as np

from .errors import KnowledgeError
from .schema import LIST, NUMBER, Field, check_value, positive


class RegionDistance:
    """Distance outside a box, sphere or cylinder (0 inside)."""

    def __init__(self, spec: dict, where: str):
        if not isinstance(spec, dict) or len(spec) != 1:
            raise KnowledgeError("a region is one of {box: ...}, {sphere: ...}, {cylinder: ...}", where=where)
        ((self.kind, body),) = spec.items()
        vec = Field(LIST, required=True, items=Field(NUMBER))
        fields = {
            "box": {"min": vec, "max": vec},
            "sphere": {"centre": vec, "radius": Field(NUMBER, required=True, check=positive)},
            "cylinder": {"start": vec, "end": vec, "radius": Field(NUMBER, required=True, check=positive)},
        }
        if self.kind not in fields:
            raise KnowledgeError(f"unknown region '{self.kind}'", where=where, fix="use box, sphere or cylinder")
        values = check_value(
            body, Field("mapping", fields=fields[self.kind]), f"region.{self.kind}", where, KnowledgeError
        )
        for key, value in values.items():
            if isinstance(value, list) and len(value) != 3:
                raise KnowledgeError(f"region.{self.kind}.{key} needs three coordinates", where=where)
        self.values = {k: np.asarray(v, dtype=float) for k, v in values.items()}
        if self.kind == "box" and np.any(self.values["max"] < self.values["min"]):
            raise KnowledgeError("region box needs min <= max on every axis", where=where)
        if self.kind == "cylinder" and np.allclose(self.values["start"], self.values["end"]):
            raise KnowledgeError("region cylinder needs start != end", where=where)
        v = self.values
        if self.kind == "box":
            self.lo, self.hi = v["min"], v["max"]
        elif self.kind == "sphere":
            self.lo, self.hi = v["centre"] - v["radius"], v["centre"] + v["radius"]
        else:
            ends = np.array([v["start"], v["end"]])
            self.lo, self.hi = ends.min(axis=0) - v["radius"], ends.max(axis=0) + v["radius"]

    def __call__(self, points: np.ndarray, bound: float = np.inf) -> np.ndarray:
        """Distances; ``inf`` where farther than ``bound``."""
        distance = np.full(len(points), np.inf)
        near = np.all((points >= self.lo - bound) & (points <= self.hi + bound), axis=1)
        distance[near] = self._distance(points[near])
        distance[distance > bound] = np.inf
        return distance

    def _distance(self, points: np.ndarray) -> np.ndarray:
        v = self.values
        if self.kind == "box":
            outside = np.maximum(np.maximum(v["min"] - points, points - v["max"]), 0.0)
            return np.linalg.norm(outside, axis=1)
        if self.kind == "sphere":
            return np.maximum(np.linalg.norm(points - v["centre"], axis=1) - v["radius"], 0.0)
        axis = v["end"] - v["start"]
        length = np.linalg.norm(axis)
        axis = axis / length
        t = (points - v["start"]) @ axis
        radial = np.linalg.norm(points - v["start"] - np.outer(t, axis), axis=1)
        along = np.maximum(np.maximum(-t, t - length), 0.0)
        return np.hypot(np.maximum(radial - v["radius"], 0.0), along)
