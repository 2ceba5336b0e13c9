"""numba, with a threading layer that does not warn: OpenMP first, then numba's own work queue.

(numba's default tries TBB first, and an older TBB on the machine makes it print a warning.)
"""
import numba

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["numba"]
