"""Side-by-side measurement of fuzzymesh and Gmsh on one case: the same solid, the same h(x), each mesher in
its own worker process (bench/worker.py), repeated; medians of the times and memory, and the mesh measured
by our own code for every mesher (engine.quality: tet_quality, size_conformity)."""

from __future__ import annotations

import json
import logging
import os
import platform
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from cases import build_case, junction_job, junction_parameters
from gmsh_junction import THREADS, write_size_grid
from worker import grid_digest

log = logging.getLogger("bench")

WORKER = Path(__file__).with_name("worker.py")
# every worker runs under the same OpenMP runtime behaviour: threads that wait sleep instead of spinning (on
# the loaded shared machine, spinning made HXT's volume stage 100x and the packer 5x slower); a set value is kept
OMP_WAIT_POLICY = os.environ.get("OMP_WAIT_POLICY", "PASSIVE")
MESHERS = ("fuzzymesh", "gmsh-delaunay", "gmsh-hxt")
# the stages that turn the solid and the sizes into a mesh; the rest of fuzzymesh's pipeline (quality,
# boundary, conformity, audit) is analysis, reported apart
MESH_STAGES = {
    "fuzzymesh": ("geometry", "sizing", "packing", "meshing"),
    "gmsh-delaunay": ("model", "size_field", "curves", "surface", "volume", "optimise"),
    "gmsh-hxt": ("model", "size_field", "curves", "surface", "volume"),
}
FIGURES = (
    "mesh_seconds",
    "peak_mb",
    "cpu_seconds",
    "nodes",
    "tets",
    "min_dihedral",
    "p01_dihedral",
    "min_radius_ratio",
    "p01_radius_ratio",
    "conformity_median",
    "conformity_within",
)


class WorkerError(RuntimeError):
    """A worker process failed; the message is its last line of error output."""


def run_worker(spec: dict, folder: Path, name: str) -> dict:
    """Run bench/worker.py on ``spec``; its result dict."""
    spec_path, result_path = folder / f"{name}.spec.json", folder / f"{name}.result.json"
    spec_path.write_text(json.dumps(spec))
    done = subprocess.run(
        [sys.executable, str(WORKER), str(spec_path), str(result_path)],
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_WAIT_POLICY": OMP_WAIT_POLICY},
    )
    if done.returncode != 0:
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        raise WorkerError(lines[-1] if lines else f"exit code {done.returncode}")
    return json.loads(result_path.read_text())


def mesh_figures(path: Path, sizing, solid_volume: float) -> dict:
    """Counts, quality (engine.quality.tet_quality) and size conformity (engine.quality.size_conformity) of the
    mesh saved at ``path`` (each run overwrites it: the last run's), measured the same way whoever made it."""
    from engine.quality import size_conformity, tet_quality

    with np.load(path) as data:
        points, tets = data["points"], data["tets"]
    quality = tet_quality(points, tets).summary()
    conformity = size_conformity(SimpleNamespace(points=points, tets=tets), sizing)
    return {
        "nodes": len(points),
        "tets": len(tets),
        "min_dihedral": quality["min_dihedral"]["min"],
        "p01_dihedral": quality["min_dihedral"]["p01"],
        "median_dihedral": quality["min_dihedral"]["median"],
        "below_10_degrees": quality["below"]["min_dihedral_10"],
        "max_dihedral": quality["max_dihedral"]["max"],
        "min_radius_ratio": quality["radius_ratio"]["min"],
        "p01_radius_ratio": quality["radius_ratio"]["p01"],
        "conformity_median": conformity["median"],
        "conformity_within": conformity["within"],
        "conformity_band": conformity["band"],
        "volume_error": quality["volume"]["total"] / solid_volume - 1.0,
        "inverted": quality["volume"]["non_positive"],
    }


def summarise(mesher: str, runs: list[dict]) -> dict:
    """Medians over the repeated runs: seconds per stage, meshing seconds, memory high-water mark and CPU
    seconds at the end of the last meshing stage (and, for fuzzymesh, at the end of the whole pipeline), and the
    high-water mark when meshing started (the process with its imports)."""
    mesh_stages = MESH_STAGES[mesher]
    last = mesh_stages[-1]
    median = statistics.median
    summary = {
        "seconds": {stage: median(run["stages"][stage] for run in runs) for stage in runs[0]["stages"]},
        "startup_seconds": median(run["startup"] for run in runs),
        "mesh_seconds": median(sum(run["stages"][s] for s in mesh_stages) for run in runs),
        "peak_mb": median(run["peak_mb_after"][last] for run in runs),
        "start_mb": median(run["start_mb"] for run in runs),
        "cpu_seconds": median(run["cpu_seconds_after"][last] for run in runs),
        "process_seconds": median(run["process_seconds"] for run in runs),
        "mesh_seconds_by_run": [sum(run["stages"][s] for s in mesh_stages) for run in runs],
        "tets_by_run": [run["tets"] for run in runs],
    }
    analysis = [stage for stage in runs[0]["stages"] if stage not in mesh_stages]
    if analysis:
        summary["analysis_seconds"] = median(sum(run["stages"][s] for s in analysis) for run in runs)
        summary["peak_mb_pipeline"] = median(max(run["peak_mb_after"].values()) for run in runs)
    return summary


def check_sizes(sizing, case: str, size_file: Path, folder: Path) -> dict:
    """The sizes Gmsh asks for along the junction's curves against ours at the same points."""
    samples_path = folder / "probe.npy"
    run_worker(
        {
            "mesher": "gmsh-probe",
            "junction": junction_parameters(case),
            "size_file": str(size_file),
            "samples": str(samples_path),
        },
        folder,
        "probe",
    )
    samples = np.load(samples_path)
    ours = sizing(samples[:, :3])
    return {"samples": len(samples), "max_relative_difference": float(np.max(np.abs(samples[:, 3] / ours - 1.0)))}


def measure_case(case: str, tier: str, scale: float, meshers, repeats: int, folder: Path) -> dict:
    """One row: every mesher ``repeats`` times on ``case`` with the sizes x ``scale``, and their ratios."""
    job = junction_job(case, scale)
    _, geometry, _, sizing = build_case(job)
    size_file = folder / "size.bin"
    begin = time.perf_counter()
    write_size_grid(sizing, size_file)
    export = time.perf_counter() - begin
    row = {
        "case": case,
        "tier": tier,
        "scale": scale,
        "global_size": job["size"],
        "job": job,
        "h": {"min": sizing.h_min, "max": sizing.h_max},
        "size_field": {
            "grid": list(sizing.grid.shape),
            "cell": sizing.cell,
            "sha1": grid_digest(sizing.grid),
            "export_seconds": export,
        },
        "meshers": {},
    }
    if any(m.startswith("gmsh") for m in meshers):
        row["size_field"]["gmsh_probe"] = check_sizes(sizing, case, size_file, folder)
    for mesher in meshers:
        log.info("%s %s (scale %g): %s x %d", case, tier, scale, mesher, repeats)
        spec = {"mesher": mesher, "mesh": str(folder / f"{mesher}.npz")}
        spec.update(
            {"job": job}
            if mesher == "fuzzymesh"
            else {"junction": junction_parameters(case), "size_file": str(size_file)}
        )
        try:
            runs = [run_worker(spec, folder, mesher) for _ in range(repeats)]
        except WorkerError as error:
            row["meshers"][mesher] = {"error": str(error)}
            log.warning("%s %s: %s failed: %s", case, tier, mesher, error)
            continue
        entry = {
            "runs": runs,
            **summarise(mesher, runs),
            **mesh_figures(folder / f"{mesher}.npz", sizing, runs[0]["solid_volume"]),
            "solid_volume": runs[0]["solid_volume"],
        }
        if mesher == "fuzzymesh":
            row["size_field"]["same_as_fuzzymesh"] = runs[0]["size_grid"]["sha1"] == row["size_field"]["sha1"]
        row["meshers"][mesher] = entry
        log.info(
            "  %s: %d tets, meshing %.2f s (median), peak %.0f MB, min dihedral %.2f deg",
            mesher,
            entry["tets"],
            entry["mesh_seconds"],
            entry["peak_mb"],
            entry["min_dihedral"],
        )
    row["ratios"] = ratios(row["meshers"])
    return row


def ratios(meshers: dict) -> dict:
    """fuzzymesh / Gmsh for every figure of FIGURES, per Gmsh algorithm."""
    ours = meshers.get("fuzzymesh", {})
    out = {}
    for name, theirs in meshers.items():
        if name == "fuzzymesh" or "error" in theirs or "error" in ours or not ours:
            continue
        out[name] = {key: ours[key] / theirs[key] if theirs[key] else None for key in FIGURES}
    return out


def warm_up(folder: Path) -> float:
    """One small fuzzymesh run, so that no measured run pays for numba compiling its kernels; its seconds."""
    begin = time.perf_counter()
    run_worker(
        {"mesher": "fuzzymesh", "job": junction_job("junction-centre", 8.0), "mesh": str(folder / "warm-up.npz")},
        folder,
        "warm-up",
    )
    return time.perf_counter() - begin


def machine_info() -> dict:
    """CPU, cores, memory, load and the versions that matter, for the record."""
    import gmsh
    import numba
    import scipy

    import engine

    cpu = platform.processor() or platform.machine()
    if Path("/proc/cpuinfo").is_file():
        cpu = next(
            (
                line.split(":", 1)[1].strip()
                for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")
            ),
            cpu,
        )
    try:
        commit = (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent
            ).stdout.strip()
            or None
        )
    except OSError:
        commit = None
    return {
        "date": datetime.now(timezone.utc).astimezone().isoformat(timespec="seconds"),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1),
        "load_average": list(os.getloadavg()),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "numba_threads": numba.config.NUMBA_NUM_THREADS,
        "gmsh": gmsh.__version__,
        "fuzzymesh": engine.__version__,
        "commit": commit,
        "gmsh_threads_3d": dict(THREADS),
        "omp_wait_policy": OMP_WAIT_POLICY,
    }
