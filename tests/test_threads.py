"""OpenMP threads sleep while they wait (engine/_numba.py): the policy is set before the OpenMP runtime starts,
and a user's own setting wins."""

import functools
import os
import subprocess
import sys
from pathlib import Path

import pytest

PROBE = (
    "import os, engine.cli, engine.pipeline; "
    "maps = open('/proc/self/maps').read() if os.path.exists('/proc/self/maps') else ''; "
    "print(os.environ['OMP_WAIT_POLICY'], 'libgomp' in maps)"
)


@functools.lru_cache(maxsize=None)
def probe(**env):
    clean = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    done = subprocess.run(
        [sys.executable, "-c", PROBE], env={**clean, **env}, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.split()


def test_passive_unless_the_user_chose():
    assert probe()[0] == "PASSIVE"
    assert probe(OMP_WAIT_POLICY="ACTIVE")[0] == "ACTIVE"


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc to see the loaded libraries")
def test_openmp_runtime_not_started_by_the_imports():
    """GNU OpenMP reads OMP_WAIT_POLICY once, when it is loaded: importing the pipeline must not load it (a
    top-level import of pymeshlab would), so that the first parallel kernel starts it with the policy set."""
    assert probe()[1] == "False"


# a parallel numba kernel, then gmsh and pymeshlab (which also load libgomp); libgomp prints its settings
PROGRAM = """
import numpy as np
from engine.quality import tet_quality
tet_quality(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]), np.array([[0, 1, 2, 3]]))
import gmsh, pymeshlab
"""


@pytest.mark.parametrize("given, spin", [(None, "0"), ("ACTIVE", None)])
def test_openmp_workers_do_not_spin_unless_asked(given, spin):
    """libgomp's default (unset) spins 300,000 times before sleeping; passive spins 0 times."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    env["OMP_DISPLAY_ENV"] = "VERBOSE"
    if given:
        env["OMP_WAIT_POLICY"] = given
    run = subprocess.run(
        [sys.executable, "-c", PROGRAM],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
    )
    assert run.returncode == 0, run.stderr
    if "GOMP_SPINCOUNT" not in run.stderr:
        pytest.skip("numba runs on a threading layer other than GNU OpenMP here")
    if spin is None:
        assert "OMP_WAIT_POLICY = 'ACTIVE'" in run.stderr
    else:
        assert f"GOMP_SPINCOUNT = '{spin}'" in run.stderr
