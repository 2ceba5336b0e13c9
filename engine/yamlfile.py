"""Safe YAML loading that remembers where every value came from.

``load_yaml`` returns plain dicts, lists and scalars, except that every
mapping is a :class:`Located` dict that knows the file and the line/column of
itself and of each of its keys. Errors can then name ``file:line:col``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import yaml

from .errors import FuzzymeshError

BOOL_1_2 = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
FLOAT_1_2 = re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


class Located(dict):
    """A dict with the source position of itself and of each key."""

    source: str = "<dict>"
    line: int = 0
    col: int = 0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.key_marks: dict = {}

    def where(self, key=None) -> str:
        """``file:line:col`` of ``key`` (or of the mapping itself)."""
        line, col = self.key_marks.get(key, (self.line, self.col))
        if line == 0:
            return self.source
        return f"{self.source}:{line}:{col}"


def located(data, source: str = "<dict>"):
    """Wrap plain nested dicts (e.g. built in Python) as :class:`Located`."""
    if isinstance(data, Located):
        return data
    if isinstance(data, dict):
        out = Located({k: located(v, source) for k, v in data.items()})
        out.source = source
        return out
    if isinstance(data, list):
        return [located(v, source) for v in data]
    return data


FAST_LOADER = getattr(yaml, "CSafeLoader", None)  # libyaml's parser, where PyYAML was built with it


def _loader_for(source: str, error=FuzzymeshError, base=yaml.SafeLoader):
    class LocatingLoader(base):
        pass

    # YAML 1.2 floats: 1e-3 and 2.5e0 are numbers, not strings (PyYAML follows YAML 1.1)
    # YAML 1.2 booleans: only true/false (PyYAML also reads yes/no/on/off, which breaks labels like ON)
    LocatingLoader.yaml_implicit_resolvers = {
        k: [(tag, regexp) for tag, regexp in v if tag != "tag:yaml.org,2002:bool"]
        for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }
    LocatingLoader.add_implicit_resolver("tag:yaml.org,2002:float", FLOAT_1_2, list("-+0123456789."))
    LocatingLoader.add_implicit_resolver("tag:yaml.org,2002:bool", BOOL_1_2, list("tTfF"))

    def construct_mapping(loader, node, deep=False):
        loader.flatten_mapping(node)
        mapping = Located()
        mapping.source = source
        mapping.line, mapping.col = node.start_mark.line + 1, node.start_mark.column + 1
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError:
                raise error(
                    "a mapping key must be a plain value",
                    where=f"{source}:{key_node.start_mark.line + 1}:{key_node.start_mark.column + 1}",
                )
            if key in mapping:
                raise error(
                    f"duplicate key '{key}'",
                    where=f"{source}:{key_node.start_mark.line + 1}:{key_node.start_mark.column + 1}",
                    fix="each key may appear once in a mapping",
                )
            mapping[key] = loader.construct_object(value_node, deep=True)
            mapping.key_marks[key] = (key_node.start_mark.line + 1, key_node.start_mark.column + 1)
        return mapping

    def construct_float(loader, node):
        value = loader.construct_yaml_float(node)
        if math.isinf(value) and not node.value.lstrip("+-").lower().startswith("."):  # 1e400, not .inf
            raise error(
                f"the number {node.value} is out of range (its magnitude is beyond 1.8e308: infinite)",
                where=f"{source}:{node.start_mark.line + 1}:{node.start_mark.column + 1}",
                fix="give a number of magnitude below 1.8e308",
            )
        return value

    LocatingLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, construct_mapping)
    LocatingLoader.add_constructor("tag:yaml.org,2002:float", construct_float)
    return LocatingLoader


def parse_yaml(text: str, source: str, error=FuzzymeshError):
    """Parse YAML text with safe loading; syntax errors become one-line ``error``s. libyaml's parser reads it
    where PyYAML has it (the knowledge base's 18 files in a new process: 0.040 -> 0.012 s); a text it refuses is
    read again by the pure-Python parser, whose messages these are."""
    if FAST_LOADER is not None:
        try:
            return yaml.load(text, Loader=_loader_for(source, error, FAST_LOADER))  # noqa: S506 - SafeLoader subclass
        except yaml.YAMLError:
            pass
    try:
        return yaml.load(text, Loader=_loader_for(source, error))  # noqa: S506 - SafeLoader subclass
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        raise error(
            f"unsupported YAML tag: {exc.problem}", where=where, fix="remove the tag; only plain YAML values are read"
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        problem = exc.problem or exc.context or "invalid YAML"
        raise error(f"invalid YAML: {problem}", where=where, fix="fix the YAML syntax") from None
    except yaml.YAMLError as exc:
        raise error(f"invalid YAML: {exc}", where=source, fix="fix the YAML syntax") from None


def read_text(path: Path, kind: str, error=FuzzymeshError) -> str:
    """The UTF-8 text of the file ``path``; one that cannot be read is an ``error`` located at the file (``kind``:
    what it should be, for the fix: "YAML", "FCL")."""
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise error(
            f"cannot read the file ({exc.__class__.__name__})",
            where=str(path),
            fix=f"give a readable UTF-8 {kind} file",
        ) from None


def load_yaml(path: str | Path, error=FuzzymeshError):
    """Read a YAML file safely; a missing, unreadable or empty file is an ``error``."""
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise error("file not found", where=source, fix="check the path")
    data = parse_yaml(read_text(path, "YAML", error), source, error)
    if data is None:
        raise error("the file is empty", where=f"{source}:1:1", fix="write the YAML content")
    return data
