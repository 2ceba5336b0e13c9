"""What lint finds without a solid, and what mesh finds the same way before any work (issue 16, item 4):
patterns evaluated at sample L and H, names shadowing the shipped ones unless a file says it overrides them,
every file's first error from a folder, recipes included. The one-file cases are in tests/broken/."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from engine.cli import main
from engine.knowledge import load_knowledge

BROKEN = Path(__file__).resolve().parent / "broken"
SHIPPED = Path(__file__).resolve().parents[1]

PATTERN = """\
kind: pattern
name: {name}
doc: small elements at a hole wall
anchor: surface
accepts: [hole]
scale: radius
parameters:
  near: {{default: 0.1, doc: "size at the wall, times the radius"}}
zones:
  - id: wall
    size: {{law: linear, near: {near}, far: H, over: 3 * L}}
    membership: {{trapezoid: [-1, 0, 3 * L, 6 * L]}}
"""


def _run(argv, capsys):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out.splitlines(), err.splitlines()


def _copy(name: str, folder: Path) -> Path:
    target = folder / name.replace("/", "-")
    shutil.copy(BROKEN / name, target)
    return target


def test_lint_of_a_folder_gives_every_files_first_error_recipes_included(tmp_path, capsys):
    folder = tmp_path / "kb"
    folder.mkdir()
    broken = [_copy(name, folder) for name in ("patterns/value-divide-by-zero.yaml", "recipes/unknown-pattern.yaml")]
    (folder / "z-recipe.yaml").write_text(
        (BROKEN / "recipes/placed-parameter-extent-zero.yaml").read_text().replace("broken-static", "other")
    )
    (folder / "fine.yaml").write_text(PATTERN.format(name="fine-hole", near="near * L"))
    code, out, err = _run(["lint", folder], capsys)
    assert code == 1 and err == [], out + err
    assert len(out) == 3, out
    for path in [*broken, folder / "z-recipe.yaml"]:
        (line,) = [line for line in out if line.startswith(f"{path}:")]
    assert "divides by zero" in out[0]
    assert any("unknown pattern 'holes'" in line for line in out)
    assert any("'over' (extent * L) is 0" in line and "hole.yaml:" in line for line in out)


def test_a_file_that_says_it_overrides_a_shipped_pattern_replaces_it(tmp_path, capsys):
    mine = tmp_path / "my-hole.yaml"
    mine.write_text(
        PATTERN.format(name="hole", near="near * L")
        .replace("name: hole", "name: hole\noverrides: true")
        .replace("small elements at a hole wall", "my own hole pattern")
    )
    code, out, err = _run(["lint", mine], capsys)
    assert (code, out, err) == (0, [f"ok: {mine}"], [])
    code, out, err = _run(["patterns", "--knowledge", mine, "show", "hole"], capsys)
    assert code == 0 and "my own hole pattern" in "\n".join(out), out + err
    # the shipped recipes that place 'hole' are checked against the new one
    assert load_knowledge([mine]).patterns["hole"].source == str(mine)


def test_a_copy_of_the_population_rules_that_says_it_overrides_them_replaces_them(tmp_path, capsys):
    copy = tmp_path / "population.yaml"
    copy.write_text(
        (SHIPPED / "knowledge" / "population.yaml")
        .read_text()
        .replace("kind: rules", "kind: rules\noverrides: true", 1)
    )
    code, out, err = _run(["lint", copy], capsys)
    assert (code, err) == (0, []) and out == [f"ok: {copy}"]
    kb = load_knowledge([copy])
    assert {rb.source.split(":")[0] for rb in kb.rulebases.values()} == {str(copy)}


def test_mesh_runs_the_same_checks_before_the_geometry(tmp_path, capsys, monkeypatch):
    def no_geometry(*args, **kwargs):
        raise AssertionError("the geometry was built before the knowledge was checked")

    monkeypatch.setattr("engine.pipeline.build_geometry", no_geometry)
    pattern = _copy("patterns/value-overflow.yaml", tmp_path)
    job = tmp_path / "job.yaml"
    job.write_text(f"geometry: {{shape: plate_with_hole}}\nknowledge: [{pattern.name}]\n")
    code, out, err = _run(["mesh", job, "--quiet", "--out", tmp_path / "out"], capsys)
    assert code == 2 and len(err) == 1, out + err
    assert err[0].startswith(f"fuzzymesh: error: {pattern}:15:") and "overflows" in err[0], err


def test_a_binding_error_names_the_placement_and_the_patterns_own_line(tmp_path, capsys):
    # at the sample L and H the size is positive; at the hole's radius 7 it is not
    pattern = tmp_path / "odd.yaml"
    pattern.write_text(PATTERN.format(name="odd-hole", near='"0.01 * L * (L - 5) * (L - 9)"'))
    job = tmp_path / "job.yaml"
    job.write_text(
        "geometry: {shape: plate_with_hole, parameters: {hole_radius: 7}}\n"
        "size: 10\n"
        "knowledge: [odd.yaml]\n"
        "place:\n"
        "  - pattern: uniform-domain\n"
        "  - pattern: odd-hole\n"
        "    every: hole\n"
    )
    code, out, err = _run(["mesh", job, "--quiet", "--out", tmp_path / "out"], capsys)
    assert code == 2 and len(err) == 1, out + err
    line = err[0]
    assert line.startswith(f"fuzzymesh: error: {job}:6:5: pattern 'odd-hole', zone 'wall': 'near'"), line
    assert "not > 0 at L = 7" in line and "on patch-" in line and f"{pattern}:11:" in line and "; " in line, line
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


@pytest.mark.parametrize("text", ["", "# only a comment\n"], ids=["zero-bytes", "comment"])
def test_an_empty_knowledge_file_is_located_at_its_first_line(tmp_path, capsys, text):
    path = tmp_path / "empty.yaml"
    path.write_text(text)
    code, out, err = _run(["lint", path], capsys)
    assert code == 1 and out == [f"{path}:1:1: the file is empty; write the YAML content"], out + err
