"""The benchmark case shared by the bench scripts: the junction near the plate edge (recipe junction-edge),
the Gmsh reference case of ../shared/reference/NOTES.md at global size 1.8."""
from __future__ import annotations

from engine.job import job_from_dict
from engine.knowledge import load_knowledge
from engine.pipeline import build_geometry, build_sizing


def junction_edge(size: float = 1.8):
    """(knowledge base, geometry, features, sizing field) of the junction-edge case at ``size``."""
    kb = load_knowledge()
    job = job_from_dict({"geometry": {"shape": "plate_cylinder_junction"}, "size": size, "recipe": "junction-edge"})
    geometry, features = build_geometry(job)
    return kb, geometry, features, build_sizing(job, geometry, features, kb)
