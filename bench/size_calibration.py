"""Edge length / h on the built-in shapes: the measurement behind the bubble packer's ``diameter`` setting
(knowledge/population.yaml, docs/rules.md section 2) and the element-count estimate (engine/sizing/counts.py).

For each shape at two sizes (the default H = bounding-box diagonal / 40, and a coarser one) it runs the
whole pipeline without writing files and prints the median of edge length / h over the mesh's edges
(engine/quality.py size_conformity), the median of the per-element mean edge / h (the audit's size_ratio),
tetrahedra and nodes against the estimate, and the time.

    python bench/size_calibration.py                 # the packer settings in force
    python bench/size_calibration.py --diameter 1.0  # another bubble diameter / h, for calibration
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from engine import pipeline
from engine.job import job_from_dict
from engine.knowledge import load_knowledge

CASES = [  # (name, job)
    ("cylinder", {"geometry": {"shape": "cylinder"}}),
    ("cylinder H5", {"geometry": {"shape": "cylinder"}, "size": 5.0}),
    ("plate", {"geometry": {"shape": "plate"}}),
    ("plate H20", {"geometry": {"shape": "plate"}, "size": 20.0}),
    ("plate_with_hole", {"geometry": {"shape": "plate_with_hole"}}),
    (
        "plate_with_hole static-stress",
        {"geometry": {"shape": "plate_with_hole"}, "size": 10, "min_size": 2, "recipe": "static-stress"},
    ),
    ("junction", {"geometry": {"shape": "plate_cylinder_junction"}}),
    ("junction-edge H12", {"geometry": {"shape": "plate_cylinder_junction"}, "size": 12.0, "recipe": "junction-edge"}),
    ("l_bracket", {"geometry": {"shape": "l_bracket"}}),
    ("l_bracket H8", {"geometry": {"shape": "l_bracket"}, "size": 8.0}),
    ("hollow_sphere_octant", {"geometry": {"shape": "hollow_sphere_octant"}}),
    ("hollow_sphere_octant H10", {"geometry": {"shape": "hollow_sphere_octant"}, "size": 10.0}),
]


def measure(job: dict, diameter: float | None, packer: str = "bubble") -> dict:
    kb = load_knowledge()
    if diameter is not None:
        kb.packer_settings["population"]["diameter"] = diameter
    original = pipeline.load_knowledge
    pipeline.load_knowledge = lambda *a, **k: kb
    try:
        start = time.perf_counter()
        result = pipeline.run(job_from_dict({**job, "packer": packer}), write=False)
        seconds = time.perf_counter() - start
    finally:
        pipeline.load_knowledge = original
    nodes, tets = result.sizing.expected_counts.nodes, result.sizing.expected_counts.tets
    return {
        "median": result.conformity["median"],
        "element_median": float(np.median(result.audit.cells["size_ratio"])),
        "tets": len(result.mesh.tets),
        "expected_tets": tets,
        "nodes": len(result.mesh.points),
        "expected_nodes": nodes,
        "seconds": seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--diameter", type=float, help="bubble diameter / h (default: the knowledge's)")
    parser.add_argument("--packer", default="bubble")
    parser.add_argument("--only", help="cases whose name contains this")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    print(f"{'case':32s} {'edge/h':>7s} {'elem/h':>7s} {'tets':>8s} {'/est':>6s} {'nodes/est':>9s} {'s':>6s}")
    medians = []
    for name, job in CASES:
        if args.only and args.only not in name:
            continue
        m = measure(job, args.diameter, args.packer)
        medians.append(m["median"])
        print(
            f"{name:32s} {m['median']:7.3f} {m['element_median']:7.3f} {m['tets']:8d} "
            f"{m['tets'] / m['expected_tets']:6.3f} {m['nodes'] / m['expected_nodes']:9.3f} {m['seconds']:6.1f}",
            flush=True,
        )
    print(f"median edge/h over the cases: {min(medians):.3f} to {max(medians):.3f}")


if __name__ == "__main__":
    main()
