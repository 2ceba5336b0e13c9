"""The parts corpus: every part builds, both tessellations bound one closed solid close to the CAD volume."""

import importlib.util
import json
from pathlib import Path

import trimesh

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).with_name("make_parts.py"))
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)


def test_corpus(tmp_path):
    paths = make_parts.make_parts(tmp_path)
    assert len(paths) >= 22 and all(set(files) == {"coarse", "fine"} for files in paths.values())
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert len(manifest) == 2 * len(paths)
    for entry in manifest:
        mesh = trimesh.load(tmp_path / entry["path"])
        assert mesh.is_watertight and mesh.is_volume and mesh.body_count == 1, entry["path"]
        assert abs(entry["stl_volume"] / entry["cad_volume"] - 1) < 0.01, entry
    fine = {e["name"]: e["stl_volume"] for e in manifest if e["tessellation"] == "fine"}
    coarse = {e["name"]: e["stl_volume"] for e in manifest if e["tessellation"] == "coarse"}
    cad = {e["name"]: e["cad_volume"] for e in manifest}
    assert all(abs(fine[n] - cad[n]) <= abs(coarse[n] - cad[n]) + 1e-9 * cad[n] for n in cad)
