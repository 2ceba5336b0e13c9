"""Writing meshes through meshio, atomically (temporary file + rename)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import meshio
import numpy as np

from .errors import FuzzymeshError
from .mesh import TetMesh

MESHIO_FORMATS = {"vtu": "vtu", "msh": "gmsh"}


def to_meshio(mesh: TetMesh) -> meshio.Mesh:
    return meshio.Mesh(
        mesh.points, [("tetra", mesh.tets.astype(np.int64))],
        point_data={"node_level": mesh.node_level.astype(np.int32),
                    "node_entity": mesh.node_entity.astype(np.int32)})


def write_atomic(path: Path, write) -> None:
    """Call ``write(temporary_path)``, then rename onto ``path``; no partial file on failure."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    except OSError as exc:
        raise FuzzymeshError(f"cannot write ({exc.strerror or exc})", where=str(path),
                             fix="choose a writable output folder") from None
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_mesh(mesh: TetMesh, directory: Path, name: str, formats: list[str]) -> list[Path]:
    """Write ``mesh`` as ``directory/name.<format>`` for each format; return the paths."""
    data = to_meshio(mesh)
    paths = []
    for fmt in formats:
        path = Path(directory) / f"{name}.{fmt}"
        write_atomic(path, lambda tmp, fmt=fmt: meshio.write(tmp, data, file_format=MESHIO_FORMATS[fmt]))
        paths.append(path)
    return paths
