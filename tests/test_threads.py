"""OpenMP threads sleep while they wait (engine/_numba.py): the policy is set before the OpenMP runtime starts,
and a user's own setting wins."""
import functools
import os
import subprocess
import sys
from pathlib import Path

import pytest

PROBE = ("import os, engine.cli, engine.pipeline; "
         "maps = open('/proc/self/maps').read() if os.path.exists('/proc/self/maps') else ''; "
         "print(os.environ['OMP_WAIT_POLICY'], 'libgomp' in maps)")


@functools.lru_cache(maxsize=None)
def probe(**env):
    clean = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    done = subprocess.run([sys.executable, "-c", PROBE], env={**clean, **env}, capture_output=True, text=True,
                          timeout=120)
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
