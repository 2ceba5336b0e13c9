"""Population rules per job: a job's knowledge folder replaces the shipped rule file by id, the audit cites
the rules that fired by the file that defined them, every event is saved, and explain tells a node's history."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml

from engine.cli import main
from engine.errors import KnowledgeError
from engine.job import load_job
from engine.knowledge import default_paths, load_knowledge
from engine.pipeline import run

SHIPPED = next(p for p in default_paths() if p.name == "knowledge") / "population.yaml"


def mesh_with(folder: Path, rule_file: str) -> tuple[Path, object]:
    """Mesh a coarse cylinder with ``rule_file`` (text) in the job's knowledge folder: (output folder, result)."""
    (folder / "rules").mkdir()
    (folder / "rules" / "population.yaml").write_text(rule_file)
    job = folder / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {"geometry": {"shape": "cylinder"}, "size": 12.0, "knowledge": ["rules"], "output": {"formats": ["vtu"]}}
        )
    )
    return folder / "out", run(load_job(job))


def line_of(path: Path, text: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if text in line)


@pytest.fixture(scope="module")
def replaced(tmp_path_factory):
    """The shipped rules copied with 'overrides: true' and one rule renamed, so its events show the copy was read."""
    text = "overrides: true\n" + SHIPPED.read_text().replace("id: insert-large,", "id: insert-large-job,")
    folder = tmp_path_factory.mktemp("replaced")
    return (folder / "rules" / "population.yaml",) + mesh_with(folder, text)


def test_a_plain_copy_is_refused_with_the_way_to_replace(tmp_path):
    (tmp_path / "population.yaml").write_text(SHIPPED.read_text())
    with pytest.raises(KnowledgeError) as error:
        load_knowledge([tmp_path])
    assert "defined twice" in str(error.value) and "overrides: true" in str(error.value)


def test_a_copy_with_overrides_replaces_the_shipped_rules_and_the_audit_cites_it(replaced):
    copy, out, result = replaced
    events = result.packing.events
    assert "population.insert/insert-large-job" in set(events.rule), "the packer read the job's copy"
    legend = json.loads((out / "mesh.audit.json").read_text())
    assert {r["id"] for r in legend["rules"]} == set(events.rule)
    for rule in legend["rules"]:
        path, line, _ = re.fullmatch(r"(.+):(\d+):(\d+)", rule["source"]).groups()
        assert Path(path).resolve() == copy.resolve(), rule
        assert int(line) == line_of(copy, f"id: {rule['id'].split('/')[1]},"), rule


def test_a_renamed_copy_is_reported_unread_and_the_shipped_rules_are_cited(tmp_path, caplog):
    text = SHIPPED.read_text().replace("id: population", "id: my-population")
    with caplog.at_level(logging.WARNING):
        out, result = mesh_with(tmp_path, text)
    warning = next(r.getMessage() for r in caplog.records if "is not read" in r.getMessage())
    assert str(tmp_path / "rules" / "population.yaml") in warning and "'my-population'" in warning
    assert "'id: population' and 'overrides: true'" in warning
    legend = json.loads((out / "mesh.audit.json").read_text())
    assert legend["rules"] and all(Path(r["source"].split(":")[0]) == SHIPPED for r in legend["rules"])
    assert all(r["id"].startswith("population.") for r in legend["rules"])


def test_every_event_is_saved_beside_the_mesh(replaced):
    _, out, result = replaced
    legend = json.loads((out / "mesh.audit.json").read_text())
    saved, events = legend["events"], result.packing.events
    assert set(saved) == set(legend["event_fields"])
    assert saved["bubble"] == events.bubble.tolist() and saved["iteration"] == events.iteration.tolist()
    assert saved["action"] == events.action.tolist() and saved["level"] == events.level.tolist()
    assert [legend["rules"][k]["id"] for k in saved["rule"]] == events.rule.tolist()
    assert np.allclose(saved["firing"], events.firing)
    stats = result.packing.stats
    assert saved["action"].count("delete") == stats["deleted"] > 0
    assert saved["action"].count("insert") == stats["inserted"] > 0
    for rule in legend["rules"]:
        fired = [a for a, k in zip(saved["action"], saved["rule"]) if k == rule["index"]]
        assert (rule["insertions"], rule["deletions"]) == (fired.count("insert"), fired.count("delete"))


def test_explain_tells_a_nodes_history(replaced, capsys):
    copy, out, _ = replaced
    nodes = meshio.read(out / "mesh.vtu").point_data
    legend = json.loads((out / "mesh.audit.json").read_text())
    inserted = int(np.flatnonzero(nodes["inserted_at"] >= 0)[0])
    assert main(["explain", str(out), "--node", str(inserted)]) == 0
    text = capsys.readouterr().out
    rule = legend["rules"][nodes["insert_rule"][inserted]]
    assert f"node {inserted} " in text and f"bubble {nodes['bubble'][inserted]}" in text
    assert f"inserted at iteration {nodes['inserted_at'][inserted]}" in text
    assert rule["id"] in text and rule["source"] in text and str(copy.name) in rule["source"]
    initial = int(np.flatnonzero((nodes["inserted_at"] < 0) & (nodes["node_level"] == 2))[0])
    assert main(["explain", str(out), "--node", str(initial)]) == 0
    assert "an initial bubble of the patch level" in capsys.readouterr().out
    assert main(["explain", str(out), "--node", str(len(nodes["bubble"]))]) == 2
    assert "is not in the mesh" in capsys.readouterr().err
