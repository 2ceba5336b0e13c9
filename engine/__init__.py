"""fuzzymesh: tetrahedral meshes sized by declarative expert rules.

``engine.mesh(job)`` runs the whole chain on a job (a :class:`~engine.job.Job`,
a job file path or a dict) and returns a :class:`~engine.pipeline.Result`.
"""

from __future__ import annotations

from pathlib import Path

from .errors import FuzzymeshError, GeometryError, JobError, KnowledgeError, LimitError

__version__ = "0.1.0"


def mesh(job, **options):
    """Mesh ``job`` (Job, path to a job file, or dict); see :func:`engine.pipeline.run`."""
    from .job import Job, job_from_dict, load_job
    from .pipeline import run

    if isinstance(job, (str, Path)):
        job = load_job(job)
    elif not isinstance(job, Job):
        job = job_from_dict(job)
    return run(job, **options)


__all__ = ["mesh", "FuzzymeshError", "GeometryError", "JobError", "KnowledgeError", "LimitError", "__version__"]
