"""numba, with a threading layer that does not warn (OpenMP first, then numba's own work queue), and
OpenMP threads that sleep instead of spinning while they wait.

(numba's default tries TBB first, and an older TBB on the machine makes it print a warning.)

GNU OpenMP's default lets an idle worker spin for a while before it sleeps. On a machine whose
cores are shared (2 cores, other processes busy) the spinning workers take the CPU from the ones
with work, and the packer's thousands of short parallel kernels slowed down 2-5x (the junction at
global size 12: 40 s spinning, 14 s passive, same mesh). ``OMP_WAIT_POLICY=passive`` is set unless
the user set it. libgomp reads it once, when it is loaded: by numba's first parallel kernel, or by
gmsh / pymeshlab, which the engine imports lazily, after this module.
"""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numba  # noqa: E402  (after the OpenMP setting)

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["numba"]
