"""What a solid's features are and where they lie, in words and numbers.

:func:`describe` names one corner, curve or patch for a message (``patch-11 (centroid 12.1, 4, 30)``);
:func:`solid_features` finds the features of a surface file or a job's solid, classified into the
knowledge base's feature kinds, without sizing or meshing; :func:`feature_records` and
:func:`feature_table` list them for ``fuzzymesh features`` (JSON-ready records, aligned text).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .features import Corner, Curve, Features, classify, detect_features

TYPES = (("corner", "corners"), ("curve", "curves"), ("patch", "patches"))


def centroid(feature) -> np.ndarray:
    """A corner's point, a curve's centroid (by length along it), a patch's area centroid."""
    if isinstance(feature, Corner):
        return feature.point
    if isinstance(feature, Curve):
        line = feature.polyline
        length = np.linalg.norm(np.diff(line, axis=0), axis=1)
        middles = (line[1:] + line[:-1]) / 2
        return length @ middles / length.sum() if length.sum() > 0 else line.mean(axis=0)
    return feature.centroid


def describe(feature) -> str:
    """The feature's id and centroid, e.g. ``patch-11 (centroid 12.1, 4, 30)``, for messages."""
    point = centroid(feature)
    return f"{feature.id} (centroid {_coordinates(point, np.abs(point).max())})"


def solid_features(target: str | Path, feature_angle: float | None = None, knowledge=()):
    """(source, geometry, features) of a surface file (several solids allowed) or of a job file's solid
    (built-in shape or file, its names, feature angle and knowledge); ``feature_angle`` overrides.
    Features carry the kinds of the shipped knowledge base plus ``knowledge``."""
    from .cad import CAD_FORMATS, load_cad
    from .geometry import SURFACE_FORMATS, load_surface
    from .knowledge import load_knowledge

    target = Path(target)
    if target.suffix.lower() in CAD_FORMATS:
        geometry, features = load_cad(target, 30.0 if feature_angle is None else feature_angle,
                                      allow_multiple_solids=True)
    elif target.suffix.lower() in SURFACE_FORMATS:
        geometry = load_surface(target, allow_multiple_solids=True)
        features = detect_features(geometry) if feature_angle is None else detect_features(geometry, feature_angle)
    else:
        from .job import load_job
        from .pipeline import build_geometry

        job = load_job(target)
        if feature_angle is not None:
            job = dataclasses.replace(job, feature_angle=feature_angle)
        knowledge = [*job.knowledge, *knowledge]
        geometry, features = build_geometry(job)
    classify(features, load_knowledge(knowledge).feature_kinds)
    return str(target), geometry, features


def feature_records(features: Features) -> dict:
    """Every corner, curve and patch: id, names, kinds, size (curve length and circle radius, patch area
    and cylinder or torus tube radius, and a CAD face's type), whether a curve is sharp (a smooth cut is one that charts a surface), convex, its
    dihedral angle (degrees, the kinds' ``dihedral_above`` / ``dihedral_below``), centroid
    and bounding box; JSON-ready, by type (``corners``, ``curves``, ``patches``)."""
    out = {}
    for kind, plural in TYPES:
        records = []
        for feature in getattr(features, plural):
            points = feature.point[None] if kind == "corner" else feature.points if kind == "curve" else feature.vertices
            record = {"id": feature.id, "names": list(feature.names), "kinds": list(getattr(feature, "kinds", []))}
            if kind == "curve":
                record.update(length=feature.length, radius=feature.circle.radius if feature.circle else None,
                              closed=feature.closed, sharp=feature.sharp, convex=feature.convex,
                              dihedral=feature.dihedral)
            if kind == "patch":
                radius = feature.cylinder.radius if feature.cylinder else feature.circle.radius if feature.circle else None
                record.update(area=feature.area, radius=radius, surface=feature.surface)
            record.update(centroid=centroid(feature).tolist(), bounds=[points.min(axis=0).tolist(),
                                                                      points.max(axis=0).tolist()])
            records.append(record)
        out[plural] = records
    return out


def feature_table(records: dict, scale: float) -> str:
    """``feature_records`` as an aligned plain-text table (a corner's bounding box, its point, as '-');
    coordinates below 1e-9 ``scale`` print as 0."""
    header = ("id", "names", "kinds", "size", "centroid", "bounding box")
    rows = [header]
    for _, plural in TYPES:
        for r in records[plural]:
            size = (f"L {_number(r['length'])}" if "length" in r else f"A {_number(r['area'])}" if "area" in r
                    else "") + (f", r {_number(r['radius'])}" if r.get("radius") is not None else "")
            low, high = r["bounds"]
            box = "-" if low == high else f"[{_coordinates(low, scale)}] .. [{_coordinates(high, scale)}]"
            kinds = r["kinds"] + (["(smooth cut)"] if r.get("sharp") is False else [])
            size = f"{r['surface']} {size}" if r.get("surface") else size
            rows.append((r["id"], ", ".join(r["names"]) or "-", ", ".join(kinds) or "-", size or "-",
                         _coordinates(r["centroid"], scale), box))
    widths = [max(len(row[k]) for row in rows) for k in range(len(header))]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows)


def _coordinates(point, scale: float) -> str:
    point = np.asarray(point, dtype=float)
    return ", ".join(_number(x) for x in np.where(np.abs(point) <= 1e-9 * scale, 0.0, point))


def _number(x: float) -> str:
    """Four significant digits, never an exponent: 19290, 94.22, 0.001235."""
    return np.format_float_positional(x, precision=4, unique=False, fractional=False, trim="-")
