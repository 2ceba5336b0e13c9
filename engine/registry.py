"""Named plug-ins (packers, meshers): built-ins register by decorator, others by entry points."""
from __future__ import annotations

import importlib
from importlib.metadata import entry_points


class Registry:
    """Functions by name. ``builtins`` are modules imported (to register themselves) on first use;
    third-party ones come from the entry-point ``group``."""

    def __init__(self, group: str, builtins: list[str]):
        self.group, self.builtins = group, builtins
        self.functions: dict = {}
        self._loaded = False

    def register(self, name: str):
        def decorate(function):
            self.functions[name] = function
            return function
        return decorate

    def _load(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        for module in self.builtins:
            importlib.import_module(module)
        for ep in entry_points(group=self.group):
            self.functions.setdefault(ep.name, ep.load())

    def get(self, name: str):
        self._load()
        return self.functions[name]

    def names(self) -> list[str]:
        self._load()
        return sorted(self.functions)
