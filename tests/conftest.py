"""Shared fixtures: built shapes are cached per session (they are immutable in use)."""

from __future__ import annotations

import contextlib
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


@contextlib.contextmanager
def gmsh_model(name: str, options: dict | None = None):
    """A Gmsh model of its own for the block (yields ``gmsh.model.occ``), with the Gmsh ``options`` set: Gmsh is
    initialised if it is not, and afterwards the model is removed, the options are set back and the model that
    was current is current again, so tests that build OpenCASCADE solids do not see each other's state."""
    import gmsh

    if not gmsh.isInitialized():
        gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    previous = gmsh.model.getCurrent() if gmsh.model.list() else None
    saved = {key: gmsh.option.getNumber(key) for key in options or {}}
    gmsh.model.add(name)
    try:
        for key, value in (options or {}).items():
            gmsh.option.setNumber(key, value)
        yield gmsh.model.occ
    finally:
        for key, value in saved.items():
            gmsh.option.setNumber(key, value)
        if name in gmsh.model.list():
            gmsh.model.setCurrent(name)
            gmsh.model.remove()
        if previous in gmsh.model.list():
            gmsh.model.setCurrent(previous)
