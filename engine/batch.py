"""Batch meshing of part families and part libraries on dask.distributed (see docs/batch.md).

A study file names a base job and what varies: ``cross`` (every combination) and ``zip`` (varied together) of
any job key or shape parameter, and ``files`` (a folder or glob of geometry files). Each variant is an ordinary
job with its own output folder, meshed by ``engine.pipeline.run`` in a Dask task. The study writes one row per
variant to ``study.csv`` and ``study.parquet`` and plots quality and element count in ``study.html``.
"""

from __future__ import annotations

import base64
import csv
import glob
import hashlib
import html
import io
import itertools
import json
import logging
import math
import os
import re
import socket
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from . import __version__
from .atomic import write_all_or_nothing
from .errors import FuzzymeshError, JobError, MeshRejected
from .job import job_from_dict, job_schema
from .knowledge import default_paths, yaml_files
from .schema import INTEGER, MAPPING, NUMBER, STRING, Field, check_value, positive, validate
from .shapes import SHAPES
from .yamlfile import Located, load_yaml

log = logging.getLogger("fuzzymesh")

GEOMETRY_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".step", ".stp", ".iges", ".igs", ".brep")
MARKER = "variant.json"  # a variant's row and job hash, written after its mesh files: the outputs are complete
EXTRA = ("distributed", "pyarrow")
FIGURES = (
    "tetrahedra",
    "nodes",
    "bubbles",
    "min_dihedral",
    "dihedral_p01",
    "radius_ratio_min",
    "below_10deg",
    "volume_error_pct",
    "conformity_median",
    "conformity_within",
)
TAIL = ("time_total", "peak_memory_mb", "worker", "directory", "files", "cached", "job_hash")


def study_schema() -> dict:
    values = "a list of values, or a range {from, to, step} or {from, to, count}"
    return {
        "job": Field(STRING, required=True, doc="the base job file, relative to the study file"),
        "cross": Field(
            MAPPING,
            open_keys=True,
            doc=f"KEY: values, every combination; KEY a job key (dotted: output.order) or a shape parameter; {values}",
        ),
        "zip": Field(MAPPING, open_keys=True, doc=f"KEY: values, all of one length, varied together; {values}"),
        "files": Field(STRING, doc="a folder or glob of geometry files, relative to the study file"),
        "output": Field(
            MAPPING,
            default=None,
            doc="where the study writes",
            fields={"directory": Field(STRING, default="study", doc="the study's folder, relative to the study file")},
        ),
    }


RANGE = {
    "from": Field(NUMBER, required=True, doc="first value"),
    "to": Field(NUMBER, required=True, doc="last value"),
    "step": Field(NUMBER, check=positive, doc="difference between values"),
    "count": Field(
        INTEGER,
        check=lambda n: None if n >= 2 else f"must be at least 2, got {n}",
        doc="number of values, evenly spaced",
    ),
}


@dataclass(frozen=True)
class Variant:
    """One job of the study: its name (and folder), varied parameters, job mapping and job hash."""

    name: str
    parameters: dict
    job: dict
    base_dir: str
    source: str
    directory: str
    digest: str

    def load(self):
        return job_from_dict(self.job, base_dir=self.base_dir, source=self.source)


@dataclass
class Study:
    """A validated study: its file, the varied keys (table columns, in this order), the variants, its folder."""

    source: Path
    keys: list[str]
    variants: list[Variant]
    directory: Path


def _values(raw, name: str, where: str) -> list:
    """A list as given, or the numbers of a range mapping."""
    if isinstance(raw, list):
        if not raw:
            raise JobError(f"'{name}' has no values", where=where, fix="give at least one value")
        return raw
    if not isinstance(raw, dict):
        raise JobError(
            f"'{name}' must be a list or a range mapping",
            where=where,
            fix="e.g. [10, 20] or {from: 10, to: 20, step: 5}",
        )
    spec = validate(raw, RANGE, JobError, name, where)
    first, last, step, count = spec["from"], spec["to"], spec["step"], spec["count"]
    if (step is None) == (count is None) or last < first:
        raise JobError(
            f"the range '{name}' needs 'from' <= 'to' and exactly one of 'step' or 'count'",
            where=where,
            fix="e.g. {from: 10, to: 20, step: 5}",
        )
    if count is None:
        count = int(math.floor((last - first) / step + 1e-9)) + 1
        return [first + i * step for i in range(count)]
    return [first + i * (last - first) / (count - 1) for i in range(count)]


def _key_field(key: str, shape: str | None, where: str) -> tuple[tuple, Field]:
    """The job-mapping path and Field of a varied key: a (dotted) job key or a shape parameter."""
    shape_fields = SHAPES.details(shape)["parameters"] if shape in SHAPES else {}
    path = tuple(str(key).split("."))
    if path[:2] == ("geometry", "parameters") and len(path) == 3:
        path = path[2:]
    if len(path) == 1 and path[0] in shape_fields:
        return ("geometry", "parameters", path[0]), shape_fields[path[0]]
    fields, field = job_schema(), None
    for part in path:
        field = (fields or {}).get(part)
        if field is None:
            break
        fields = field.fields
    if field is None or path in (("output",), ("output", "directory")):
        raise JobError(
            f"'{key}' is neither a job key nor a parameter of the shape '{shape}'",
            where=where,
            fix=f"vary a job key ({', '.join(k for k in job_schema() if k != 'output')}, dotted ones "
            f"such as output.order) or a shape parameter ({', '.join(shape_fields) or 'none'}); "
            f"the study sets output.directory",
        )
    return path, field


def _axes(block, name: str, shape: str | None) -> list[list[tuple]]:
    """One axis per key of a 'cross' block, or one for the whole 'zip' block: a list of settings groups, each a
    tuple of (key, job path, value)."""
    if block is None:
        return []
    columns = []
    for key in block:
        where = block.where(key)
        path, field = _key_field(key, shape, where)
        values = [check_value(v, field, str(key), where, JobError) for v in _values(block[key], f"{name}.{key}", where)]
        columns.append([(str(key), path, v) for v in values])
    if name == "cross":
        return [[(setting,) for setting in column] for column in columns]
    lengths = {len(c) for c in columns}
    if len(lengths) > 1:
        raise JobError(
            f"the lists of 'zip' have different lengths ({', '.join(map(str, sorted(lengths)))})",
            where=block.where(),
            fix="give every key of 'zip' as many values",
        )
    return [list(zip(*columns))] if columns else []


def _files(pattern: str, base: Path, where: str) -> list[Path]:
    folder = base / pattern
    found = sorted(folder.iterdir()) if folder.is_dir() else sorted(map(Path, glob.glob(str(base / pattern))))
    found = [p for p in found if p.is_file() and p.suffix.lower() in GEOMETRY_SUFFIXES]
    if not found:
        raise JobError(
            f"'files: {pattern}' names no geometry file",
            where=where,
            fix=f"give a folder or glob of {', '.join(GEOMETRY_SUFFIXES)} files",
        )
    return found


def _slug(value) -> str:
    text = f"{value:g}" if isinstance(value, float) else str(value)
    return re.sub(r"[^A-Za-z0-9.+-]+", "-", text).strip("-") or "x"


def _set(mapping: dict, path: tuple, value) -> None:
    for part in path[:-1]:
        mapping = mapping.setdefault(part, {})
    mapping[path[-1]] = value


def _plain(data):
    if isinstance(data, dict):
        return {k: _plain(v) for k, v in data.items()}
    if isinstance(data, list):
        return [_plain(v) for v in data]
    return data


def _digest(job: dict, base_dir: Path, knowledge_digest: str) -> str:
    """The job hash: the job mapping, the contents of its knowledge and geometry files, the fuzzymesh version."""
    sha = hashlib.sha256(json.dumps({"job": job, "version": __version__}, sort_keys=True, default=str).encode())
    sha.update(knowledge_digest.encode())
    for path in yaml_files(base_dir / k for k in job.get("knowledge", [])):
        sha.update(path.read_bytes() if path.is_file() else b"")
    geometry_file = job["geometry"].get("file")
    if geometry_file:
        sha.update((base_dir / geometry_file).read_bytes())
    return sha.hexdigest()


def load_study(path: str | Path) -> Study:
    """Read and validate a study file; every variant's job is validated too (located one-line errors)."""
    path = Path(path)
    data = load_yaml(path, JobError)
    if not isinstance(data, Located):
        raise JobError("a study must be a YAML mapping", where=str(path), fix="see docs/batch.md for the keys")
    spec = validate(data, study_schema(), JobError)
    job_path = path.parent / spec["job"]
    raw = load_yaml(job_path, JobError)
    job_from_dict(raw, base_dir=job_path.parent, source=str(job_path))  # the base job itself is valid
    base = _plain(raw)
    shape = None if spec["files"] else base.get("geometry", {}).get("shape")
    axes = _axes(data.get("cross"), "cross", shape) + _axes(data.get("zip"), "zip", shape)
    if spec["files"]:
        axes.append(
            [
                (("file", ("geometry", "file"), str(f.resolve())),)
                for f in _files(spec["files"], path.parent, data.where("files"))
            ]
        )
    if not axes:
        raise JobError("the study varies nothing", where=data.where(), fix="add 'cross', 'zip' or 'files'")
    directory = path.parent / (spec["output"] or {"directory": "study"})["directory"]
    knowledge = hashlib.sha256(b"".join(p.read_bytes() for p in yaml_files(default_paths()))).hexdigest()
    variants = []
    keys = [key for axis in axes for key, _, _ in axis[0]]
    for combination in itertools.product(*axes):
        settings = [setting for group in combination for setting in group]
        job = json.loads(json.dumps(base))
        if spec["files"]:
            job["geometry"] = {k: v for k, v in job["geometry"].items() if k not in ("shape", "parameters")}
        for _, key_path, value in settings:
            _set(job, key_path, value)
        name = "_".join(
            _slug(Path(v).name) if k == "file" else f"{_slug(k.split('.')[-1])}-{_slug(v)}" for k, _, v in settings
        )
        folder = (directory / "variants" / name).resolve()
        _set(job, ("output", "directory"), str(folder))
        try:
            job_from_dict(job, base_dir=job_path.parent, source=f"{job_path} [{name}]")
        except JobError as error:
            raise JobError(f"variant '{name}': {error.what}", where=data.where(), fix=error.fix) from None
        variants.append(
            Variant(
                name,
                {k: v for k, _, v in settings},
                job,
                str(job_path.parent.resolve()),
                f"{job_path} [{name}]",
                str(folder),
                _digest(job, job_path.parent, knowledge),
            )
        )
    names = [v.name for v in variants]
    if len(set(names)) < len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise JobError(
            f"the study makes the variant '{twice[0]}' more than once", where=data.where(), fix="give every value once"
        )
    return Study(path, keys, variants, directory)


def _reset_peak() -> None:
    """Start the process's peak resident size (VmHWM) afresh (Linux); elsewhere the peak is the process's."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def _peak_mb() -> float | None:
    try:
        status = Path("/proc/self/status").read_text()
    except OSError:
        return None
    match = re.search(r"VmHWM:\s+(\d+) kB", status)
    return int(match.group(1)) / 1024 if match else None


def mesh_variant(variant: Variant) -> dict:
    """Mesh one variant with ``engine.pipeline.run`` (a Dask task): its row, status ok, refused or rejected.

    An internal fault is raised, for Dask to report (and retry with ``retries``); the client makes it a
    'failed' row. An ok variant's row and job hash go to its folder's ``variant.json``, after its mesh files.
    """
    from .pipeline import run

    logging.getLogger("fuzzymesh").setLevel(logging.WARNING)
    _reset_peak()
    start = time.perf_counter()
    row = {
        "variant": variant.name,
        **variant.parameters,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
        "directory": variant.directory,
        "job_hash": variant.digest,
    }
    try:
        result = run(variant.load())
    except MeshRejected as error:
        return {**row, "status": "rejected", "message": error.one_line()}
    except FuzzymeshError as error:
        return {**row, "status": "refused", "message": error.one_line()}
    quality, conformity = result.quality, result.conformity
    row.update(
        {
            "status": "ok",
            "message": "",
            "tetrahedra": len(result.mesh.tets),
            "nodes": len(result.mesh.points),
            "bubbles": len(result.packing),
            "min_dihedral": quality["min_dihedral"]["min"],
            "dihedral_p01": quality["min_dihedral"]["p01"],
            "radius_ratio_min": quality["radius_ratio"]["min"],
            "below_10deg": quality["below"]["min_dihedral_10"],
            "volume_error_pct": 100 * (result.mesh.volume / result.geometry.volume - 1),
            "conformity_median": conformity["median"],
            "conformity_within": conformity["within"],
            **{f"time_{stage}": seconds for stage, seconds in result.timings.items()},
            "time_total": time.perf_counter() - start,
            "peak_memory_mb": _peak_mb(),
            "files": " ".join(p.name for p in result.files),
            "cached": False,
        }
    )
    marker = Path(variant.directory) / MARKER
    write_all_or_nothing([(marker, lambda tmp: Path(tmp).write_text(json.dumps({"hash": variant.digest, "row": row})))])
    return row


def cached_row(variant: Variant) -> dict | None:
    """The row of an earlier run of this very job (same hash) whose files are all there, else None."""
    try:
        saved = json.loads((Path(variant.directory) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    row = saved.get("row", {})
    complete = saved.get("hash") == variant.digest and all(
        (Path(variant.directory) / name).is_file() for name in row.get("files", "").split()
    )
    return {**row, "cached": True} if complete and row.get("files") else None


def require_batch() -> None:
    """Raise a one-line FuzzymeshError naming the fix when the 'batch' extra is not installed."""
    import importlib.util

    missing = [m for m in EXTRA if importlib.util.find_spec(m) is None]
    if missing:
        raise FuzzymeshError(
            f"batch meshing needs {' and '.join(missing)} (the optional 'batch' extra), not installed",
            fix="pip install 'fuzzymesh[batch]'",
        )


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A Client of the cluster at ``scheduler`` (or Dask's ``scheduler-address``: DASK_SCHEDULER_ADDRESS), else
    of an embedded LocalCluster of ``workers`` single-threaded processes (default: one per core)."""
    import dask
    from distributed import Client, LocalCluster

    address = scheduler or dask.config.get("scheduler-address", None)
    if address:
        with Client(address) as client:
            _import_on_main_thread(client)
            yield client
        return
    logging.getLogger("distributed").setLevel(logging.WARNING)  # the embedded cluster's start and stop
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True) as cluster, Client(cluster) as client:
        _import_on_main_thread(client)
        yield client


def _import_on_main_thread(client) -> None:
    """Import pymeshlab in every worker's main thread (a WorkerPlugin's setup): first imported in a task's
    thread, it aborts the worker process at exit (glibc: malloc_consolidate)."""
    from distributed import WorkerPlugin

    class MainThreadImports(WorkerPlugin):
        def setup(self, worker):
            import pymeshlab  # noqa: F401

            from . import _numba  # noqa: F401  (OpenMP's settings before pymeshlab starts it)

    client.register_plugin(MainThreadImports(), name="fuzzymesh-main-thread-imports")


def run_variants(study: Study, client, retries: int = 0) -> list[dict]:
    """Every variant's row, in study order: from an earlier complete run, or meshed on the cluster."""
    from distributed import as_completed

    from .progress import progress

    rows = {v.name: row for v in study.variants if (row := cached_row(v)) is not None}
    futures = {
        client.submit(mesh_variant, v, pure=False, retries=retries): v for v in study.variants if v.name not in rows
    }
    try:
        with progress(len(study.variants), "variants") as bar:
            bar.update(len(rows))
            for future in as_completed(futures):
                variant = futures[future]
                rows[variant.name] = future.result() if future.status == "finished" else failed_row(variant, future)
                log.debug("%s: %s", variant.name, rows[variant.name]["status"])
                bar.update(1)
    except BaseException:
        client.cancel(list(futures))
        raise
    return [rows[v.name] for v in study.variants]


def failed_row(variant: Variant, future) -> dict:
    error = future.exception()
    message = " ".join(f"{error.__class__.__name__}: {error}".split())
    return {
        "variant": variant.name,
        **variant.parameters,
        "status": "failed",
        "message": message,
        "directory": variant.directory,
        "job_hash": variant.digest,
    }


def remove_partial_files(study: Study) -> None:
    """Remove the temporary files (engine/atomic.py names them '.*') that killed tasks left in variant folders."""
    for variant in study.variants:
        for path in Path(variant.directory).glob(".*"):
            if path.is_file():
                path.unlink(missing_ok=True)


def columns(study: Study, rows: list[dict]) -> list[str]:
    stages = list(dict.fromkeys(k for row in rows for k in row if k.startswith("time_") and k not in TAIL))
    return ["variant", "status", "message", *study.keys, *FIGURES, *stages, *TAIL]


def _plots(study: Study, rows: list[dict]) -> list[str]:
    """PNG data URIs: element count and min dihedral against each parameter, one line per setting of the others."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["status"] == "ok"]
    images = []
    for key in study.keys if ok else []:
        figure, axes = plt.subplots(1, 2, figsize=(9, 3.4))
        others = [k for k in study.keys if k != key]
        groups = sorted({tuple(str(r[k]) for k in others) for r in ok})
        for group in groups:
            series = [r for r in ok if tuple(str(r[k]) for k in others) == group]
            label = ", ".join(f"{k} {Path(v).name}" for k, v in zip(others, group)) or None
            xs = [Path(r[key]).name if key == "file" else r[key] for r in series]
            for axis, figure_key in zip(axes, ("tetrahedra", "min_dihedral")):
                axis.plot(xs, [r[figure_key] for r in series], "o-", label=label)
        for axis, title in zip(axes, ("tetrahedra", "min dihedral angle (deg)")):
            axis.set_xlabel(key)
            axis.set_title(title)
            axis.grid(alpha=0.3)
        if len(groups) > 1:
            axes[1].legend(fontsize=7)
        figure.tight_layout()
        buffer = io.BytesIO()
        figure.savefig(buffer, format="png", dpi=90)
        plt.close(figure)
        images.append("data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode())
    return images


def _cell(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else "" if value is None else str(value)


def study_page(study: Study, rows: list[dict]) -> str:
    """The study's HTML page: counts by status, the plots, the table."""
    shown = [
        "variant",
        "status",
        *study.keys,
        "tetrahedra",
        "min_dihedral",
        "conformity_within",
        "time_total",
        "peak_memory_mb",
        "message",
    ]
    counts = ", ".join(f"{sum(r['status'] == s for r in rows)} {s}" for s in ("ok", "refused", "rejected", "failed"))
    head = "".join(f"<th>{html.escape(c)}</th>" for c in shown)
    body = "".join(
        "<tr>"
        + "".join(f"<td>{html.escape(_cell(Path(r.get(c)).name if c == 'file' else r.get(c)))}</td>" for c in shown)
        + "</tr>"
        for r in rows
    )
    images = "".join(f'<p><img src="{uri}"></p>' for uri in _plots(study, rows))
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>study {html.escape(study.source.name)}</title>"
        "<style>body{font-family:sans-serif}td,th{padding:2px 8px;border-bottom:1px solid #ddd;"
        "text-align:left}</style></head><body>"
        f"<h1>study {html.escape(str(study.source))}</h1><p>{len(rows)} variants: {counts}</p>{images}"
        f"<table><tr>{head}</tr>{body}</table></body></html>"
    )


def write_study(study: Study, rows: list[dict]) -> list[Path]:
    """study.csv, study.parquet and study.html in the study's folder, all or none."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = columns(study, rows)
    table = [{c: row.get(c) for c in names} for row in rows]

    def write_csv(tmp):
        with open(tmp, "w", newline="") as handle:
            writer = csv.DictWriter(handle, names)
            writer.writeheader()
            writer.writerows(table)

    return write_all_or_nothing(
        [
            (study.directory / "study.csv", write_csv),
            (study.directory / "study.parquet", lambda tmp: pq.write_table(pa.Table.from_pylist(table), tmp)),
            (study.directory / "study.html", lambda tmp: Path(tmp).write_text(study_page(study, rows))),
        ]
    )


def batch(
    path: str | Path, scheduler: str | None = None, workers: int | None = None, retries: int = 0
) -> tuple[list[dict], list[Path]]:
    """Load a study, mesh its variants on Dask, write its table and page: (rows, files). Interrupted (Ctrl-C),
    an embedded cluster's killed tasks leave no partial files and the study writes nothing."""
    import dask

    study = load_study(path)
    require_batch()
    embedded = not (scheduler or dask.config.get("scheduler-address", None))
    try:
        with dask_client(scheduler, workers) as client:
            rows = run_variants(study, client, retries)
    except KeyboardInterrupt:
        if embedded:
            remove_partial_files(study)
        raise
    return rows, write_study(study, rows)


__all__ = ["Study", "Variant", "load_study", "mesh_variant", "batch", "dask_client", "run_variants", "write_study"]
