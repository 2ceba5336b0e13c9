"""Plug-ins registered by entry point: the example package of examples/plugin meshes through the pipeline and
keeps the contracts; a plug-in that does not take what the pipeline passes, or does not load, is refused in one
line before any work."""

from __future__ import annotations

from pathlib import Path

import pytest
import tomllib
import yaml
from test_meshers import check_packer_contract

from engine.cli import main
from engine.errors import JobError
from engine.job import load_job
from engine.meshing import MESHERS
from engine.packing import PACKERS
from engine.pipeline import run

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "plugin"


def register(monkeypatch, folder: Path, name: str, entry_points: dict) -> None:
    """Make ``entry_points`` ({group: {name: "module:function"}}) visible as an installed distribution
    would (a .dist-info folder on sys.path), and let the registries load them afresh."""
    info = folder / f"{name}-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text(
        "".join(
            f"[{group}]\n" + "".join(f"{key} = {value}\n" for key, value in items.items())
            for group, items in entry_points.items()
        )
    )
    monkeypatch.syspath_prepend(str(folder))
    for registry in (PACKERS, MESHERS):
        registry.get(registry.names()[0])  # the built-ins registered first
        monkeypatch.setattr(registry, "functions", dict(registry.functions))
        monkeypatch.setattr(registry, "broken", {})
        monkeypatch.setattr(registry, "_loaded", False)


def write_job(folder: Path, **keys) -> Path:
    job = folder / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {
                "geometry": {"shape": "plate", "parameters": {"length": 60, "width": 40}},
                "size": 6.0,
                "output": {"formats": ["vtu"]},
                **keys,
            }
        )
    )
    return job


@pytest.fixture
def example_plugin(tmp_path, monkeypatch):
    """The example package registered by the entry points its pyproject.toml declares."""
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())["project"]
    monkeypatch.syspath_prepend(str(EXAMPLE / "src"))
    register(monkeypatch, tmp_path / "site", project["name"].replace("-", "_"), project["entry-points"])
    return project["entry-points"]


def test_the_example_plugin_meshes_through_its_entry_points(example_plugin, tmp_path):
    (packer,), (mesher,) = example_plugin["fuzzymesh.packers"], example_plugin["fuzzymesh.meshers"]
    result = run(load_job(write_job(tmp_path, packer=packer, mesher=mesher)))
    assert result.packing.stats["jittered"] > 0, "the plug-in packer placed the nodes"
    assert sum(result.mesh.stats["nodes_per_level"].values()) == len(result.mesh.points), "the plug-in mesher ran"
    assert (tmp_path / "out" / "mesh.vtu").is_file(), "the mesh passed the acceptance gate and was written"
    check_packer_contract(packer)


def test_a_packer_without_the_knowledge_argument_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "old_packer.py").write_text(
        "def pack(geometry, features, sizing, *, seed):\n    raise AssertionError('never called')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path / "src"))
    register(monkeypatch, tmp_path / "site", "old_packer", {"fuzzymesh.packers": {"old": "old_packer:pack"}})
    assert main(["mesh", str(write_job(tmp_path, packer="old"))]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"fuzzymesh: error: {tmp_path / 'src' / 'old_packer.py'}:1: packer 'old' does not take")
    assert "unexpected keyword argument 'knowledge'" in line and "Packer protocol of engine/plugins.py" in line
    assert not (tmp_path / "out").exists()


def test_a_plugin_that_does_not_load_is_named_and_does_not_stop_the_others(tmp_path, monkeypatch):
    register(monkeypatch, tmp_path / "site", "broken", {"fuzzymesh.meshers": {"broken": "no_such_module:mesh"}})
    assert {"broken", "delaunay", "qhull"} <= set(MESHERS.names())
    MESHERS.get("delaunay")
    with pytest.raises(JobError, match="mesher 'broken' cannot be loaded .*no_such_module.*ModuleNotFoundError"):
        MESHERS.get("broken")


def test_a_plugin_meshers_broken_mesh_is_rejected_by_the_acceptance_gate(tmp_path, monkeypatch, capsys):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "holed_mesher.py").write_text(
        "from engine.mesh import TetMesh\nfrom engine.meshing import get_mesher\n\n\n"
        "def mesh(packing, geometry, features, *, seed):\n"
        "    whole = get_mesher('delaunay')(packing, geometry, features, seed=seed)\n"
        "    return TetMesh(points=whole.points, tets=whole.tets[1:], node_level=whole.node_level,\n"
        "                   node_entity=whole.node_entity)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path / "src"))
    register(monkeypatch, tmp_path / "site", "holed", {"fuzzymesh.meshers": {"holed": "holed_mesher:mesh"}})
    assert main(["mesh", str(write_job(tmp_path, mesher="holed"))]) == 4
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("fuzzymesh: error: mesh rejected ("), "the missing tet leaves a dent in the boundary"
    assert not list((tmp_path / "out").glob("mesh.*"))
