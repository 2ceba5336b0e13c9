"""Every ```bash block of README.md runs, in order, as a reader runs it.

The blocks run one after the other with ``bash -euo pipefail`` in one scratch folder that holds a copy of
``examples/`` (the README's commands run from the repository root, and later blocks use what earlier
ones wrote), with this environment's ``fuzzymesh`` and ``python`` first on PATH. Two kinds of command
are not executed as written, and the test says so in its output instead of skipping them silently:

- ``pip install ...``: the package is already installed in the test environment (CI installs
  ``.[test]`` before running the suite), and reinstalling would take minutes and the network. It is
  replaced by a check that the distribution ``fuzzymesh`` is installed and ``engine`` imports.
- ``python -m pytest`` with no arguments (the whole suite) would run this test inside itself. It must be
  the command ``.ci/run`` executes, which is what CI runs.
- ``python bench/NAME.py ...``: a benchmark takes minutes to an hour (that is what it measures). It is
  replaced by ``python bench/NAME.py --help`` from the repository, which checks that the script exists and
  starts; tests/test_bench.py runs the harness itself on a small case.

Every other line, heredocs included, runs verbatim.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)
PIP_INSTALL = re.compile(r"\bpip install [^&;|\n]*?(?=[ \t]*(?:&&|;|\||$))", re.M)
INSTALLED = "python -m pip show --quiet fuzzymesh && python -c 'import engine'"
SUITE = re.compile(r"\bpython -m pytest[ \t]*($|&&|;|\|)", re.M)
BENCH = re.compile(r"\bpython (bench/[\w.-]+\.py)[^&;|\n#]*")


def bash_blocks(text: str) -> list[str]:
    return BLOCK.findall(text)


def as_run(block: str) -> str:
    """The block as the test runs it (see the module doc)."""
    block = PIP_INSTALL.sub(INSTALLED, block)
    block = BENCH.sub(lambda m: f"python {ROOT / m.group(1)} --help > /dev/null ", block)
    return SUITE.sub(lambda m: "true " + m.group(1), block)


def test_the_readme_blocks_are_found_and_rewritten_as_documented():
    blocks = bash_blocks((ROOT / "README.md").read_text())
    assert len(blocks) >= 7
    assert as_run('pip install ".[test]" && python -m pytest\n') == f"{INSTALLED} && true \n"
    assert as_run("python -m pytest -q test_x.py\n") == "python -m pytest -q test_x.py\n", "a test file runs"
    bench = ROOT / "bench" / "run.py"
    assert as_run("python bench/run.py --quick   # fast\n") == f"python {bench} --help > /dev/null # fast\n"
    suite = [b for b in blocks if SUITE.search(b)]
    assert suite, "the README says how to run the tests"
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert "python -m pytest" in ci, "the README's test command is the one CI runs"


def test_every_bash_block_of_the_readme_runs(tmp_path):
    shutil.copytree(ROOT / "examples", tmp_path / "examples", ignore=shutil.ignore_patterns("out", "__pycache__"))
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("PYTHONPATH", None)
    for number, block in enumerate(bash_blocks((ROOT / "README.md").read_text()), 1):
        script = as_run(block)
        if script != block:
            print(f"README bash block {number} runs as:\n{script}")
        run = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", script],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert run.returncode == 0, (
            f"README bash block {number} ({block.splitlines()[0]!r}) failed:\n"
            f"{run.stdout[-2000:]}\n{run.stderr[-3000:]}"
        )
        assert "Traceback" not in run.stderr
    assert (tmp_path / "plate-out" / "mesh.report.html").is_file()
    assert (tmp_path / "bearing-out" / "mesh.audit.json").is_file()
