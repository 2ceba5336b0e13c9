"""Named implementations, one way for every kind: packers, meshers, shapes, validation cases and output writers.

Each kind is one :class:`Registry` with a contract (a Protocol of engine/plugins.py). Built-ins register by
decorator, ``@REGISTRY.register(name, **details)``, when their module is imported (``builtins``: modules
imported on first use), or are named as ``"module:attribute"`` (``lazy``: loaded on first ``get``, for modules
whose dependencies are optional); third-party ones come from the entry-point ``group``. Look-up is
``REGISTRY.get(name)`` (the implementation, checked against the contract), ``REGISTRY.details(name)`` (what
it was registered with, e.g. a shape's parameter schema), ``name in REGISTRY`` and ``list(REGISTRY)`` (in
registration order; ``names()``: sorted).
"""

from __future__ import annotations

import importlib
import inspect
from importlib.metadata import entry_points

from .errors import JobError


class Registry:
    """Functions by name, each keeping ``contract`` (a Protocol of engine/plugins.py). ``builtins`` are modules
    imported (to register themselves) on first use, ``lazy`` maps names to ``"module:attribute"`` loaded when
    first got; third-party ones come from the entry-point ``group`` (None: none)."""

    def __init__(
        self,
        group: str | None,
        builtins: list[str],
        contract: type,
        *,
        noun: str | None = None,
        lazy: dict[str, str] | None = None,
    ):
        self.group, self.builtins, self.contract = group, builtins, contract
        self.noun = noun or group.rsplit(".", 1)[1].rstrip("s")  # "packer"
        self.lazy = dict(lazy or {})  # name -> "module:attribute", loaded on first get
        self.functions: dict = {}
        self.broken: dict[str, str] = {}  # entry points that failed to load: name -> why
        self._details: dict[str, dict] = {}
        self._loaded = False

    def register(self, name: str, **details):
        """Decorator: register the function as ``name``, with ``details`` (see :meth:`details`)."""

        def decorate(function):
            self.functions[name] = function
            self._details[name] = details
            return function

        return decorate

    def _load(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        for module in self.builtins:
            importlib.import_module(module)
        if self.group is None:
            return
        for ep in entry_points(group=self.group):
            if ep.name not in self.functions:
                try:
                    self.functions[ep.name] = ep.load()
                except Exception as exc:  # one broken plug-in must not stop the others
                    self.broken[ep.name] = f"entry point {ep.name} = {ep.value}: {exc.__class__.__name__}: {exc}"

    def _function(self, name: str):
        """The function registered as ``name``, a lazy one imported now."""
        if name not in self.functions and name in self.lazy:
            module, _, attribute = self.lazy[name].partition(":")
            self.functions[name] = getattr(importlib.import_module(module), attribute)
        if name not in self.functions:
            raise JobError(
                f"no {self.noun} named '{name}'",
                where=self.group or self.noun,
                fix=f"known: {', '.join(self) or 'none'}",
            )
        return self.functions[name]

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
        function = self._function(name)
        expected = inspect.signature(self.contract.__call__)
        given = list(expected.parameters.values())[1:]
        positional = [p for p in given if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        keywords = [p.name for p in given if p.kind == p.KEYWORD_ONLY]
        if any(p.kind == p.VAR_KEYWORD for p in given):  # e.g. a shape's parameters, by its schema
            keywords += list(self.details(name).get("parameters", {}))
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

    def details(self, name: str) -> dict:
        """What ``name`` was registered with (``register(name, **details)``); {} for lazy and entry-point ones."""
        self._load()
        return self._details.get(name, {})

    def names(self) -> list[str]:
        """Every name, sorted, those that failed to load last."""
        self._load()
        return sorted(set(self.functions) | set(self.lazy)) + sorted(self.broken)

    def __iter__(self):
        """Every name in registration order (lazy, registered, entry points), those that failed to load last."""
        self._load()
        return iter([*self.lazy, *(n for n in self.functions if n not in self.lazy), *self.broken])

    def __contains__(self, name) -> bool:
        self._load()
        return name in self.functions or name in self.lazy or name in self.broken

    def __len__(self) -> int:
        return len(list(iter(self)))
