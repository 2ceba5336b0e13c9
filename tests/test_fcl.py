"""FCL (IEC 61131-7): export, round trip, loading with located errors, a job's population rules in FCL, and
conformance of fuzzymesh's inference with fuzzylite's (pyfuzzylite) on the shipped rule bases."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from engine.cli import main
from engine.fcl import parse_fcl, to_fcl
from engine.job import load_job
from engine.knowledge import lint, load_knowledge, load_rules
from engine.pipeline import run

SHIPPED = load_knowledge()
POPULATION = ["population.delete", "population.insert"]


def content(base):
    """Everything a rule base computes and cites, without the file positions."""
    return (
        base.id,
        base.inputs,
        base.outputs,
        [(r.id, r.conditions, r.conclusions) for r in base.rules],
        base.resolution,
        base.extra,
    )


def exported(tmp_path, name="population", *extra) -> Path:
    out = tmp_path / f"{name}.fcl"
    assert main(["rules", "export", name, "--fcl", "-o", str(out), *extra]) == 0
    return out


def test_round_trip_yaml_fcl_yaml_gives_identical_rule_bases_and_settings(tmp_path):
    bases, settings = load_rules(parse_fcl(exported(tmp_path).read_text(), "population.fcl"), "population.fcl")
    assert sorted(bases) == POPULATION
    for name in POPULATION:
        assert content(bases[name]) == content(SHIPPED.rulebases[name])
    assert settings == SHIPPED.packer_settings["population"]


def test_the_demo_rule_base_round_trips_with_two_inputs_triangles_and_several_conclusions(tmp_path):
    demo = tmp_path / "demo.yaml"
    demo.write_text(
        yaml.safe_dump(
            {
                "kind": "rules",
                "id": "demo",
                "rulebases": {
                    "x": {
                        "resolution": 201,
                        "inputs": {
                            "a": {"universe": [0, 2], "terms": {"LO": [0, 0, 1], "HI": [0.5, 1.5, 2, 2]}},
                            "b": {"universe": [-1, 1], "terms": {"ANY": [-1, -1, 1, 1]}},
                        },
                        "outputs": {
                            "p": {
                                "universe": [0, 1],
                                "default": 0.25,
                                "terms": {"S": [0, 0.2, 0.4], "L": [0.3, 0.8, 1, 1]},
                            },
                            "r": {"universe": [5, 6], "default": 5.5, "terms": {"M": [5, 5.5, 6]}},
                        },
                        "rules": [
                            {"id": "lo", "if": {"a": "LO", "b": "ANY"}, "then": {"p": "S", "r": "M"}},
                            {"id": "hi", "if": {"a": "HI"}, "then": {"p": "L"}},
                        ],
                    }
                },
            }
        )
    )
    out = exported(tmp_path, "demo.x", "--knowledge", str(demo))
    text = out.read_text()
    assert "TERM LO := TRIAN 0.0 0.0 1.0;" in text and "IF a IS LO AND b IS ANY THEN p IS S, r IS M;" in text
    original = load_knowledge([demo]).rulebases["demo.x"]
    bases, _ = load_rules(parse_fcl(text, str(out)), str(out))
    assert content(bases["demo.x"]) == content(original)


def test_export_writes_the_standard_blocks():
    text = to_fcl([SHIPPED.rulebases["population.delete"]], "population")
    for line in [
        "FUNCTION_BLOCK delete",
        "VAR_INPUT",
        "overlap : REAL;",
        "VAR_OUTPUT",
        "FUZZIFY overlap",
        "RANGE := (1.0 .. 3.0);",
        "TERM LARGE := TRAP 1.12 1.2 3.0 3.0;",
        "DEFUZZIFY q",
        "METHOD : COG;",
        "DEFAULT := 0.0;",
        "RULEBLOCK rules",
        "AND : MIN;",
        "ACT : MIN;",
        "ACCU : MAX;",
        "RULE 3 : IF overlap IS LARGE THEN q IS LARGE;",
        "END_FUNCTION_BLOCK",
    ]:
        assert line in text, line


def test_a_plain_fcl_file_without_annotations_loads_with_its_stem_and_rule_numbers(tmp_path):
    text = re.sub(r"\(\*@ \{.*?\} \*\)", "", to_fcl([SHIPPED.rulebases["population.delete"]], "population"))
    assert "(*@ {" not in text
    text = text.lower().replace("overlap", "Overlap")  # keywords in any case, names as written
    path = tmp_path / "plain.fcl"
    path.write_text(text)
    kb = load_knowledge([path])
    base = kb.rulebases["plain.delete"]
    assert [r.id for r in base.rules] == ["1", "2", "3"] and "action" not in base.extra
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "rule 2 :" in t)
    assert base.rules[1].source == f"{path}:{line}:5"


@pytest.mark.parametrize(
    "edit, line_of, message",
    [
        (
            ("TRAP 1.03 1.08 1.12 1.2", "TRAP 1.03 1.08 1.12"),
            "TERM MEDIUM := TRAP 1.03",
            "expected a number, found ';'",
        ),
        (("IS MEDIUM THEN q", "IS MEDUIM THEN q"), "IS MEDUIM", "label 'MEDUIM' is not defined for input 'overlap'"),
        (("TRAP 1.12 1.2 3.0 3.0", "TRAP 1.3 1.4 3.0 3.0"), "coverage", "no rule fires at overlap = 1.2"),
        (("ACCU : MAX", "ACCU : BSUM"), "ACCU : BSUM", "ACCU : BSUM is not supported"),
        (("IS SMALL THEN q IS SMALL", "IS SMALL OR overlap IS LARGE THEN q IS SMALL"), "OR overlap", "expected 'THEN'"),
        (("TRAP 0.5 0.7 1.0 1.0", "GAUSS 0.7 0.1"), "GAUSS", "membership function 'GAUSS' is not supported"),
        (("0.45", "1.45"), "1.45", "action threshold 1.45 lies outside the universe of 'q'"),
        (("    RANGE := (1.0 .. 3.0);\n", ""), "FUZZIFY overlap", "FUZZIFY 'overlap' has no RANGE"),
    ],
)
def test_broken_fcl_is_one_located_line_in_lint(tmp_path, edit, line_of, message):
    text = to_fcl([SHIPPED.rulebases["population.delete"]], "population").replace('"population"', '"mine"')
    assert edit[0] in text
    broken = text.replace(edit[0], edit[1], 1)
    path = tmp_path / "broken.fcl"
    path.write_text(broken)
    errors = lint([tmp_path])
    assert len(errors) == 1 and "\n" not in errors[0], errors
    lines = broken.splitlines()
    line = next(i for i, t in enumerate(lines, 1) if (line_of in t if line_of != "coverage" else "RULEBLOCK" in t))
    assert re.match(rf"{re.escape(str(path))}:{line}:\d+: ", errors[0]), (errors[0], line)
    assert message in errors[0]


def test_a_jobs_population_rules_in_fcl_replace_the_shipped_ones(tmp_path):
    text = exported(tmp_path / "..", "population").read_text()
    text = text.replace('{"id": "population"', '{"id": "population", "overrides": true', 1)
    text = text.replace('"insert-large"', '"insert-large-fcl"')
    rules = tmp_path / "rules"
    rules.mkdir()
    (rules / "population.fcl").write_text(text)
    job = tmp_path / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {"geometry": {"shape": "cylinder"}, "size": 12.0, "knowledge": ["rules"], "output": {"formats": ["vtu"]}}
        )
    )
    result = run(load_job(job))
    assert "population.insert/insert-large-fcl" in set(result.packing.events.rule), "the packer read the FCL rules"
    legend = json.loads((tmp_path / "out" / "mesh.audit.json").read_text())
    cited = {r["id"]: r["source"] for r in legend["rules"]}
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "insert-large-fcl" in t)
    assert cited["population.insert/insert-large-fcl"] == f"{rules / 'population.fcl'}:{line}:5"


# ------------------------------------------------------------------------------ conformance with fuzzylite


def fuzzylite_engine(base):
    """A pyfuzzylite Mamdani engine of the rule base: AND min, implication min, aggregation max, centroid."""
    fl = pytest.importorskip("fuzzylite")

    def variable(cls, var):
        v = cls(name=var.name, minimum=var.universe[0], maximum=var.universe[1])
        v.terms = [fl.Trapezoid(t.name, *t.points) for t in var.terms.values()]
        return v

    engine = fl.Engine(name=base.id.replace(".", "_"))
    engine.input_variables = [variable(fl.InputVariable, v) for v in base.inputs.values()]
    outputs = []
    for var in base.outputs.values():
        out = variable(fl.OutputVariable, var)
        out.default_value = var.default
        out.aggregation = fl.Maximum()
        out.defuzzifier = fl.Centroid(base.resolution)
        outputs.append(out)
    engine.output_variables = outputs
    block = fl.RuleBlock(name="rules", conjunction=fl.Minimum(), implication=fl.Minimum(), activation=fl.General())
    for rule in base.rules:
        condition = " and ".join(f"{v} is {t}" for v, t in rule.conditions)
        conclusion = " and ".join(f"{v} is {t}" for v, t in rule.conclusions)
        block.rules.append(fl.Rule.create(f"if {condition} then {conclusion}", engine))
    engine.rule_blocks = [block]
    return engine


@pytest.mark.parametrize("name", POPULATION)
def test_shipped_rule_bases_agree_with_fuzzylite_within_the_resolution(tmp_path, name):
    """The rule base read back from its FCL export, evaluated by fuzzymesh and by fuzzylite on a grid of each
    input's universe: both integrate the same shape on grids of ``resolution`` points (end points against
    midpoints), so they agree within one step of that grid."""
    text = exported(tmp_path).read_text()
    base = load_rules(parse_fcl(text, "population.fcl"), "population.fcl")[0][name]
    engine = fuzzylite_engine(base)
    (var,) = base.inputs.values()
    grid = np.linspace(*var.universe, 401)
    ours = base.evaluate({var.name: grid})[0]
    (output,) = base.outputs.values()
    step = (output.universe[1] - output.universe[0]) / (base.resolution - 1)
    theirs = []
    for x in grid:
        engine.input_variables[0].value = float(x)
        engine.process()
        theirs.append(engine.output_variables[0].value)
    difference = np.abs(ours[output.name] - np.array(theirs))
    assert difference.max() <= step, (grid[difference.argmax()], difference.max(), step)
    assert np.ptp(ours[output.name]) > 0.5, "the grid spans the rule base's range of outputs"
