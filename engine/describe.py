"""What a solid's features are and where they lie, in words and numbers (``fuzzymesh features``).

:func:`solid_features` finds the features of a surface file or a job's solid, classified into the
knowledge base's feature kinds, without sizing or meshing; :func:`feature_records` and
:func:`feature_table` list them for ``fuzzymesh features`` (JSON-ready records, aligned text).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from .features import Features, centroid, classify, coordinates, detect_features, number

TYPES = (("corner", "corners"), ("curve", "curves"), ("patch", "patches"))


def solid_features(target: str | Path, feature_angle: float | None = None, knowledge=()):
    """(source, geometry, features) of a surface file (several solids allowed) or of a job file's solid
    (built-in shape or file, its names, feature angle and knowledge); ``feature_angle`` overrides.
    Features carry the kinds of the shipped knowledge base plus ``knowledge``."""
    from .cad import CAD_FORMATS, load_cad
    from .geometry import SURFACE_FORMATS, load_surface
    from .knowledge import load_knowledge

    target = Path(target)
    if target.suffix.lower() in CAD_FORMATS:
        geometry, features = load_cad(
            target, 30.0 if feature_angle is None else feature_angle, allow_multiple_solids=True
        )
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
    return str(target), geometry, classify(features, load_knowledge(knowledge).feature_kinds)


def feature_records(features: Features) -> dict:
    """Every corner, curve and patch: id, names, kinds, size (curve length and circle radius, patch area
    and cylinder or torus tube radius, and a CAD face's type), whether a curve is sharp (a smooth cut is one
    that charts a surface), convex, its dihedral angle (degrees, the kinds' ``dihedral_above`` /
    ``dihedral_below``), centroid and bounding box; JSON-ready, by type (``corners``, ``curves``, ``patches``)."""
    out = {}
    for kind, plural in TYPES:
        records = []
        for feature in getattr(features, plural):
            points = (
                feature.point[None] if kind == "corner" else feature.points if kind == "curve" else feature.vertices
            )
            record = {"id": feature.id, "names": list(feature.names), "kinds": list(getattr(feature, "kinds", []))}
            if kind == "curve":
                record.update(
                    length=feature.length,
                    radius=feature.circle.radius if feature.circle else None,
                    closed=feature.closed,
                    sharp=feature.sharp,
                    convex=feature.convex,
                    dihedral=feature.dihedral,
                )
            if kind == "patch":
                radius = (
                    feature.cylinder.radius if feature.cylinder else feature.circle.radius if feature.circle else None
                )
                record.update(area=feature.area, radius=radius, surface=feature.surface)
            record.update(
                centroid=centroid(feature).tolist(), bounds=[points.min(axis=0).tolist(), points.max(axis=0).tolist()]
            )
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
            size = (
                f"L {number(r['length'])}" if "length" in r else f"A {number(r['area'])}" if "area" in r else ""
            ) + (f", r {number(r['radius'])}" if r.get("radius") is not None else "")
            low, high = r["bounds"]
            box = "-" if low == high else f"[{coordinates(low, scale)}] .. [{coordinates(high, scale)}]"
            kinds = r["kinds"] + (["(smooth cut)"] if r.get("sharp") is False else [])
            size = f"{r['surface']} {size}" if r.get("surface") else size
            rows.append(
                (
                    r["id"],
                    ", ".join(r["names"]) or "-",
                    ", ".join(kinds) or "-",
                    size or "-",
                    coordinates(r["centroid"], scale),
                    box,
                )
            )
    widths = [max(len(row[k]) for row in rows) for k in range(len(header))]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows)
