"""IEC 61131-7 Fuzzy Control Language (FCL): write rule bases as FCL and read ``.fcl`` rule files.

:func:`to_fcl` writes rule bases as FUNCTION_BLOCKs (TRAP / TRIAN terms, AND : MIN, ACT : MIN, ACCU : MAX,
METHOD : COG). What FCL cannot hold (the rule file's id and settings, rule ids, the resolution, the
action) goes into annotations ``(*@ {YAML flow mapping} *)``, comments to every other FCL tool.
:func:`load_fcl` parses a file into the same located tree a YAML rules file gives, so
``engine.knowledge.load_rules`` checks both alike and its errors point into the ``.fcl`` file.
See docs/rules.md section 2, *FCL*.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from .errors import KnowledgeError
from .fuzzy import RuleBase
from .yamlfile import Located, parse_yaml, read_text

IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
TOKEN = re.compile(
    r"""
    (?P<space>\s+)
  | (?P<note>\(\*@(?P<body>.*?)\*\))
  | (?P<comment>\(\*.*?\*\)|//[^\n]*)
  | (?P<number>[-+]?(?:\d+(?:\.\d+)?|\.\d+)(?:[eE][-+]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<punct>:=|\.\.|[:;(),])
""",
    re.VERBOSE | re.DOTALL,
)
SHAPES = {"TRAP": 4, "TRAPE": 4, "TRAPEZOID": 4, "TRIAN": 3, "TRIANGLE": 3}  # jFuzzyLogic's and fuzzylite's names
SETTINGS = {"AND": "MIN", "ACT": "MIN", "ACCU": "MAX", "METHOD": "COG"}  # the only inference fuzzymesh has
FIX_SETTING = "fuzzymesh infers with AND : MIN, ACT : MIN, ACCU : MAX and METHOD : COG (docs/rules.md, FCL)"


# ------------------------------------------------------------------------------------------ writer


def to_fcl(bases: list[RuleBase], file_id: str, settings: dict | None = None) -> str:
    """FCL text of rule bases of the rule file ``file_id`` (all named ``file_id.NAME``), with its packer settings."""
    header = {"id": file_id, **({"packer": settings} if settings else {})}
    lines = [
        f"(* rule file '{file_id}' of fuzzymesh: the annotations, comments that begin with '(*@', hold what "
        "FCL cannot *)",
        _note(header),
        "",
    ]
    for base in bases:
        lines += _block(base, file_id)
    return "\n".join(lines)


def _block(base: RuleBase, file_id: str) -> list[str]:
    name = base.id.removeprefix(f"{file_id}.")
    for word in [
        name,
        *base.inputs,
        *base.outputs,
        *(t for v in [*base.inputs.values(), *base.outputs.values()] for t in v.terms),
    ]:
        if not IDENTIFIER.match(word):
            raise KnowledgeError(
                f"FCL cannot name '{word}' of rule base '{base.id}'",
                where=base.source,
                fix="FCL names are letters, digits and '_', not starting with a digit; rename it",
            )
    note = {"resolution": base.resolution, **({"action": base.extra["action"]} if "action" in base.extra else {})}
    lines = [f"FUNCTION_BLOCK {name} {_note(note)}", ""]
    for section, variables in (("VAR_INPUT", base.inputs), ("VAR_OUTPUT", base.outputs)):
        lines += [section, *(f"    {v} : REAL;" for v in variables), "END_VAR", ""]
    for section, variables in (("FUZZIFY", base.inputs), ("DEFUZZIFY", base.outputs)):
        for var in variables.values():
            lines += [f"{section} {var.name}", f"    RANGE := ({_num(var.universe[0])} .. {_num(var.universe[1])});"]
            for term in var.terms.values():
                a, b, c, d = term.points
                shape = f"TRIAN {_num(a)} {_num(b)} {_num(d)}" if b == c else f"TRAP {' '.join(map(_num, term.points))}"
                lines.append(f"    TERM {term.name} := {shape};")
            if var.default is not None:
                lines += ["    METHOD : COG;", f"    DEFAULT := {_num(var.default)};"]
            lines += [f"END_{section}", ""]
    lines += ["RULEBLOCK rules", "    AND : MIN;", "    ACT : MIN;", "    ACCU : MAX;"]
    for n, rule in enumerate(base.rules, 1):
        condition = " AND ".join(f"{v} IS {t}" for v, t in rule.conditions)
        conclusion = ", ".join(f"{v} IS {t}" for v, t in rule.conclusions)
        lines.append(f"    RULE {n} : IF {condition} THEN {conclusion}; {_note({'id': rule.id})}")
    return lines + ["END_RULEBLOCK", "", "END_FUNCTION_BLOCK", ""]


def _num(x: float) -> str:
    return repr(float(x))


def _note(values: dict) -> str:
    """An annotation: JSON (a YAML flow mapping) in a comment, '*)' escaped so the comment cannot end early."""
    return "(*@ " + json.dumps(values, ensure_ascii=False).replace("*)", "*\\u0029") + " *)"


# ------------------------------------------------------------------------------------------ reader


class _Tokens:
    """The tokens of an FCL text, each ``(kind, text, line, col)``; annotations kept, comments dropped."""

    def __init__(self, text: str, source: str):
        self.source, self.items, self.i = source, [], 0
        pos, line, start = 0, 1, 0
        while pos < len(text):
            m = TOKEN.match(text, pos)
            if m is None:
                raise KnowledgeError(
                    f"unexpected character {text[pos]!r}",
                    where=f"{source}:{line}:{pos - start + 1}",
                    fix="FCL has names, numbers, := .. : ; ( ) , and (* comments *)",
                )
            kind = m.lastgroup if m.lastgroup != "body" else "note"
            if kind not in ("space", "comment"):
                value = m.group("body") if kind == "note" else m.group()
                self.items.append((kind, value, line, pos - start + 1))
            newlines = m.group().count("\n")
            if newlines:
                line += newlines
                start = pos + m.group().rindex("\n") + 1
            pos = m.end()
        self.items.append(("end", "end of file", line, pos - start + 1))

    def where(self, token=None) -> str:
        _, _, line, col = token or self.items[self.i]
        return f"{self.source}:{line}:{col}"

    def peek(self):
        return self.items[self.i]

    def is_word(self, *words) -> bool:
        kind, text, *_ = self.peek()
        return kind == "name" and text.upper() in words

    def take(self, kind=None, word=None, fix=None):
        token = self.peek()
        if (kind and token[0] != kind) or (word and (token[0] not in ("name", "punct") or token[1].upper() != word)):
            wanted = f"'{word}'" if word else {"name": "a name", "number": "a number"}.get(kind, kind)
            raise KnowledgeError(f"expected {wanted}, found '{token[1]}'", where=self.where(token), fix=fix)
        self.i += 1
        return token

    def note(self) -> Located | None:
        """The annotation here, if any, as a located mapping."""
        if self.peek()[0] != "note":
            return None
        _, body, line, col = self.take("note")
        where = f"{self.source}:{line}:{col}"
        value = parse_yaml(body, where, KnowledgeError)
        if not isinstance(value, Located):
            raise KnowledgeError(
                "an annotation (*@ ... *) must hold a mapping", where=where, fix="write e.g. (*@ {id: delete-small} *)"
            )
        return _relocate(value, self.source, line, col + 3)


def _relocate(value, source: str, line: int, col: int):
    """Positions of a one-line annotation parsed on its own, moved to where it stands in the file."""
    if isinstance(value, Located):
        value.source = source
        value.line, value.col = line + value.line - 1, col + value.col - 1
        value.key_marks = {k: (line + ln - 1, col + c - 1) for k, (ln, c) in value.key_marks.items()}
        for v in value.values():
            _relocate(v, source, line, col)
    elif isinstance(value, list):
        for v in value:
            _relocate(v, source, line, col)
    return value


def _node(tokens: _Tokens, token, items=()) -> Located:
    node = Located()
    node.source, node.line, node.col = tokens.source, token[2], token[3]
    for key, value, mark in items:
        _put(node, key, value, mark)
    return node


def _put(node: Located, key, value, mark) -> None:
    node[key] = value
    node.key_marks[key] = (mark[2], mark[3])


def _merge(node: Located, note: Located | None) -> None:
    for key, value in (note or {}).items():
        if key in node:
            raise KnowledgeError(
                f"the annotation sets '{key}', which the FCL already gives",
                where=note.where(key),
                fix=f"remove '{key}' from the annotation",
            )
        _put(node, key, value, (None, None, *note.key_marks[key]))


def parse_fcl(text: str, source: str) -> Located:
    """The located tree of a rules file (``kind: rules``) that the FCL text says."""
    tokens = _Tokens(text, source)
    root = _node(tokens, tokens.peek(), [("kind", "rules", tokens.peek())])
    _merge(root, tokens.note())
    bases = _node(tokens, tokens.peek())
    while tokens.peek()[0] != "end":
        name, base = _function_block(tokens)
        if name[1] in bases:
            raise KnowledgeError(
                f"FUNCTION_BLOCK '{name[1]}' is defined twice",
                where=tokens.where(name),
                fix="give each FUNCTION_BLOCK its own name",
            )
        _put(bases, name[1], base, name)
    if not bases:
        raise KnowledgeError(
            "no FUNCTION_BLOCK", where=tokens.where(), fix="write FUNCTION_BLOCK NAME ... END_FUNCTION_BLOCK"
        )
    if "id" not in root:
        _put(root, "id", Path(source).stem, (None, None, 1, 1))
    _put(root, "rulebases", bases, tokens.items[0])
    return root


def _function_block(tokens: _Tokens):
    tokens.take(word="FUNCTION_BLOCK", fix="an FCL file is one or more FUNCTION_BLOCK ... END_FUNCTION_BLOCK")
    name = tokens.take("name", fix="name the FUNCTION_BLOCK (the rule base's name)")
    base = _node(tokens, name)
    _merge(base, tokens.note())
    declared = {"VAR_INPUT": _node(tokens, name), "VAR_OUTPUT": _node(tokens, name)}
    blocks = {"FUZZIFY": declared["VAR_INPUT"], "DEFUZZIFY": declared["VAR_OUTPUT"]}
    rules = None
    while not tokens.is_word("END_FUNCTION_BLOCK"):
        start = tokens.peek()
        if tokens.is_word("VAR_INPUT", "VAR_OUTPUT"):
            _declarations(tokens, declared[tokens.take()[1].upper()])
        elif tokens.is_word("FUZZIFY", "DEFUZZIFY"):
            _variable(tokens, blocks)
        elif tokens.is_word("RULEBLOCK"):
            if rules is not None:
                raise KnowledgeError(
                    "a second RULEBLOCK",
                    where=tokens.where(start),
                    fix="put all rules of a FUNCTION_BLOCK into one RULEBLOCK",
                )
            rules = _ruleblock(tokens)
        else:
            raise KnowledgeError(
                f"expected VAR_INPUT, VAR_OUTPUT, FUZZIFY, DEFUZZIFY, RULEBLOCK or "
                f"END_FUNCTION_BLOCK, found '{start[1]}'",
                where=tokens.where(start),
            )
    end = tokens.take()
    for section, variables in declared.items():
        block = "FUZZIFY" if section == "VAR_INPUT" else "DEFUZZIFY"
        for var, body in variables.items():
            if "terms" not in body:
                raise KnowledgeError(
                    f"'{var}' has no {block} block",
                    where=variables.where(var),
                    fix=f"add {block} {var} with RANGE := (low .. high); and TERMs",
                )
    if rules is None:
        raise KnowledgeError(
            f"FUNCTION_BLOCK '{name[1]}' has no RULEBLOCK",
            where=tokens.where(end),
            fix="add RULEBLOCK NAME ... END_RULEBLOCK with its RULEs",
        )
    _put(base, "inputs", declared["VAR_INPUT"], name)
    _put(base, "outputs", declared["VAR_OUTPUT"], name)
    _put(base, "rules", rules[1], rules[0])
    return name, base


def _declarations(tokens: _Tokens, variables: Located) -> None:
    while not tokens.is_word("END_VAR"):
        name = tokens.take("name", fix="declare each variable as NAME : REAL;")
        if name[1] in variables:
            raise KnowledgeError(f"variable '{name[1]}' is declared twice", where=tokens.where(name))
        tokens.take(word=":")
        tokens.take(word="REAL", fix="fuzzymesh variables are REAL")
        tokens.take(word=";")
        var = _node(tokens, name)
        _merge(var, tokens.note())
        _put(variables, name[1], var, name)
    tokens.take()


def _variable(tokens: _Tokens, blocks: dict) -> None:
    block = tokens.take()[1].upper()
    name = tokens.take("name")
    variables = blocks[block]
    if name[1] not in variables:
        kind = "VAR_INPUT" if block == "FUZZIFY" else "VAR_OUTPUT"
        raise KnowledgeError(
            f"{block} '{name[1]}' is not declared in {kind}",
            where=tokens.where(name),
            fix=f"declare it: {kind} {name[1]} : REAL; END_VAR",
        )
    var = variables[name[1]]
    if "terms" in var:
        raise KnowledgeError(f"a second {block} block for '{name[1]}'", where=tokens.where(name))
    terms = _node(tokens, name)
    while not tokens.is_word(f"END_{block}"):
        word = tokens.take(
            "name", fix=f"a {block} block holds RANGE, TERM{', METHOD, DEFAULT, ACCU' if block == 'DEFUZZIFY' else ''}"
        )
        key = word[1].upper()
        if key == "RANGE":
            tokens.take(word=":=")
            tokens.take(word="(")
            low = float(tokens.take("number")[1])
            tokens.take(word="..")
            high = float(tokens.take("number")[1])
            tokens.take(word=")")
            _put(var, "universe", [low, high], word)
        elif key == "TERM":
            label = tokens.take("name")
            tokens.take(word=":=")
            shape = tokens.take("name", fix="give TRAP a b c d or TRIAN a b c")
            count = SHAPES.get(shape[1].upper())
            if count is None:
                raise KnowledgeError(
                    f"membership function '{shape[1]}' is not supported",
                    where=tokens.where(shape),
                    fix="give TRAP a b c d (trapezoid) or TRIAN a b c (triangle)",
                )
            if label[1] in terms:
                raise KnowledgeError(f"term '{label[1]}' of '{name[1]}' is defined twice", where=tokens.where(label))
            _put(terms, label[1], [float(tokens.take("number")[1]) for _ in range(count)], label)
        elif block == "DEFUZZIFY" and key == "DEFAULT":
            tokens.take(word=":=")
            _put(var, "default", float(tokens.take("number", fix="DEFAULT := NUMBER; (NC is not supported)")[1]), word)
        elif block == "DEFUZZIFY" and key in ("METHOD", "ACCU"):
            _setting(tokens, word)
            continue
        else:
            raise KnowledgeError(f"'{word[1]}' is not allowed in a {block} block", where=tokens.where(word))
        tokens.take(word=";")
    tokens.take()
    if "universe" not in var:
        raise KnowledgeError(
            f"{block} '{name[1]}' has no RANGE",
            where=tokens.where(name),
            fix="add RANGE := (low .. high); (inputs are clipped to it)",
        )
    _put(var, "terms", terms, name)


def _setting(tokens: _Tokens, word) -> None:
    """``KEY : VALUE;`` of the inference: only fuzzymesh's own is accepted."""
    tokens.take(word=":")
    value = tokens.take("name")
    if value[1].upper() != SETTINGS[word[1].upper()]:
        raise KnowledgeError(f"{word[1]} : {value[1]} is not supported", where=tokens.where(value), fix=FIX_SETTING)
    tokens.take(word=";")


def _ruleblock(tokens: _Tokens):
    start = tokens.take()
    tokens.take("name", fix="name the RULEBLOCK")
    rules = []
    while not tokens.is_word("END_RULEBLOCK"):
        word = tokens.take("name", fix="a RULEBLOCK holds AND, ACT, ACCU and RULEs")
        key = word[1].upper()
        if key in ("AND", "ACT", "ACCU"):
            _setting(tokens, word)
        elif key == "OR":
            raise KnowledgeError(
                "OR is not supported",
                where=tokens.where(word),
                fix="fuzzymesh rules have no OR: write one rule per alternative",
            )
        elif key == "RULE":
            rules.append(_rule(tokens, word))
        else:
            raise KnowledgeError(f"'{word[1]}' is not allowed in a RULEBLOCK", where=tokens.where(word))
    tokens.take()
    return start, rules


def _rule(tokens: _Tokens, start) -> Located:
    label = tokens.peek()
    if label[0] not in ("number", "name"):
        raise KnowledgeError(
            f"expected the rule's number, found '{label[1]}'",
            where=tokens.where(label),
            fix="number the rule: RULE 1 : IF ... THEN ...;",
        )
    tokens.take()
    tokens.take(word=":")
    rule = _node(tokens, start)
    if_token = tokens.take(word="IF")
    condition = _clauses(tokens, if_token, "AND")
    then_token = tokens.take(
        word="THEN", fix="write IF v IS T AND ... THEN out IS T; (OR, NOT, WITH and parentheses are not supported)"
    )
    conclusion = _clauses(tokens, then_token, ",")
    tokens.take(word=";", fix="end the rule with ';' (OR, NOT and WITH are not supported)")
    _put(rule, "if", condition, if_token)
    _put(rule, "then", conclusion, then_token)
    note = tokens.note()
    if note is None or "id" not in note:
        _put(rule, "id", label[1], label)
    _merge(rule, note)
    return rule


def _clauses(tokens: _Tokens, start, joiner: str) -> Located:
    clauses = _node(tokens, start)
    while True:
        var = tokens.take("name", fix="write VARIABLE IS TERM")
        if tokens.is_word("NOT"):
            raise KnowledgeError("IS NOT is not supported", where=tokens.where(), fix="name the terms it means")
        tokens.take(word="IS", fix="write VARIABLE IS TERM")
        if tokens.is_word("NOT"):
            raise KnowledgeError("IS NOT is not supported", where=tokens.where(), fix="name the terms it means")
        term = tokens.take("name", fix="write VARIABLE IS TERM")
        if var[1] in clauses:
            raise KnowledgeError(
                f"'{var[1]}' appears twice in one rule", where=tokens.where(var), fix="a rule tests each variable once"
            )
        _put(clauses, var[1], term[1], var)
        if joiner == "AND" and tokens.is_word("AND") or joiner == "," and tokens.peek()[1] == ",":
            tokens.take()
        else:
            return clauses


def load_fcl(path: str | Path) -> Located:
    """Read an FCL file as the located tree of a rules file; unreadable files and syntax errors are one line."""
    path = Path(path)
    return parse_fcl(read_text(path, "FCL", KnowledgeError), str(path))


__all__ = ["to_fcl", "parse_fcl", "load_fcl"]
