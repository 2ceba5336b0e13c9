"""Named plug-ins (packers, meshers): built-ins register by decorator, others by entry points."""

from __future__ import annotations

import importlib
import inspect
from importlib.metadata import entry_points

from .errors import JobError


class Registry:
    """Functions by name, each keeping ``contract`` (a Protocol of engine/plugins.py). ``builtins`` are modules
    imported (to register themselves) on first use; third-party ones come from the entry-point ``group``."""

    def __init__(self, group: str, builtins: list[str], contract: type):
        self.group, self.builtins, self.contract = group, builtins, contract
        self.noun = group.rsplit(".", 1)[1].rstrip("s")  # "packer"
        self.functions: dict = {}
        self.broken: dict[str, str] = {}  # entry points that failed to load: name -> why
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
            if ep.name not in self.functions:
                try:
                    self.functions[ep.name] = ep.load()
                except Exception as exc:  # one broken plug-in must not stop the others
                    self.broken[ep.name] = f"entry point {ep.name} = {ep.value}: {exc.__class__.__name__}: {exc}"

    def get(self, name: str):
        """The function registered as ``name``, checked to accept what the pipeline passes (a one-line
        JobError naming the function's file:line otherwise)."""
        self._load()
        if name in self.broken:
            raise JobError(
                f"{self.noun} '{name}' cannot be loaded ({self.broken[name]})",
                where=self.group,
                fix="install the plug-in's package and its dependencies, or pick another " + self.noun,
            )
        function = self.functions[name]
        expected = inspect.signature(self.contract.__call__)
        positional = [p for p in list(expected.parameters.values())[1:] if p.kind != p.KEYWORD_ONLY]
        keywords = [p.name for p in expected.parameters.values() if p.kind == p.KEYWORD_ONLY]
        try:
            inspect.signature(function).bind(*positional, **dict.fromkeys(keywords))
        except TypeError as exc:
            code = getattr(function, "__code__", None)
            where = f"{code.co_filename}:{code.co_firstlineno}" if code else f"{self.noun} '{name}'"
            call = ", ".join(p.name for p in positional) + ", *, " + ", ".join(keywords)
            raise JobError(
                f"{self.noun} '{name}' does not take what the pipeline passes ({call}): {exc}",
                where=where,
                fix=f"write it to the {self.contract.__name__} protocol of engine/plugins.py (docs/plugins.md)",
            ) from None
        return function

    def names(self) -> list[str]:
        self._load()
        return sorted(self.functions) + sorted(self.broken)
