"""All-or-nothing file output: a run writes every file it promised, or none (a leaf module)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable

from .errors import FuzzymeshError

Target = tuple[Path, Callable[[str], None]]  # (final path, write(temporary path))


def write_all_or_nothing(targets: list[Target]) -> list[Path]:
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
        raise FuzzymeshError(
            f"cannot write ({exc.strerror or exc})",
            where=str(current),
            fix="choose a writable output folder and file name",
        ) from None
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    return placed
