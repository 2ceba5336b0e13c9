"""``fuzzymesh lint``: every knowledge file checked, one line per problem, with no solid and no geometry
library (tests/test_architecture.py)."""

from __future__ import annotations

from ..errors import FuzzymeshError
from .base import KnowledgeBase
from .loading import default_paths, yaml_files


def lint(paths) -> list[str]:
    """The first error of each file, one line each, empty when all is well: loading (patterns evaluated at sample
    L and H), then the recipes and sizing defaults checked against the shipped knowledge and the linted files."""
    files = yaml_files(paths)
    linted = {f.resolve() for f in files if f.exists()}
    kb = KnowledgeBase()
    for path in yaml_files(default_paths()):  # what the linted files add to, or must say they override
        if path.resolve() not in linted:
            try:
                kb = kb.with_file(path)
            except FuzzymeshError:
                pass
    errors, sizings = [], []
    for path in files:
        try:
            before = kb.sizing
            kb = kb.with_file(path)
            if kb.sizing is not before:
                sizings.append(kb.sizing)
        except FuzzymeshError as exc:
            errors.append(exc.one_line())
        except Exception as exc:  # a loader fault must not hide the other files' findings
            errors.append(f"{path}: internal error while reading ({exc.__class__.__name__}: {exc}); please report it")
    return errors + [exc.one_line() for exc in kb.problems(sizings)]
