"""The thin plate of issue 15: a 400 x 100 x 5 plate with a hole of radius 12, at global sizes at and above
its thickness. It crashed at size 5 (seeds 1 and 2: "the boundary triangulation is not a closed
2-manifold") and had slivers of 0.6-2.7 deg when h exceeded the thickness; the thin-wall rule now puts
2 elements through the wall, and the mesh passes the acceptance gate with 10-node elements."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engine.fe import quadratic
from engine.job import job_from_dict
from engine.pipeline import run
from engine.quadratic import scaled_jacobian

PLATE = {"length": 400, "width": 100, "thickness": 5, "hole_radius": 12}  # the issue's
SHORT = {"length": 120, "width": 60, "thickness": 5, "hole_radius": 12}  # the same wall, a third of the tets


@pytest.mark.parametrize("plate, size, seed", [(PLATE, 5.0, 1), (SHORT, 10.0, 2)], ids=["issue-size-5", "size-10"])
def test_the_thin_plate_meshes_without_slivers(plate, size, seed):
    geometry = {"shape": "plate_with_hole", "parameters": plate}
    job = job_from_dict(
        {"geometry": geometry, "size": size, "seed": seed, "output": {"order": 2}},
        base_dir=Path("."),
        source="<thin plate>",
    )
    result = run(job, write=False)  # the acceptance gate ran: valid, closed, on the surface
    assert result.quality["min_dihedral"]["min"] >= 10.0
    assert result.quality["volume"]["non_positive"] == 0
    # at least 2 elements through the 5 mm wall: the thin-wall rule sizes the plate at 2.5
    thin = [k for k, p in enumerate(result.sizing.placed) if p.pattern == "thin-wall"]
    assert np.mean(np.isin(result.audit.cells["winner"], thin)) > 0.9
    assert np.median(result.audit.cells["h_target"]) <= 2.5 * 1.01
    points, tets10, _ = quadratic(result.mesh, result.geometry, result.features)
    assert scaled_jacobian(points, tets10).min() >= 0.2
