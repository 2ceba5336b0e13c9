"""The wheel ships the knowledge base: a non-editable install must mesh with the default rules."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_wheel_contains_the_knowledge_and_pattern_files(tmp_path):
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w", str(tmp_path), str(ROOT)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if build.returncode != 0 and "hatchling" in build.stderr:
        build = subprocess.run(
            [sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(tmp_path), str(ROOT)],
            capture_output=True,
            text=True,
            timeout=300,
        )
    assert build.returncode == 0, build.stderr[-2000:]
    (wheel,) = tmp_path.glob("fuzzymesh-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {
        f"engine/_data/{p.relative_to(ROOT).as_posix()}"
        for folder in ("knowledge", "patterns")
        for p in (ROOT / folder).rglob("*.yaml")
    }
    assert shipped and shipped <= names
    assert "engine/cli.py" in names


def test_the_installed_package_meshes_with_its_shipped_knowledge(tmp_path):
    """Outside the source tree, `import engine` is the installed copy (CI installs it non-editable)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    probe = subprocess.run(
        [sys.executable, "-c", "import engine, pathlib; print(pathlib.Path(engine.__file__).parent)"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    if probe.returncode != 0:
        pytest.skip("fuzzymesh is not installed in this environment")
    package = Path(probe.stdout.strip())
    if package == ROOT / "engine":
        pytest.skip("installed in editable mode: the installed copy is the source tree")
    assert (package / "_data" / "knowledge" / "population.yaml").is_file()
    run = subprocess.run(
        [sys.executable, "-m", "engine.cli", "mesh", "--size", "20", "--quiet"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "out" / "mesh.vtu").is_file()
