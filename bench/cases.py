"""The benchmark cases shared by the bench scripts: the plate-cylinder junction (the paper's Fig. 10) with
the cylinder at the plate centre (``junction-centre``) or near its edge (``junction-edge``), sized by the
patterns of the junction-edge recipe.

The Gmsh reference case of ../shared/reference/NOTES.md is the junction-edge recipe at global size 1.8
(h = 1.5 at the junction, about 1.02M tetrahedra). ``junction_job(case, scale)`` multiplies every size of
that field by ``scale`` (H = 1.8 s and the pattern's ``near`` = 0.06 s), so the field keeps its shape and
the element count falls as about s^-3: one family of fields from 10k to 10M tetrahedra.
"""

from __future__ import annotations

from engine.job import job_from_dict
from engine.pipeline import prepare
from engine.schema import validate
from engine.shapes import SHAPES

REFERENCE_SIZE = 1.8  # global size H of the reference case
JUNCTION_NEAR = 0.06  # plate-edge-junction's default 'near' (x the cylinder radius): h = 1.5 at H = 1.8
OFFSETS = {"junction-centre": 0.0, "junction-edge": 60.0}  # cylinder axis x from the plate centre
TIERS = {"10k": 4.67, "100k": 2.17, "1M": 1.0, "10M": 0.531}  # scale -> about this many tetrahedra (fuzzymesh)
TIER_CASES = {"10M": ("junction-edge",)}  # tiers run on some cases only (each mesher takes minutes at 10M)


def junction_parameters(case: str) -> dict:
    """Every dimension of the case's solid (engine.shapes' defaults with the case's offset)."""
    schema = SHAPES.details("plate_cylinder_junction")["parameters"]
    return validate({"offset": OFFSETS[case]}, schema)


def junction_job(case: str, scale: float = 1.0) -> dict:
    """The job (as a dict) of ``case`` with the junction-edge recipe's patterns, every size x ``scale``."""
    return {
        "geometry": {"shape": "plate_cylinder_junction", "parameters": {"offset": OFFSETS[case]}},
        "size": REFERENCE_SIZE * scale,
        "place": [
            {"pattern": "uniform-domain"},
            {
                "pattern": "plate-edge-junction",
                "every": "junction",
                "roles": {"edge": "plate-edge"},
                "parameters": {"near": JUNCTION_NEAR * scale},
            },
        ],
    }


def build_case(job: dict):
    """(knowledge base, geometry, features, sizing field) of a job dict."""
    return tuple(prepare(job_from_dict(job)))


def junction_edge(size: float = REFERENCE_SIZE):
    """(knowledge base, geometry, features, sizing field) of the junction-edge recipe at global ``size``."""
    return build_case({"geometry": {"shape": "plate_cylinder_junction"}, "size": size, "recipe": "junction-edge"})
