"""Where the knowledge comes from: the shipped knowledge/ and patterns/ folders (in the wheel under
engine/_data/) and a job's own files or folders."""

from __future__ import annotations

from pathlib import Path

from .base import KnowledgeBase

KNOWLEDGE_SUFFIXES = (".yaml", ".yml", ".fcl")  # .fcl: rule files in FCL (engine/fcl.py)


def default_paths() -> list[Path]:
    """The shipped knowledge/ and patterns/ folders (installed wheel or source checkout)."""
    here = Path(__file__).resolve().parents[1]  # engine/
    installed = here / "_data"
    root = installed if installed.is_dir() else here.parent
    return [root / "knowledge", root / "patterns"]


def yaml_files(paths) -> list[Path]:
    files = []
    for path in map(Path, paths):
        if path.is_dir():
            files += sorted(p for p in path.rglob("*") if p.suffix in KNOWLEDGE_SUFFIXES)
        else:
            files.append(path)
    return files


def load_knowledge(extra_paths=()) -> KnowledgeBase:
    """The default knowledge base plus ``extra_paths`` (files or folders)."""
    kb = KnowledgeBase()
    for path in yaml_files([*default_paths(), *extra_paths]):
        kb = kb.with_file(path)
    kb.check()
    return kb
