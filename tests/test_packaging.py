"""The wheel ships the knowledge base: a non-editable install must mesh with the default rules."""
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_wheel_contains_the_knowledge_and_pattern_files(tmp_path):
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w",
                            str(tmp_path), str(ROOT)], capture_output=True, text=True, timeout=300)
    if build.returncode != 0 and "hatchling" in build.stderr:
        build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(tmp_path), str(ROOT)],
                               capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stderr[-2000:]
    (wheel,) = tmp_path.glob("fuzzymesh-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {f"engine/_data/{p.relative_to(ROOT).as_posix()}"
               for folder in ("knowledge", "patterns") for p in (ROOT / folder).rglob("*.yaml")}
    assert shipped and shipped <= names
    assert "engine/cli.py" in names
