"""Shared fixtures: built shapes are cached per session (they are immutable in use)."""

from __future__ import annotations

import functools

import pytest

from engine.features import apply_names, detect_features
from engine.schema import validate
from engine.shapes import SHAPES, build_shape


@functools.lru_cache(maxsize=None)
def shape_and_features(kind: str, **parameters):
    schema = SHAPES.details(kind)["parameters"]
    shape = build_shape(kind, validate(parameters, schema))
    features = detect_features(shape.geometry, 30.0, shape.face_groups)
    return shape, apply_names(features, shape.name_rules, shape.given_curves)


@pytest.fixture
def built():
    """shape_and_features(kind, **parameters) -> (shape, features), cached: do not change what it returns."""
    return shape_and_features


@pytest.fixture
def fresh_features():
    """fresh_features(kind, **parameters) -> features of their own, for a test that changes them."""
    return lambda kind, **parameters: shape_and_features.__wrapped__(kind, **parameters)[1]


@pytest.fixture(scope="session")
def junction_run(tmp_path_factory):
    """The junction near the plate edge meshed through a job file (recipe junction-edge, size 12, VTU):
    (output folder, pipeline result)."""
    import yaml

    from engine.job import load_job
    from engine.pipeline import run

    folder = tmp_path_factory.mktemp("junction")
    job = folder / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {
                "geometry": {"shape": "plate_cylinder_junction"},
                "recipe": "junction-edge",
                "size": 12.0,
                "output": {"formats": ["vtu"]},
            }
        )
    )
    return folder / "out", run(load_job(job))
