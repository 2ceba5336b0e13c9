"""The whole chain: job -> geometry -> features -> sizing -> packing -> mesh -> files."""

from __future__ import annotations

import inspect
import logging
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .acceptance import check_mesh, check_mixed
from .assembly import mesh_assembly
from .atomic import write_all_or_nothing
from .audit import Audit, audit_mesh, idle_patterns
from .cad import CAD_FORMATS, load_cad
from .errors import JobError, LimitError, MeshRejected
from .exact import ExactSurfaces, on_exact_surfaces
from .fe import feature_groups, quadratic, tet_bodies
from .features import Features, apply_names, classify, detect_features
from .geometry import Geometry, load_surface
from .hexdom import mixed_model
from .hexdom import summary as hexdom_summary
from .io import FEModel, mesh_targets
from .job import Job
from .knowledge import KnowledgeBase, Placement, check_placement, load_knowledge
from .mesh import TetMesh
from .meshing import get_mesher
from .packing import Packing, get_packer
from .quadratic import QUADRATIC_FLOOR, curved_volumes, scaled_jacobian
from .quality import boundary_report, size_conformity, tet_quality
from .recombine import recombine
from .report import report_summary, report_targets, volume_errors
from .shapes import build_shape
from .sizing import GRADED_THRESHOLD, SizingField, bind, check_element_limit, pattern_shares

log = logging.getLogger("fuzzymesh")

SIZE_FROM_SCALE = 40.0  # default global size = model size (bounding-box diagonal) / this
LARGE = 1e6  # expected tetrahedra from which the sizing line names the patterns that size most of them


@dataclass(frozen=True, kw_only=True)
class Result:
    """What ``run`` made: the stages' values, the figures and the files written. A frozen value; ``run`` derives
    the one with its files by ``dataclasses.replace``."""

    job: Job
    geometry: Geometry
    features: Features
    sizing: SizingField
    packing: Packing
    mesh: TetMesh
    timings: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)
    audit: Audit | None = None
    conformity: dict = field(default_factory=dict)
    boundary: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # for the report, beside the log


@contextmanager
def stage(name: str, timings: dict):
    start = time.perf_counter()
    yield
    timings[name] = time.perf_counter() - start


def build_geometry(job: Job):
    """Geometry and named features (with the shape's characteristic lengths) of the job's solid."""
    if job.shape is not None:
        try:
            shape = build_shape(job.shape, job.shape_parameters)
        except JobError as error:  # a shape's consistency check: locate it in the job file
            raise JobError(
                error.what, where=error.where or job.where("geometry", "parameters"), fix=error.fix
            ) from None
        features = replace(
            detect_features(shape.geometry, job.feature_angle, shape.face_groups), lengths=dict(shape.lengths)
        )
        return shape.geometry, apply_names(features, shape.name_rules, shape.given_curves)
    if job.geometry_file.suffix.lower() in CAD_FORMATS:
        # touching solids are an assembly (no job key): Features.assembly, meshed by engine.assembly
        return load_cad(
            job.geometry_file, job.feature_angle, allow_multiple_solids=job.allow_multiple_solids, assembly=True
        )
    geometry = load_surface(job.geometry_file, allow_multiple_solids=job.allow_multiple_solids)
    return geometry, detect_features(geometry, job.feature_angle)


def job_placements(job: Job, kb: KnowledgeBase) -> list[Placement]:
    """The recipe's placements, then the job's own (the base pattern alone when neither places any), then the
    sizing defaults' ``always_place`` for every pattern not placed yet."""
    placements = []
    if job.recipe is not None:
        if job.recipe not in kb.recipes:
            raise JobError(
                f"unknown recipe '{job.recipe}'",
                where=job.where("recipe"),
                fix=f"known recipes: {', '.join(sorted(kb.recipes))}",
            )
        placements += kb.recipes[job.recipe].placements
    placements += job.placements
    if not placements:
        base = kb.sizing["base_pattern"]
        placements = [Placement(pattern=base, id="base", source=job.where(), origin="default")]
    placed = {p.pattern for p in placements}
    return placements + [p for p in kb.sizing["always_place"] if p.pattern not in placed]


def check_job_knowledge(job: Job, kb: KnowledgeBase) -> list[Placement]:
    """The job's placements, checked against the knowledge base before any geometry work."""
    placements = job_placements(job, kb)
    for placement in placements:
        check_placement(kb, placement)
    return placements


def build_sizing(job: Job, geometry: Geometry, features: Features, kb: KnowledgeBase) -> SizingField:
    size = job.size if job.size is not None else geometry.scale / SIZE_FROM_SCALE
    features = classify(features, kb.feature_kinds)  # as prepare's already are: classify adds no kind twice
    placed = bind(kb, job_placements(job, kb), features, geometry, size)
    if not placed:
        raise JobError(
            "no pattern could be placed on this solid: the placements match none of its features",
            where=job.where("recipe") if job.recipe else job.where("place"),
            fix="add the base pattern 'uniform-domain' or place patterns with 'at:' on named features",
        )
    return SizingField.build(
        placed=placed,
        geometry=geometry,
        gradation=kb.sizing["gradation"],
        global_size=size,
        min_size=job.min_size,
        max_size=job.max_size,
        features=features,
    )


def fe_model(
    job: Job,
    mesh: TetMesh,
    geometry: Geometry,
    features: Features,
    audit: Audit | None = None,
    floor: float = QUADRATIC_FLOOR,
    exact: ExactSurfaces | None = None,
) -> FEModel:
    """The mesh as the files hold it: the job's element order (10-node elements curved no further than a
    scaled Jacobian of ``floor``, onto the ``exact`` surfaces the exact stage fitted, else fitted here), the
    bodies' and features' named groups, the audit, and the cell field ``body`` (1-based)."""
    quadratic_elements = quadratic(mesh, geometry, features, floor, exact=exact) if job.output_order == 2 else None
    body = tet_bodies(mesh, geometry)
    return FEModel.build(
        mesh,
        groups=feature_groups(mesh, features, body),
        quadratic=quadratic_elements,
        audit=audit,
        cell_data={"body": (body + 1).astype(np.int32)},
    )


def write_files(model: FEModel, summary: dict, job: Job, name: str) -> list[Path]:
    """The mesh in the job's formats, its audit legend and its report, all or none (engine/atomic.py)."""
    targets = mesh_targets(model, job.output_dir, name, job.output_formats)
    if model.legend is not None:
        targets += report_targets(
            summary, model.legend, model.points, model.tets[:, :4], model.cell_data, job.output_dir, name
        )
    return write_all_or_nothing(targets)


def describe_mesher_stats(stats: dict) -> str:
    """The mesher's counts and stage times as ``; key value, ...`` for the log."""
    items = [
        f"{key.replace('_', ' ')} {value:.3g}" if isinstance(value, float) else f"{key.replace('_', ' ')} {value}"
        for key, value in stats.items()
        if not isinstance(value, dict)
    ]
    items += [f"{key} {value:.2f} s" for key, value in stats.get("seconds", {}).items()]
    return "; " + ", ".join(items) if items else ""


def check_output_dir(job: Job) -> None:
    """Refuse, before any work, an output folder that is a file or that cannot be created or written, and an
    output file that is a folder."""
    directory = Path(job.output_dir)
    where = job.where("output", "directory")
    if directory.exists() and not directory.is_dir():
        raise JobError(
            f"the output folder '{directory}' is an existing file",
            where=where,
            fix="name a folder (output.directory or --out)",
        )
    for target in (directory / f"{job.output_name}.{suffix}" for suffix in job.output_formats):
        if target.is_dir():
            raise JobError(
                f"the output file '{target}' is an existing folder",
                where=job.where("output", "name"),
                fix="remove it, or give another output.name or output folder",
            )
    existing = next(p for p in (directory, *directory.parents) if p.exists())
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise JobError(
            f"cannot write the output folder '{directory}': '{existing}' is not writable",
            where=where,
            fix="name a folder you can write (output.directory or --out)",
        )


class Prepared(NamedTuple):
    """Everything a job needs before packing."""

    knowledge: KnowledgeBase
    geometry: Geometry
    features: Features
    sizing: SizingField


def _placed_list(placed, most: int = 3) -> str:
    """The placed patterns' ids, those of one ``every:`` placement on more than ``most`` features as one item:
    'static-stress/place[2] on 64 features' (a recipe's re-entrant edges), not 64 ids."""
    groups: dict[str, list[str]] = {}
    for p in placed:
        groups.setdefault(p.placement.id if p.placement.every else p.id, []).append(p.id)
    return ", ".join(
        f"{placement} on {len(ids)} features" if len(ids) > most else ", ".join(ids)
        for placement, ids in groups.items()
    )


def _drivers(sizing) -> str:
    """', most sized by PATTERN (S %), ...' for the patterns that size a tenth or more of the expected elements."""
    shares = [f"{name} ({100 * share:.0f} %)" for name, share in pattern_shares(sizing).items() if share >= 0.1]
    return f", most sized by {', '.join(shares)}" if shares else ""


def prepare(job: Job, max_elements: float | None = None, timings: dict | None = None) -> Prepared:
    """The job's knowledge (loaded and checked against the job), geometry, features and sizing field, logged
    with their times in ``timings``; refuses a sizing needing more than ``max_elements`` tetrahedra (None:
    20 million, or what this machine's memory holds, engine/sizing/counts.py). The
    one way to get there: the pipeline, ``fuzzymesh explain``, tests and benchmarks."""
    timings = {} if timings is None else timings
    kb = load_knowledge(job.knowledge)
    check_job_knowledge(job, kb)
    with stage("geometry", timings):
        geometry, features = build_geometry(job)
        features = classify(features, kb.feature_kinds)
    log.info(
        "geometry: %s, %d faces, volume %.6g, %d corners, %d curves, %d patches, named: %s (%.2f s)",
        job.shape or job.geometry_file,
        len(geometry.faces),
        geometry.volume,
        len(features.corners),
        len(features.curves),
        len(features.patches),
        features.names_listed(),
        timings["geometry"],
    )
    with stage("sizing", timings):
        sizing = build_sizing(job, geometry, features, kb)
        try:
            expected = check_element_limit(sizing, max_elements, job.output_order)
        except LimitError as error:
            raise LimitError(error.what, where=job.where("size"), fix=error.fix) from None
    log.info(
        "sizing: %d placed patterns (%s), H = %.4g, h from %.4g to %.4g, about %.3g tetrahedra expected%s (%.2f s)",
        len(sizing.placed),
        _placed_list(sizing.placed),
        sizing.global_size,
        sizing.h_min,
        sizing.h_max,
        expected,
        _drivers(sizing) if expected > LARGE else "",
        timings["sizing"],
    )
    return Prepared(kb, geometry, features, sizing)


def _log_hexdom(figures: dict, seconds: float) -> None:
    cells = figures["cells"]
    log.info(
        "hex-dominant: %s; %.1f %% of the volume in hexahedra; scaled Jacobian min (1st percentile) %s (%.2f s)",
        ", ".join(f"{c['cells']} {name}" for name, c in cells.items()),
        100 * figures["hex_volume_share"],
        ", ".join(
            f"{name} {c['scaled_jacobian']['min']:.3f} ({c['scaled_jacobian']['p01']:.3f})"
            for name, c in cells.items()
            if c["scaled_jacobian"]
        ),
        seconds,
    )


def _with_mixed(model: FEModel, mixed) -> FEModel:
    """The FE model with the hex-dominant cells (engine/hexdom.py): the recombination's centre nodes added (node
    level and entity -1), the groups and audit fields carried to the cells; the tets stay for the report's view."""
    from dataclasses import replace

    extra = len(mixed.points) - len(model.points)

    def pad(values):
        return np.r_[values, np.full(extra, -1 if values.dtype.kind in "iu" else 0, dtype=values.dtype)]

    return replace(
        model,
        points=mixed.points,
        node_level=pad(model.node_level),
        node_entity=pad(model.node_entity),
        point_data={k: pad(v) for k, v in model.point_data.items()},
        mixed=mixed_model(mixed, model.groups, model.cell_data),
    )


def _no_mesh(job: Job, what: str, error: Exception) -> MeshRejected:
    return MeshRejected(
        f"the {job.mesher} mesher made no valid mesh of the {what} of the {job.packer} packer: {error}",
        check="meshing",
        fix="if the job replaces the population rules or uses a plug-in packer or mesher, "
        "check them; else mesh again with another seed and report the input",
    )


def _mesh_assembly(job: Job, packer, mesher, geometry, features, sizing, kb, timings: dict):
    """(Packing, TetMesh) of touching solids (engine/assembly.py): each body packed and meshed in turn, the
    packer's and the mesher's times summed into the ``packing`` and ``meshing`` timings."""
    assembly = features.assembly
    if "prescribed" not in inspect.signature(mesher).parameters:
        raise JobError(
            f"the file holds an assembly ({len(assembly.bodies)} touching solids) and the mesher '{job.mesher}' "
            "cannot mesh one: it takes no prescribed interface triangles",
            where=job.where("mesher"),
            fix="use the default mesher 'delaunay'",
        )
    timings["packing"] = timings["meshing"] = 0.0

    def timed(function, key):
        def call(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                timings[key] += time.perf_counter() - start

        return call

    try:
        mesh, packing = mesh_assembly(
            timed(packer, "packing"), timed(mesher, "meshing"), geometry, features, sizing, seed=job.seed, knowledge=kb
        )
    except RuntimeError as error:  # a body's nodes make no mesh, or an interface lost its triangles
        raise _no_mesh(job, f"assembly's {len(assembly.bodies)} bodies", error) from None
    log.info(
        "packing (%s): %d nodes in %d bodies (%s) (%.2f s)",
        job.packer,
        len(packing),
        len(assembly.bodies),
        ", ".join(assembly.names),
        timings["packing"],
    )
    return packing, mesh


def run(job: Job, *, max_elements: float | None = None, write: bool = True, keep_invalid: bool = False) -> Result:
    """Mesh the job's solid, check the mesh against the acceptance gate (engine/acceptance.py) and write the
    outputs when ``write``. Errors are FuzzymeshErrors; a rejected mesh raises MeshRejected and writes nothing,
    or, with ``keep_invalid``, writes the files as ``<name>.invalid.*`` first."""
    timings: dict = {}
    if write:
        check_output_dir(job)
    packer, mesher = get_packer(job.packer), get_mesher(job.mesher)  # the plug-ins' contracts, before any work
    kb, geometry, features, sizing = prepare(job, max_elements, timings)
    if features.assembly is not None:
        packing, mesh = _mesh_assembly(job, packer, mesher, geometry, features, sizing, kb, timings)
    else:
        with stage("packing", timings):
            packing = packer(geometry, features, sizing, seed=job.seed, knowledge=kb)
        log.info("packing (%s): %d nodes (%.2f s)", job.packer, len(packing), timings["packing"])
        with stage("meshing", timings):
            try:
                mesh = mesher(packing, geometry, features, seed=job.seed)
            except RuntimeError as error:  # the nodes do not make a mesh of this solid
                raise _no_mesh(job, f"{len(packing)} nodes", error) from None
    log.info(
        "meshing (%s): %d nodes, %d tetrahedra, volume %.6g (input surface %.6g, %+.3f %%)%s (%.2f s)",
        job.mesher,
        len(mesh.points),
        len(mesh.tets),
        mesh.volume,
        geometry.volume,
        100 * (mesh.volume / geometry.volume - 1),
        describe_mesher_stats(mesh.stats),
        timings["meshing"],
    )
    with stage("exact", timings):
        mesh, moved, exact = on_exact_surfaces(mesh, geometry, features)
    log.info(
        "exact surfaces: %d of %d patches and %d of %d curves have one (a plane, cylinder, sphere, cone or torus, or "
        "the CAD face or edge itself); %d nodes moved "
        "onto them, at most %.3g%s%s (%.2f s)",
        moved["exact_patches"],
        moved["patches"],
        moved["exact_curves"],
        moved["curves"],
        moved["nodes_moved"],
        moved["largest_move"],
        f", {moved['nodes_kept_for_validity']} kept on the facets so that no tet folds or flattens"
        if moved["nodes_kept_for_validity"]
        else "",
        f"; {moved['patches_left_on_facets']} curved patches left on the input's facets (a coarse STL: its facets "
        f"lie up to {moved['facet_deviation_left']:.3g} times farther from the surface fitted to them than the "
        "larger of 0.05 h and the mesh's own chord sagitta there, so the nodes stay on the facets)"
        if moved.get("patches_left_on_facets")
        else "",
        timings["exact"],
    )
    with stage("quality", timings):
        elements = tet_quality(mesh.points, mesh.tets)
        quality = elements.summary()
    below = quality["below"]
    log.info(
        "quality: min dihedral %.2f deg (1st percentile %.2f), %d below 10 deg, %d below 5 deg; "
        "radius ratio min %.3f, %d below 0.1 (%.2f s)",
        quality["min_dihedral"]["min"],
        quality["min_dihedral"]["p01"],
        below["min_dihedral_10"],
        below["min_dihedral_5"],
        quality["radius_ratio"]["min"],
        below["radius_ratio_0.1"],
        timings["quality"],
    )
    with stage("boundary", timings):
        boundary = boundary_report(mesh, geometry, sizing)
    there, back = boundary["hausdorff_input_to_mesh"], boundary["hausdorff_mesh_to_input"]
    beyond = f" beyond the tessellation's own {geometry.chord:.3g} from the CAD faces" if geometry.chord else ""
    log.info(
        "boundary: %d triangles, %s, %d boundary edges, %d component(s); Hausdorff input -> mesh max %.4g "
        "(%.3g h%s), mean %.4g; mesh -> input max %.4g (%.3g h%s), mean %.4g; area %+.3f %% of the input's, volume "
        "%s; triangle quality min %.3f (%.2f s)",
        boundary["triangles"],
        "two-manifold" if boundary["two_manifold"] else "NOT two-manifold",
        boundary["boundary_edges"],
        boundary["components"],
        there["max"],
        there["max_over_h"],
        beyond,
        there["mean"],
        back["max"],
        back["max_over_h"],
        beyond,
        back["mean"],
        100 * (boundary["area"] / boundary["input_area"] - 1),
        volume_errors(boundary["volume"], geometry.volume, geometry.exact_volume),
        boundary["triangle_quality"]["min"],
        timings["boundary"],
    )
    with stage("audit", timings):
        audit = audit_mesh(mesh, sizing, packing, features, kb, str(job.source))
    shares = np.bincount(audit.cells["winner"] + 1, minlength=len(sizing.placed) + 1) / max(len(mesh.tets), 1)
    winners = ", ".join(
        f"{name} {100 * share:.1f} %"
        for name, share in zip(["none"] + [p.id for p in sizing.placed], shares)
        if share > 0
    )
    log.info(
        "audit: %d elements sized by %s; %.1f %% lowered by more than %g %% by the gradation limit (%.2f s)",
        len(mesh.tets),
        winners,
        100 * np.mean(audit.cells["graded"]),
        100 * GRADED_THRESHOLD,
        timings["audit"],
    )
    with stage("conformity", timings):
        conformity = size_conformity(mesh, sizing, audit.cells["winner"])
    log.info(
        "size conformity: edge length / target size median %.3f, %.1f %% within [%g, %g] (%s) (%.2f s)",
        conformity["median"],
        100 * conformity["within"],
        *conformity["band"],
        ", ".join(f"{name} {100 * s['within']:.1f} %" for name, s in conformity["by_pattern"].items() if s["edges"]),
        timings["conformity"],
    )
    warnings, outdone = idle_patterns(audit.legend)
    for warning in warnings:
        log.warning(warning)
    if outdone:
        log.info(
            "placed by the base pattern, a recipe or the sizing defaults, %d patterns win no element (another asks "
            "for smaller ones wherever they reach): %s",
            len(outdone),
            ", ".join(outdone),
        )
    result = Result(
        job=job,
        geometry=geometry,
        features=features,
        sizing=sizing,
        packing=packing,
        mesh=mesh,
        timings=timings,
        quality=quality,
        audit=audit,
        conformity=conformity,
        boundary=boundary,
        warnings=warnings,
    )
    tolerances = kb.sizing["acceptance"]
    mixed = None
    if job.output_elements == "hex-dominant":
        with stage("recombine", timings):
            mixed = recombine(mesh.points, mesh.tets, tolerances.hex_jacobian)
            quality["hex_dominant"] = hexdom_summary(mixed)
        _log_hexdom(quality["hex_dominant"], timings["recombine"])
    model = (
        fe_model(job, mesh, geometry, features, audit, tolerances.quadratic_jacobian, exact)
        if write or job.output_order == 2
        else None
    )
    if mixed is not None and model is not None:
        model = _with_mixed(model, mixed)
    jacobian = None
    if job.output_order == 2:
        jacobian = scaled_jacobian(model.points, model.tets)
        quality["quadratic"] = {
            "scaled_jacobian_min": float(jacobian.min()),
            "volume": float(curved_volumes(model.points, model.tets).sum()),
        }
        log.info(
            "10-node elements: scaled Jacobian min %.3f; volume %.6g, %s",
            jacobian.min(),
            quality["quadratic"]["volume"],
            volume_errors(quality["quadratic"]["volume"], geometry.volume, geometry.exact_volume),
        )
    with stage("acceptance", timings):
        try:
            kept = check_mesh(mesh, geometry, features, elements, boundary, tolerances, jacobian)
            if mixed is not None:
                quality["hex_dominant"]["boundary"] = check_mixed(mixed, mesh.volume, geometry, features, tolerances)
        except MeshRejected:
            if write and keep_invalid:
                files = write_files(
                    model, {**report_summary(result), "warnings": warnings}, job, f"{job.output_name}.invalid"
                )
                log.warning("kept the rejected mesh for inspection: %s", ", ".join(map(str, files)))
            raise
    for warning in kept:
        log.warning(warning)
    warnings = [*warnings, *kept]
    result = replace(result, warnings=warnings)
    log.info("acceptance: passed (%.2f s)", timings["acceptance"])
    if write:
        with stage("output", timings):
            files = write_files(model, {**report_summary(result), "warnings": warnings}, job, job.output_name)
            result = replace(result, files=files)
        log.info("output: %s (%.2f s)", ", ".join(map(str, result.files)), timings["output"])
    return result
