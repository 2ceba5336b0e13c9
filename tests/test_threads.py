"""OpenMP workers sleep while they wait (engine/_numba.py), unless the user chose otherwise."""
import os
import subprocess
import sys

import pytest

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
    run = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, env=env, timeout=120,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert run.returncode == 0, run.stderr
    if "GOMP_SPINCOUNT" not in run.stderr:
        pytest.skip("numba runs on a threading layer other than GNU OpenMP here")
    if spin is None:
        assert "OMP_WAIT_POLICY = 'ACTIVE'" in run.stderr
    else:
        assert f"GOMP_SPINCOUNT = '{spin}'" in run.stderr
