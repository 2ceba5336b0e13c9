"""One measured meshing run in its own process, so its peak memory is its own.

    python bench/worker.py SPEC.json RESULT.json

SPEC names the mesher (``fuzzymesh``, ``gmsh-delaunay``, ``gmsh-hxt``, or ``gmsh-probe`` for the size
check) and what it needs: the job dict (fuzzymesh), the junction's dimensions and the Structured size
file (Gmsh), and where to save the mesh (``mesh``: an .npz with ``points`` and ``tets``). RESULT gets
the seconds per stage, the resident-memory high-water mark after each stage and the CPU seconds.
Only the module of the mesher under test is imported: a Gmsh run never loads fuzzymesh.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from contextlib import contextmanager

STARTED = time.perf_counter()


def peak_mb() -> float:
    """This process's resident-memory high-water mark so far, in MB.

    On Linux VmHWM of /proc/self/status: ru_maxrss (of the process, or RUSAGE_CHILDREN in the parent) starts
    from the parent's resident size at the fork that started this process, which exec does not reset (a
    worker doing nothing reports the harness's 300 MB). Elsewhere ru_maxrss (KB; bytes on macOS).
    """
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024


def cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


class Meter:
    """The memory high-water mark and the CPU seconds (since the meter started) after each stage."""

    def __init__(self):
        self.started, self.start_mb = cpu_seconds(), peak_mb()
        self.peak_mb, self.cpu_seconds = {}, {}

    def mark(self, stage: str) -> None:
        self.peak_mb[stage] = peak_mb()
        self.cpu_seconds[stage] = cpu_seconds() - self.started

    def figures(self) -> dict:
        return {"start_mb": self.start_mb, "peak_mb_after": self.peak_mb, "cpu_seconds_after": self.cpu_seconds}


def run_fuzzymesh(spec: dict) -> dict:
    """``engine.pipeline.run(job, write=False)``: its stage timings, and the memory high-water mark at the end of
    each stage (the pipeline's ``stage`` context manager, wrapped)."""
    import numpy as np

    import engine.pipeline as pipeline
    from engine.job import job_from_dict

    startup, meter = time.perf_counter() - STARTED, Meter()
    timed_stage = pipeline.stage

    @contextmanager
    def measured_stage(name, timings):
        with timed_stage(name, timings):
            yield
        meter.mark(name)

    pipeline.stage = measured_stage
    result = pipeline.run(job_from_dict(spec["job"]), write=False)
    np.savez(spec["mesh"], points=result.mesh.points, tets=result.mesh.tets)
    sizing = result.sizing
    return {
        "startup": startup,
        "stages": result.timings,
        **meter.figures(),
        "nodes": len(result.mesh.points),
        "tets": len(result.mesh.tets),
        "bubbles": len(result.packing),
        "solid_volume": float(result.geometry.volume),
        "mesher_stats": {k: v for k, v in result.mesh.stats.items() if not isinstance(v, dict)},
        "size_grid": {
            "shape": list(sizing.grid.shape),
            "origin": list(map(float, sizing.origin)),
            "cell": float(sizing.cell),
            "sha1": grid_digest(sizing.grid),
        },
    }


def grid_digest(grid) -> str:
    import hashlib

    import numpy as np

    return hashlib.sha1(np.ascontiguousarray(grid, dtype="<f8").tobytes()).hexdigest()


def run_gmsh(spec: dict) -> dict:
    """Gmsh's OpenCASCADE junction meshed with the Structured size field, curves to optimised volume."""
    import gmsh
    import gmsh_junction as gj
    import numpy as np

    gj.start(gj.THREADS[spec["mesher"]])
    startup, meter, stages = time.perf_counter() - STARTED, Meter(), {}
    begin = time.perf_counter()
    volume = gj.build_junction(**spec["junction"])
    stages["model"] = time.perf_counter() - begin
    meter.mark("model")
    begin = time.perf_counter()
    gj.use_size_grid(spec["size_file"])
    stages["size_field"] = time.perf_counter() - begin
    meter.mark("size_field")
    stages.update(gj.generate(spec["mesher"], meter.mark))
    points, tets = gj.mesh_arrays()
    np.savez(spec["mesh"], points=points, tets=tets)
    gmsh.finalize()
    return {
        "startup": startup,
        "stages": stages,
        **meter.figures(),
        "nodes": len(points),
        "tets": len(tets),
        "solid_volume": volume,
    }


def run_probe(spec: dict) -> dict:
    """The sizes Gmsh asks for along the curves of the junction (see gmsh_junction.probe_sizes)."""
    import gmsh
    import gmsh_junction as gj
    import numpy as np

    gj.start()
    gj.build_junction(**spec["junction"])
    gj.use_size_grid(spec["size_file"])
    samples = gj.probe_sizes()
    gmsh.finalize()
    np.save(spec["samples"], samples)
    return {"samples": len(samples)}


RUNS = {"fuzzymesh": run_fuzzymesh, "gmsh-delaunay": run_gmsh, "gmsh-hxt": run_gmsh, "gmsh-probe": run_probe}


def main() -> None:
    spec_path, result_path = sys.argv[1:3]
    with open(spec_path) as file:
        spec = json.load(file)
    result = RUNS[spec["mesher"]](spec)
    result["process_seconds"] = time.perf_counter() - STARTED
    with open(result_path, "w") as file:
        json.dump(result, file, default=float)  # numpy scalars among the mesher's stats


if __name__ == "__main__":
    main()
