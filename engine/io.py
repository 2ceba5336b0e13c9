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


def write_all_or_nothing(targets: list[tuple[Path, object]]) -> list[Path]:
    """Write every ``(path, write)`` to a temporary file, then rename them all into place.

    ``write(temporary_path)`` writes one file. If any write or rename fails, this
    run's temporary and already renamed files are removed and a one-line
    FuzzymeshError is raised: a failed run leaves no partial output.
    """
    staged: list[tuple[str, Path]] = []
    placed: list[Path] = []
    current = targets[0][0]
    try:
        for path, write in targets:
            current = path
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
            os.close(fd)
            staged.append((tmp, path))
            write(tmp)
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        for tmp, path in staged:
            current = path
            os.replace(tmp, path)
            placed.append(path)
    except OSError as exc:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        for path in placed:
            path.unlink(missing_ok=True)
        raise FuzzymeshError(f"cannot write ({exc.strerror or exc})", where=str(current),
                             fix="choose a writable output folder and file name") from None
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    return placed


def write_mesh(mesh: TetMesh, directory: Path, name: str, formats: list[str]) -> list[Path]:
    """Write ``mesh`` as ``directory/name.<format>`` for each format; return the paths."""
    data = to_meshio(mesh)
    return write_all_or_nothing([
        (Path(directory) / f"{name}.{fmt}", lambda tmp, fmt=fmt: meshio.write(tmp, data, file_format=MESHIO_FORMATS[fmt]))
        for fmt in formats])
