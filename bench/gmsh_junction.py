"""Gmsh on the benchmark junction with our size field: the same solid (Gmsh's own OpenCASCADE model of the
plate-cylinder junction, built from the dimensions of engine.shapes) and the same h(x) (our SizingField's
graded background grid, read by Gmsh's ``Structured`` field, which interpolates it trilinearly as we do).

This module imports gmsh and numpy only, so a Gmsh worker process measures Gmsh's memory, not ours.
"""

from __future__ import annotations

import time

import numpy as np

ALGORITHMS = {"gmsh-delaunay": 1, "gmsh-hxt": 10}  # Mesh.Algorithm3D
THREADS = {"gmsh-delaunay": 1, "gmsh-hxt": 2}  # Mesh.MaxNumThreads3D (Delaunay is serial)
SIZE_SOURCES_OFF = ("MeshSizeFromPoints", "MeshSizeFromCurvature", "MeshSizeExtendFromBoundary")


def write_size_grid(sizing, path) -> None:
    """Write the sizing field's graded grid as a binary Gmsh ``Structured`` field file.

    Format (Gmsh src/mesh/Field.cpp, StructuredField): origin (3 doubles), spacing
    (3 doubles), node counts (3 int32), then the node values (doubles), the last
    index fastest: value (i, j, k) at origin + spacing * (i, j, k), which is our grid's
    C order. Gmsh interpolates it trilinearly, exactly as ``SizingField.__call__``.
    """
    if sizing.min_size is not None or sizing.max_size is not None or sizing.graded.finer:
        raise ValueError("the Structured export reproduces h(x) only without min_size / max_size and finer grids")
    grid = np.ascontiguousarray(sizing.grid, dtype="<f8")
    with open(path, "wb") as file:
        file.write(np.asarray(sizing.origin, dtype="<f8").tobytes())
        file.write(np.full(3, sizing.cell, dtype="<f8").tobytes())
        file.write(np.asarray(grid.shape, dtype="<i4").tobytes())
        file.write(grid.tobytes())


def start(threads: int = 1) -> None:
    """Initialise Gmsh quietly, one thread for curves and surfaces and ``threads`` for the volume."""
    import gmsh

    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.NumThreads", 1)
    gmsh.option.setNumber("Mesh.MaxNumThreads1D", 1)
    gmsh.option.setNumber("Mesh.MaxNumThreads2D", 1)
    gmsh.option.setNumber("Mesh.MaxNumThreads3D", threads)


def build_junction(length, width, thickness, radius, height, offset) -> float:
    """The plate-cylinder junction of engine.shapes.plate_cylinder_junction as an OpenCASCADE solid
    (plate centred on the z axis, bottom on z = 0; the cylinder from z = thickness / 2 to thickness + height,
    axis at x = offset); returns its exact volume."""
    import gmsh

    plate = gmsh.model.occ.addBox(-length / 2, -width / 2, 0, length, width, thickness)
    cylinder = gmsh.model.occ.addCylinder(offset, 0, thickness / 2, 0, 0, height + thickness / 2, radius)
    solid, _ = gmsh.model.occ.fuse([(3, plate)], [(3, cylinder)])
    gmsh.model.occ.synchronize()
    if len(solid) != 1:
        raise RuntimeError(f"the junction fused into {len(solid)} volumes, expected 1")
    return gmsh.model.occ.getMass(3, solid[0][1])


def use_size_grid(path) -> None:
    """Make the Structured field of ``path`` Gmsh's only size source."""
    import gmsh

    field = gmsh.model.mesh.field.add("Structured")
    gmsh.model.mesh.field.setString(field, "FileName", str(path))
    gmsh.model.mesh.field.setNumber(field, "TextFormat", 0)
    gmsh.model.mesh.field.setAsBackgroundMesh(field)
    for option in SIZE_SOURCES_OFF:
        gmsh.option.setNumber(f"Mesh.{option}", 0)


def probe_sizes() -> np.ndarray:
    """Mesh the curves with a pass-through size callback: (n, 4) points and the size Gmsh asked for there
    (the callback receives the size from every other source, here our field alone)."""
    import gmsh

    seen = []

    def record(dim, tag, x, y, z, size):
        seen.append((x, y, z, size))
        return size

    gmsh.model.mesh.setSizeCallback(record)
    gmsh.model.mesh.generate(1)
    gmsh.model.mesh.removeSizeCallback()
    gmsh.model.mesh.clear()
    return np.array(seen, dtype=float).reshape(-1, 4)


def generate(mesher: str, after_stage=None) -> dict:
    """Mesh curves, surfaces and the volume with the 3-D algorithm of ``mesher``, Gmsh's default optimiser
    included: {stage: seconds}. Delaunay's optimiser (run by ``generate(3)`` by default) is run as its own
    stage, which gives the same mesh; HXT optimises inside its volume stage. ``after_stage(name)`` is
    called after each stage (to read the memory high-water mark)."""
    import gmsh

    gmsh.option.setNumber("Mesh.Algorithm3D", ALGORITHMS[mesher])
    separate_optimiser = mesher == "gmsh-delaunay"
    if separate_optimiser:
        gmsh.option.setNumber("Mesh.Optimize", 0)
    stages = [
        ("curves", lambda: gmsh.model.mesh.generate(1)),
        ("surface", lambda: gmsh.model.mesh.generate(2)),
        ("volume", lambda: gmsh.model.mesh.generate(3)),
    ]
    if separate_optimiser:
        stages.append(("optimise", lambda: gmsh.model.mesh.optimize("")))
    seconds = {}
    for name, step in stages:
        begin = time.perf_counter()
        step()
        seconds[name] = time.perf_counter() - begin
        if after_stage is not None:
            after_stage(name)
    return seconds


def mesh_arrays() -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3), tets (m, 4) 0-based) of the current model's linear tetrahedra."""
    import gmsh

    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    _, nodes = gmsh.model.mesh.getElementsByType(4)
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    return np.asarray(coordinates, dtype=float).reshape(-1, 3), index[np.asarray(nodes, dtype=np.int64)].reshape(-1, 4)
