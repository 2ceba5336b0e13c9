"""A corpus of broken knowledge and job files: each names its one defect, and the CLI must say so in one line.

Every file under ``tests/broken/`` has exactly one defect and a first line::

    # expect: line N: "a fragment of the message"

Knowledge files (``rules/``, ``patterns/``, ``recipes/``, ``features/``,
``sizing/``) are linted with ``fuzzymesh lint FILE``: exit code 1, exactly one
output line (stdout and stderr together, Python warnings included), starting
with ``FILE:N:``, containing the fragment, no traceback.

Job files (``jobs/``) are run with ``fuzzymesh mesh FILE --quiet --out TMP``:
exit code 2, exactly one stderr line ``fuzzymesh: error: FILE:N:...`` with the
fragment, and nothing written. The packer is replaced by a tripwire, so a case
that slipped through validation fails fast instead of meshing.

Cases the engine gets wrong today are listed in :data:`KNOWN_BUGS` and run as
strict xfails: when the engine is fixed, the xfail turns into a failure and the
entry is removed.

The rest checks ``lint`` on folders and on the shipped knowledge base, and the
``patterns`` / ``recipes`` commands.
"""

from __future__ import annotations

import contextlib
import logging
import re
import shutil
import sys
import warnings
from pathlib import Path

import pytest
import yaml

from engine.cli import main
from engine.knowledge import default_paths

BROKEN = Path(__file__).resolve().parent / "broken"
EXPECT = re.compile(r'^# expect: line (\d+): "(.+)"$')
JOB_FOLDER = "jobs"
MIN_CORPUS = 35

# corpus file (relative to tests/broken) -> why it fails today (strict xfail); empty when all pass
KNOWN_BUGS: dict[str, str] = {}


# --------------------------------------------------------------------------- helpers


def _corpus() -> list[Path]:
    return sorted(BROKEN.rglob("*.yaml"))


def _rel(path: Path) -> str:
    return path.relative_to(BROKEN).as_posix()


def _expectation(path: Path) -> tuple[int, str]:
    first = path.read_text(encoding="utf-8").splitlines()[0]
    match = EXPECT.match(first)
    assert match, f"{path}: the first line must be '# expect: line N: \"fragment\"', got {first!r}"
    return int(match[1]), match[2]


def _cases(jobs: bool) -> list:
    params = []
    for path in _corpus():
        rel = _rel(path)
        if rel.startswith(JOB_FOLDER + "/") != jobs:
            continue
        marks = [pytest.mark.xfail(strict=True, reason=KNOWN_BUGS[rel])] if rel in KNOWN_BUGS else []
        params.append(pytest.param(path, id=rel, marks=marks))
    return params


@contextlib.contextmanager
def _like_a_terminal():
    """Logging and Python warnings reach the captured stderr, as they would in a real run.

    pytest keeps handlers on the root logger (so ``main``'s ``basicConfig`` would
    do nothing) and records warnings itself; here the root logger has no
    handlers and warnings are printed to ``sys.stderr``. Everything is restored
    afterwards.
    """
    root = logging.getLogger()
    saved_handlers, saved_level = root.handlers[:], root.level
    for handler in saved_handlers:
        root.removeHandler(handler)

    def show(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = show
            yield
    finally:
        for handler in root.handlers[:]:
            root.removeHandler(handler)
        for handler in saved_handlers:
            root.addHandler(handler)
        root.setLevel(saved_level)


def _run(argv: list[str], capsys) -> tuple[int, list[str], list[str]]:
    capsys.readouterr()
    with _like_a_terminal():
        code = main(argv)
    out, err = capsys.readouterr()
    return code, out.splitlines(), err.splitlines()


def _no_meshing(*args, **kwargs):
    raise AssertionError("the job reached the packer: it should have failed validation")


def _shipped(folder: str) -> Path:
    path = next((p for p in default_paths() if p.name == folder), None)
    assert path is not None, f"no shipped '{folder}' folder in {default_paths()}"
    return path


def _words(text: str) -> str:
    return " ".join(text.split())


# --------------------------------------------------------------------------- the corpus itself


def test_corpus_is_large_enough_and_well_formed():
    files = _corpus()
    assert len(files) >= MIN_CORPUS, f"only {len(files)} broken files"
    for path in files:
        line, fragment = _expectation(path)
        assert 1 <= line <= len(path.read_text(encoding="utf-8").splitlines()), f"{path}: line {line} out of range"
        assert fragment.strip(), path
    assert set(KNOWN_BUGS) <= {_rel(p) for p in files}, "KNOWN_BUGS names a file that is not in the corpus"


@pytest.mark.parametrize("path", _cases(jobs=False))
def test_lint_names_the_defect_in_one_line(path, capsys):
    line_no, fragment = _expectation(path)
    code, out, err = _run(["lint", str(path)], capsys)
    lines = out + err
    text = "\n".join(lines)
    assert "Traceback" not in text and "internal error" not in text, text
    assert code == 1, f"exit code {code}: {text}"
    assert len(lines) == 1, f"expected one line, got {len(lines)}:\n{text}"
    assert lines[0].startswith(f"{path}:{line_no}:"), f"expected '{path}:{line_no}:...', got: {lines[0]}"
    assert fragment in lines[0], f"expected {fragment!r} in: {lines[0]}"


@pytest.mark.parametrize("path", _cases(jobs=True))
def test_job_fails_validation_in_one_line(path, capsys, tmp_path, monkeypatch):
    line_no, fragment = _expectation(path)
    monkeypatch.setattr("engine.pipeline.get_packer", lambda name: _no_meshing)  # looked up early, called late
    out_dir = tmp_path / "out"
    code, out, err = _run(["mesh", str(path), "--quiet", "--out", str(out_dir)], capsys)
    text = "\n".join(out + err)
    assert "Traceback" not in text and "internal error" not in text, text
    assert len(err) == 1, f"expected one stderr line, got {len(err)}:\n{text}"
    assert err[0].startswith(f"fuzzymesh: error: {path}:{line_no}:"), (
        f"expected 'fuzzymesh: error: {path}:{line_no}:...', got: {err[0]}"
    )
    assert fragment in err[0], f"expected {fragment!r} in: {err[0]}"
    assert code == 2, f"exit code {code}: {text}"
    assert not out_dir.exists() or not any(out_dir.iterdir()), "a failed job wrote files"


@pytest.mark.parametrize("name", ["unknown-recipe", "place-unknown-pattern"])
def test_job_names_are_checked_before_the_geometry_is_built(name, capsys, tmp_path, monkeypatch):
    path = BROKEN / JOB_FOLDER / f"{name}.yaml"
    line_no, fragment = _expectation(path)

    def no_geometry(*args, **kwargs):
        raise AssertionError("the geometry was built before the job's names were checked")

    monkeypatch.setattr("engine.pipeline.build_geometry", no_geometry)
    code, _, err = _run(["mesh", str(path), "--quiet", "--out", str(tmp_path / "out")], capsys)
    assert len(err) == 1 and err[0].startswith(f"fuzzymesh: error: {path}:{line_no}:") and fragment in err[0], err


def test_on_off_labels_are_not_turned_into_contradictory_messages(tmp_path, capsys):
    path = tmp_path / "switch.yaml"
    path.write_text(
        "kind: rules\nid: switch\nrulebases:\n  s:\n    inputs:\n      x:\n        universe: [0, 1]\n"
        "        terms: {OFF: [0, 0, 0.4, 0.6], ON: [0.4, 0.6, 1, 1]}\n    outputs:\n      q:\n"
        "        universe: [0, 1]\n        default: 0\n        terms: {LOW: [0, 0, 0.5], HIGH: [0.5, 1, 1]}\n"
        "    rules:\n      - {id: a, if: {x: OFF}, then: {q: LOW}}\n      - {id: b, if: {x: ON}, then: {q: HIGH}}\n"
    )
    code, out, err = _run(["lint", str(path)], capsys)
    # either the labels are names (ok), or the one error line says what to do about them
    assert (code == 0 and out[0].startswith("ok")) or (
        code == 1
        and len(out + err) == 1
        and out[0].startswith(f"{path}:")
        and "ON" in out[0][len(str(path)) :]
        and "defined labels: False, True" not in out[0]
    )


# --------------------------------------------------------------------------- lint on folders


def test_lint_without_arguments_checks_the_shipped_knowledge_base(capsys):
    code, out, err = _run(["lint"], capsys)
    assert code == 0, out + err
    assert len(out) == 1 and out[0].startswith("ok"), out
    assert err == []


def test_lint_of_a_folder_prints_one_line_per_broken_file(tmp_path, capsys):
    folder = tmp_path / "kb"
    chosen = ["rules/unknown-kind.yaml", "patterns/no-zones.yaml"]
    copies = []
    for rel in chosen:
        target = folder / rel.replace("/", "-")
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(BROKEN / rel, target)
        copies.append((target, *_expectation(target)))
    code, out, err = _run(["lint", str(folder)], capsys)
    assert code == 1, out + err
    assert err == []
    assert len(out) == 2, out
    for (path, line_no, fragment), line in zip(sorted(copies), out):
        assert line.startswith(f"{path}:{line_no}:") and fragment in line, line


PATTERN_TWICE = """\
kind: pattern
name: twice
doc: a pattern defined in two files
anchor: domain
zones:
  - id: base
    size: {law: constant, near: H}
    membership: {constant: 0.25}
"""


def test_a_pattern_defined_twice_is_an_error_naming_the_second_file(tmp_path, capsys):
    first, second = tmp_path / "a-first.yaml", tmp_path / "b-second.yaml"
    first.write_text(PATTERN_TWICE)
    second.write_text(PATTERN_TWICE.replace("two files", "two files, again"))
    code, out, err = _run(["lint", str(tmp_path)], capsys)
    assert code == 1, out + err
    assert len(out + err) == 1, out + err
    assert out[0].startswith(f"{second}:2:"), out[0]
    assert "'twice' is defined twice" in out[0] and str(first) in out[0], out[0]


def test_a_shipped_pattern_redefined_by_extra_knowledge_names_the_extra_file(tmp_path, capsys):
    extra = tmp_path / "my-hole.yaml"
    extra.write_text(PATTERN_TWICE.replace("name: twice", "name: hole"))
    code, out, err = _run(["patterns", "--knowledge", str(extra), "list"], capsys)
    assert code != 0 and out == [], out + err
    assert len(err) == 1 and err[0].startswith(f"fuzzymesh: error: {extra}:2:"), err
    assert "'hole' is defined twice" in err[0], err


# --------------------------------------------------------------------------- patterns and recipes commands


def test_patterns_list_names_every_shipped_pattern(capsys):
    code, out, err = _run(["patterns", "list"], capsys)
    assert code == 0 and err == [], err
    listed = {line.split()[0] for line in out if line.strip()}
    shipped = {yaml.safe_load(p.read_text())["name"] for p in _shipped("patterns").glob("*.yaml")}
    assert shipped and shipped <= listed, (shipped, listed)


def test_patterns_show_hole_prints_its_doc_and_zones(capsys):
    code, out, err = _run(["patterns", "show", "hole"], capsys)
    assert code == 0 and err == [], err
    text = "\n".join(out)
    spec = yaml.safe_load((_shipped("patterns") / "hole.yaml").read_text())
    assert out[0].startswith("pattern hole"), out[0]
    assert _words(spec["doc"]) in _words(text)
    assert f"anchor: {spec['anchor']}" in text
    for zone in spec["zones"]:
        assert f"zone {zone['id']} " in text
    for name in spec.get("parameters", {}):
        assert f"  {name} (" in text


def test_recipes_list_names_every_shipped_recipe(capsys):
    code, out, err = _run(["recipes", "list"], capsys)
    assert code == 0 and err == [], err
    listed = {line.split()[0] for line in out if line.strip()}
    shipped = {yaml.safe_load(p.read_text())["name"] for p in (_shipped("knowledge") / "recipes").glob("*.yaml")}
    assert shipped and shipped <= listed, (shipped, listed)


def test_recipes_show_junction_edge_prints_its_doc_and_placements(capsys):
    code, out, err = _run(["recipes", "show", "junction-edge"], capsys)
    assert code == 0 and err == [], err
    spec = yaml.safe_load((_shipped("knowledge") / "recipes" / "junction-edge.yaml").read_text())
    text = "\n".join(out)
    assert out[0].startswith("recipe junction-edge"), out[0]
    assert _words(spec["doc"]) in _words(text)
    places = out[out.index("places:") + 1 :]
    assert len(places) == len(spec["place"]), places
    for line, placement in zip(places, spec["place"]):
        assert line.split()[0] == placement["pattern"], line
        if "every" in placement:
            assert f"on every {placement['every']}" in line, line
        for role, feature in placement.get("roles", {}).items():
            assert f"{role} -> '{feature}'" in line, line


@pytest.mark.parametrize("noun", ["patterns", "recipes"])
def test_show_of_an_unknown_name_is_one_error_line(noun, capsys):
    code, out, err = _run([noun, "show", "nope"], capsys)
    assert code == 2, out + err
    assert out == [] and len(err) == 1, out + err
    assert err[0].startswith("fuzzymesh: error:") and "'nope'" in err[0], err
    assert ("hole" if noun == "patterns" else "junction-edge") in err[0], "the error should list the known names"
