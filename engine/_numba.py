"""numba, with a threading layer that does not warn: OpenMP first, then numba's own work queue; and OpenMP
threads that sleep while they wait.

(numba's default tries TBB first, and an older TBB on the machine makes it print a warning.)

OMP_WAIT_POLICY=PASSIVE unless the user set it: with GNU OpenMP's default, a thread that finishes its share
of a parallel loop spins before it sleeps. With other work on the cores (another process, or this process's
own serial Python between kernels) the spinning thread takes a core from the thread that is still working,
and every parallel loop waits for a descheduled thread: on the 2-core reference machine under load, the
packer's force kernel (about 1,400 short calls on the paper's junction) took 13 s instead of 0.5 s, and the
whole paper-scale run 29 s instead of 14 s. Sleeping costs a wake-up of tens of microseconds per loop.
It is read when the OpenMP runtime starts, at the first parallel call, after this module has run.
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402  (after the environment the OpenMP runtime reads when it starts)

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["numba"]
