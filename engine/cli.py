"""The ``fuzzymesh`` command line: a thin shell over :mod:`engine`.

Every user error is printed as one line ``fuzzymesh: error: ...`` with the
error's exit code (engine/errors.py: 2 bad input, 4 mesh rejected by the acceptance
gate; 1 for lint findings, 3 internal faults); no traceback unless ``--debug``.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
from pathlib import Path

import numpy as np

from .errors import FuzzymeshError, JobError, LimitError

log = logging.getLogger("fuzzymesh")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def _angle(text: str) -> float:
    value = _positive_float(text)
    if not value < 180:
        raise argparse.ArgumentTypeError(f"must be an angle in degrees between 0 and 180, got {text}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def _plane(text: str) -> tuple[int, float]:
    """'x=10', 'y=0' or 'z=-2.5' -> (axis, value)."""
    axis, _, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = float("nan")
    if axis.strip().lower() not in ("x", "y", "z") or not np.isfinite(number):
        raise argparse.ArgumentTypeError(f"'{text}' is not a plane AXIS=VALUE such as z=10")
    return "xyz".index(axis.strip().lower()), number


class OneLineParser(argparse.ArgumentParser):
    """Argument errors as one line, like every other error of the CLI."""

    def error(self, message):
        self.exit(2, f"fuzzymesh: error: {self.prog}: {message}; see '{self.prog} --help'\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="fuzzymesh", description=__import__("engine").__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    mesh = commands.add_parser("mesh", help="mesh a job file (default: the built-in junction example)")
    mesh.add_argument("job", nargs="?", help="job YAML file; omitted: the plate-cylinder junction example")
    mesh.add_argument("--out", type=Path, help="output folder (overrides the job's output.directory)")
    mesh.add_argument("--size", type=_positive_float, help="global element size (overrides the job's size)")
    mesh.add_argument("--seed", type=_seed, help="random seed >= 0 (overrides the job's seed)")
    mesh.add_argument(
        "--max-elements",
        type=_positive_float,
        default=None,
        help="refuse jobs expected to exceed this many tetrahedra (default: 2e7, and refuse jobs expected to need "
        "more memory than this machine has available; a limit given here skips the memory check)",
    )
    mesh.add_argument("-q", "--quiet", action="store_true", help="print warnings and errors only")
    mesh.add_argument(
        "--keep-invalid",
        action="store_true",
        help="when the acceptance gate rejects the mesh (exit 4), still write it as <name>.invalid.* for inspection",
    )
    mesh.set_defaults(run=_cmd_mesh)

    lint = commands.add_parser("lint", help="check rule, pattern, recipe and feature files")
    lint.add_argument("paths", nargs="*", type=Path, help="files or folders (default: the shipped knowledge base)")
    lint.set_defaults(run=_cmd_lint)

    explain = commands.add_parser(
        "explain",
        help="explain why a point or an element got its size, or where a node came from",
        description="TARGET is a job file (--at: the sizing at a point) "
        "or a mesh output folder or .vtu with its .audit.json (--element N, 0-based, or "
        "--at: the element containing the point; --node N, 0-based: the node's bubble and "
        "the population event that inserted it)",
    )
    explain.add_argument("job", metavar="TARGET", help="job YAML file, or output folder / .vtu file")
    where = explain.add_mutually_exclusive_group(required=True)
    where.add_argument("--at", nargs=3, type=float, metavar=("X", "Y", "Z"))
    where.add_argument("--element", type=int, metavar="N")
    where.add_argument("--node", type=int, metavar="N")
    explain.set_defaults(run=_cmd_explain)

    report = commands.add_parser(
        "report",
        help="rewrite the HTML report of a meshed output folder",
        description="rebuilds <name>.report.html from <name>.vtu, <name>.audit.json and <name>.report.json in OUT",
    )
    report.add_argument("out", type=Path, metavar="OUT", help="output folder of 'fuzzymesh mesh'")
    report.add_argument("--name", default=None, help="base name of the files (default: the one report there)")
    report.add_argument(
        "--cut",
        type=_plane,
        metavar="AXIS=VALUE",
        help="the plane of the cut through the mesh, e.g. z=10 (default: the plane holding the "
        "longest and shortest extents, at the median node)",
    )
    report.set_defaults(run=_cmd_report)

    view = commands.add_parser("view", help="open the HTML report of a meshed output folder in the default browser")
    view.add_argument("out", type=Path, metavar="OUT", help="output folder of 'fuzzymesh mesh'")
    view.add_argument("--name", default=None, help="base name of the files (default: the one report there)")
    view.set_defaults(run=_cmd_view)

    from .validation import CASES

    validate = commands.add_parser(
        "validate",
        help="solve linear elasticity on a mesh and compare with a published solution (needs the 'fe' extra)",
        description="plate-hole: Peterson's Kt of a plate with a central hole in tension, "
        "meshed by the static-stress recipe; sphere: Lamé's thick hollow sphere "
        "under internal pressure. Prints the table; see docs/validation.md",
    )
    validate.add_argument("case", metavar="NAME", choices=list(CASES), help=f"one of {', '.join(CASES)}")
    validate.add_argument(
        "--scale",
        type=_positive_float,
        default=1.0,
        help="multiply every element size by this (default 1; 3: a coarse mesh in seconds)",
    )
    validate.add_argument("--seed", type=_seed, default=0, help="random seed of the mesh")
    validate.add_argument(
        "--study",
        action="store_true",
        help="plate-hole: the convergence study, Kt error against nodes for the recipe's graded mesh "
        "and a uniform mesh (minutes); writes fe_convergence.json, .md, .png to --out",
    )
    validate.add_argument(
        "--seeds", type=int, default=3, metavar="N", help="--study: mesh every scale with seeds 0 .. N-1 (default 3)"
    )
    validate.add_argument("--out", type=Path, default=Path("validation-out"), help="--study: output folder")
    validate.set_defaults(run=_cmd_validate)

    features = commands.add_parser(
        "features",
        help="list the corners, curves and patches of a solid, with their kinds, sizes and places (no meshing)",
        description="FILE_OR_JOB is a surface file (STL, OBJ, PLY, OFF, GLB), a CAD file (STEP, IGES, "
        "BREP) or a job file "
        "(its solid: built-in shape or file, named features, feature angle, "
        "knowledge). Lists every corner, curve and patch: id, names, feature "
        "kinds (hole, fillet, junction, re-entrant-edge, ...), size (curve: "
        "length L and circle radius r; patch: a CAD face's type, area A and cylinder "
        "or fillet radius r), "
        "centroid and bounding box",
    )
    features.add_argument("target", metavar="FILE_OR_JOB", help="surface file, CAD file or job YAML file")
    features.add_argument(
        "--feature-angle",
        type=_angle,
        metavar="DEGREES",
        help="dihedral angle above which an edge is a feature edge (default: the job's, or 30)",
    )
    features.add_argument(
        "--knowledge", type=Path, action="append", default=[], help="extra knowledge files or folders (feature kinds)"
    )
    features.add_argument("--json", action="store_true", help="print JSON instead of the table")
    features.set_defaults(run=_cmd_features)

    batch = commands.add_parser(
        "batch",
        help="mesh every variant of a study (a parameter grid or a folder of "
        "parts) on dask.distributed (needs the 'batch' extra)",
        description="STUDY is a study file (docs/batch.md): a base job and what varies. "
        "Writes every variant's outputs to <study folder>/variants/NAME and the "
        "table study.csv / study.parquet and the page study.html; a variant whose "
        "job is unchanged and whose outputs are complete is not meshed again. "
        "Exit 0 when the table is written, whatever the variants' status",
    )
    batch.add_argument("study", type=Path, metavar="STUDY", help="study YAML file")
    batch.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing Dask cluster, e.g. tcp://HOST:8786 (default: DASK_SCHEDULER_ADDRESS, else a local cluster)",
    )
    batch.add_argument(
        "--workers", type=int, metavar="N", help="local cluster: N worker processes (default: one per core)"
    )
    batch.add_argument(
        "--retries",
        type=int,
        default=0,
        metavar="N",
        help="let Dask run a variant that ended in an internal fault or a lost worker N more times",
    )
    batch.add_argument("-q", "--quiet", action="store_true", help="print warnings and errors only")
    batch.set_defaults(run=_cmd_batch)

    rules = commands.add_parser("rules", help="export rule bases (e.g. to IEC 61131-7 FCL)")
    rule_verbs = rules.add_subparsers(dest="verb", required=True, parser_class=OneLineParser)
    export = rule_verbs.add_parser(
        "export",
        help="write a rule base, or every rule base of a rule file, as FCL; "
        "annotations keep what FCL cannot hold (docs/rules.md, FCL)",
    )
    export.add_argument("rulebase", help="a rule base id (population.delete) or a rule file id (population)")
    export.add_argument("--fcl", action="store_true", required=True, help="write IEC 61131-7 FCL (the one format)")
    export.add_argument("-o", "--output", type=Path, help="the file to write (default: standard output)")
    export.add_argument("--knowledge", type=Path, action="append", default=[], help="extra knowledge files or folders")
    export.set_defaults(run=_cmd_rules_export)

    for noun in ("patterns", "recipes"):
        sub = commands.add_parser(noun, help=f"list or show the {noun} of the knowledge base")
        verbs = sub.add_subparsers(dest="verb", required=True, parser_class=OneLineParser)
        verbs.add_parser("list", help=f"list the {noun}")
        show = verbs.add_parser("show", help=f"show one of the {noun}")
        show.add_argument("name")
        sub.add_argument("--knowledge", type=Path, action="append", default=[], help="extra knowledge files or folders")
        sub.set_defaults(run=_cmd_library, noun=noun)
    return parser


def _cmd_lint(args) -> int:
    from .knowledge import default_paths, lint

    paths = args.paths or default_paths()
    errors = lint(paths)
    for line in errors:
        print(line)
    if errors:
        return 1
    print(f"ok: {', '.join(map(str, paths))}")
    return 0


def _cmd_explain(args) -> int:
    target = Path(args.job)
    if target.is_dir() or target.suffix == ".vtu":
        return _explain_saved(target, args)
    if args.at is None:
        raise JobError(
            f"--{'element' if args.node is None else 'node'} needs a mesh output folder or .vtu, not a job file",
            where=str(target),
            fix="run 'fuzzymesh mesh' first and give its output folder",
        )
    from .explain import explain_point
    from .job import load_job
    from .pipeline import prepare

    logging.getLogger().setLevel(logging.WARNING)
    _, geometry, _, sizing = prepare(load_job(args.job), max_elements=float("inf"))
    inside = bool(geometry.contains([args.at])[0])
    print(explain_point(sizing, args.at, inside))
    return 0


def _explain_saved(target: Path, args) -> int:
    """--element / --at / --node on a written mesh, from its VTU audit fields and JSON legend."""
    import json

    import meshio

    from .audit import element_at, explain_element, explain_node

    vtu = target if target.suffix == ".vtu" else next(iter(sorted(target.glob("*.vtu"))), target / "mesh.vtu")
    legend_path = vtu.with_suffix(".audit.json")
    for path in (vtu, legend_path):
        if not path.is_file():
            raise JobError(
                "no saved mesh audit here",
                where=str(path),
                fix="give the output folder of 'fuzzymesh mesh' (it writes <name>.vtu and <name>.audit.json)",
            )
    mesh = meshio.read(vtu)
    cells = {name: values[0] for name, values in mesh.cell_data.items()}
    legend = json.loads(legend_path.read_text())
    if args.node is not None:
        try:
            print(explain_node(mesh.point_data, legend, mesh.points, args.node))
        except IndexError as error:
            raise JobError(str(error), where=str(vtu), fix="give a node number from 0 to the node count - 1") from None
        return 0
    element = args.element
    if args.at is not None:
        tets = next(block.data for block in mesh.cells if block.type.startswith("tetra"))[:, :4]
        element = element_at(mesh.points, tets, np.asarray(args.at, dtype=float))
        if element < 0:
            print(f"point ({', '.join(f'{c:.6g}' for c in args.at)}) is in no element of {vtu}")
            return 1
        print(f"point ({', '.join(f'{c:.6g}' for c in args.at)}) lies in element {element}")
    try:
        print(explain_element(cells, legend, element))
    except IndexError as error:
        raise JobError(
            str(error), where=str(vtu), fix="give an element number from 0 to the element count - 1"
        ) from None
    return 0


def _cmd_features(args) -> int:
    import json

    from .describe import feature_records, feature_table, solid_features

    source, geometry, features = solid_features(args.target, args.feature_angle, args.knowledge)
    records = feature_records(features)
    if args.json:
        print(
            json.dumps(
                {"source": source, "feature_angle": features.feature_angle, "bodies": geometry.bodies, **records},
                indent=1,
            )
        )
        return 0
    print(
        f"{source}: {len(features.corners)} corners, {len(features.curves)} curves, {len(features.patches)} "
        f"patches (feature angle {features.feature_angle:g} deg"
        + (f", {geometry.bodies} bodies)" if geometry.bodies > 1 else ")")
    )
    print(feature_table(records, geometry.scale))
    if any(r.get("sharp") is False for r in records["curves"]):
        print(
            "(smooth cut): not an edge of the solid but a cut across a smooth surface, where a face meets a tangent "
            "one (a fillet's border) or a curved surface is cut into pieces that can be flattened"
        )
    return 0


def _report_name(args, suffixes: tuple[str, ...], fix: str) -> str:
    """The base name of the one report in args.out (or args.name), its files with these suffixes present."""
    names = [args.name] if args.name else sorted(p.name[: -len(".report.json")] for p in args.out.glob("*.report.json"))
    if len(names) != 1:
        raise JobError(
            "no report here" if not names else f"several reports here: {', '.join(names)}",
            where=str(args.out),
            fix="give the output folder of 'fuzzymesh mesh'" + ("" if not names else " and --name NAME"),
        )
    name = names[0]
    for suffix in suffixes:
        if not (args.out / f"{name}{suffix}").is_file():
            raise JobError(f"'{name}{suffix}' is missing", where=str(args.out), fix=fix)
    return name


def _cmd_report(args) -> int:
    from .report import write_report

    for path in write_report(
        args.out,
        _report_name(args, (".vtu", ".audit.json", ".report.json"), "mesh again with 'vtu' among output.formats"),
        args.cut,
    ):
        print(f"wrote {path}")
    return 0


def _cmd_view(args) -> int:
    import webbrowser

    name = _report_name(args, (".report.html",), "rebuild it: fuzzymesh report OUT")
    page = (args.out / f"{name}.report.html").resolve()
    if not webbrowser.open(page.as_uri()):
        raise FuzzymeshError("no web browser could be started", fix=f"open {page} in a browser")
    print(f"opened {page}")
    return 0


def _cmd_validate(args) -> int:
    from .validation import require_fe, run_case

    require_fe()
    logging.getLogger().setLevel(logging.WARNING)
    if not args.study:
        print(run_case(args.case, args.scale, args.seed).table())
        return 0
    if args.case != "plate-hole":
        raise FuzzymeshError(
            f"the convergence study is for plate-hole, not {args.case}",
            fix="run 'fuzzymesh validate plate-hole --study'",
        )
    if args.seeds < 1:
        raise FuzzymeshError(f"--seeds must be at least 1, got {args.seeds}", fix="e.g. --seeds 3")
    from .validation.study import run_study, write_study

    def progress(row):
        print(
            f"{row['series']} x {row['scale']:g}, seed {row['seed']}: {row['nodes']:,} nodes, Kt {row['Kt']:.4f} "
            f"({100 * row['error']:+.2f} %), {sum(row['seconds'].values()):.0f} s",
            file=sys.stderr,
            flush=True,
        )

    study = run_study(seeds=range(args.seeds), progress=progress)
    paths = write_study(study, args.out)
    print(paths[1].read_text())
    for path in paths:
        print(f"wrote {path}")
    return 0


def _cmd_rules_export(args) -> int:
    from .atomic import write_all_or_nothing
    from .fcl import to_fcl
    from .knowledge import load_knowledge

    kb = load_knowledge(args.knowledge)
    whole_file = args.rulebase not in kb.rulebases  # a rule file id: all its rule bases and its packer settings
    file_id = args.rulebase if whole_file else args.rulebase.rsplit(".", 1)[0]
    bases = [
        base
        for name, base in kb.rulebases.items()
        if (name.rsplit(".", 1)[0] == file_id if whole_file else name == args.rulebase)
    ]
    if not bases:
        raise FuzzymeshError(
            f"no rule base or rule file '{args.rulebase}'", fix=f"known rule bases: {', '.join(sorted(kb.rulebases))}"
        )
    text = to_fcl(bases, file_id, kb.packer_settings.get(file_id) if whole_file else None)
    if args.output is None:
        sys.stdout.write(text)
    else:
        write_all_or_nothing([(args.output, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))])
    return 0


def _cmd_library(args) -> int:
    from .knowledge import load_knowledge

    kb = load_knowledge(args.knowledge)
    table = kb.patterns if args.noun == "patterns" else kb.recipes
    if args.verb == "list":
        for name, item in sorted(table.items()):
            summary = " ".join(item.doc.split())
            print(f"{name:22s} {summary[:90]}{'...' if len(summary) > 90 else ''}")
        return 0
    if args.name not in table:
        raise FuzzymeshError(
            f"no {args.noun[:-1]} named '{args.name}'", fix=f"known {args.noun}: {', '.join(sorted(table))}"
        )
    print(_describe_pattern(table[args.name]) if args.noun == "patterns" else _describe_recipe(table[args.name]))
    return 0


def _describe_pattern(pattern) -> str:
    lines = [
        f"pattern {pattern.name}  ({pattern.source})",
        "",
        " ".join(pattern.doc.split()),
        "",
        f"anchor: {pattern.anchor}"
        + (f"; placed by 'every:' on {', '.join(pattern.accepts)}" if pattern.accepts else ""),
        f"L (scale): {pattern.scale}; H: the job's global size",
    ]
    if pattern.parameters:
        lines.append("parameters:")
        for name, p in pattern.parameters.items():
            default = "required" if p.default is None else f"default {p.default:g}"
            lines.append(f"  {name} ({default}): {p.doc}")
    for role, (default, doc) in pattern.roles.items():
        lines.append(f"role {role} (default feature '{default}'): {doc}")
    for zone in pattern.zones:
        lines.append(
            f"zone {zone.id} ({zone.source}): distance {zone.distance}, {zone.law} size law "
            f"near = {zone.near.text}"
            + (f", far = {zone.far.text}, over = {zone.over.text}" if zone.far else "")
            + (
                f"; membership trapezoid [{', '.join(e.text for e in zone.trapezoid)}]"
                if zone.trapezoid
                else "; constant membership"
            )
            + f", height {zone.height.text}"
            + (f"; active if {zone.active_if.text} > 0" if zone.active_if else "")
        )
    return "\n".join(lines)


def _describe_recipe(recipe) -> str:
    lines = [f"recipe {recipe.name}  ({recipe.source})", "", " ".join(recipe.doc.split()), "", "places:"]
    for p in recipe.placements:
        where = (
            f"at '{p.at}'"
            if p.at
            else f"on every {p.every}"
            if p.every
            else f"at {p.point}"
            if p.point
            else f"in {p.region}"
            if p.region
            else "over the whole solid"
        )
        extra = "".join(f", {k} = {v}" for k, v in p.parameters.items())
        roles = "".join(f", {k} -> '{v}'" for k, v in p.roles.items())
        lines.append(f"  {p.pattern} {where}{extra}{roles}  ({p.source})")
    return "\n".join(lines)


def _cmd_batch(args) -> int:
    from .batch import batch

    if args.workers is not None and args.workers < 1 or args.retries < 0:
        raise FuzzymeshError("--workers must be at least 1 and --retries at least 0", fix="e.g. --workers 2")
    rows, files = batch(args.study, args.scheduler, args.workers, args.retries)
    counts = ", ".join(f"{sum(r['status'] == s for r in rows)} {s}" for s in ("ok", "refused", "rejected", "failed"))
    log.info(
        "%d variants: %s (%d from earlier runs); wrote %s",
        len(rows),
        counts,
        sum(bool(r.get("cached")) for r in rows),
        ", ".join(map(str, files)),
    )
    return 0


def _cmd_mesh(args) -> int:
    from .job import default_job, load_job
    from .pipeline import run

    job = load_job(args.job) if args.job else default_job()
    overrides = {}
    if args.out is not None:
        overrides["output_dir"] = args.out
    if args.size is not None:
        overrides["size"] = args.size
    if args.seed is not None:
        overrides["seed"] = args.seed
    job = dataclasses.replace(job, **overrides)
    result = run(job, max_elements=args.max_elements, keep_invalid=args.keep_invalid)
    total = sum(result.timings.values())
    log.info("done: %d tetrahedra, %d nodes in %.2f s", len(result.mesh.tets), len(result.mesh.points), total)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run a command: ``argv`` (a list, for tests and callers: the exit code is returned), or the program's
    own arguments (the console script, ``python -m engine.cli``: the process ends here, see :func:`_end`)."""
    code = _run(argv)
    if argv is None:
        _end(code)
    return code


def _end(code: int | None) -> None:
    """End the process with ``code`` once the command is done: the exit handlers run (logging, numba's, weakref
    finalizers such as temporary folders) and the streams are flushed, but the interpreter's teardown of every
    module and object is skipped. That teardown took 0.3-0.5 s after a paper-scale mesh run (numpy, scipy,
    trimesh, numba, pymeshlab and gmsh loaded), and writes nothing. Left to the interpreter while another
    thread runs."""
    import atexit
    import threading

    if threading.active_count() > 1:
        return
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more to write
            pass
    os._exit(int(code or 0))  # a command returning None: 0, as sys.exit(None)


class _LevelFormatter(logging.Formatter):
    """Log lines as they are, a warning's marked 'warning: ' so it stands out of the stages' lines."""

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return f"warning: {text}" if record.levelno == logging.WARNING else text


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_LevelFormatter("%(message)s"))
    logging.basicConfig(level=logging.WARNING if getattr(args, "quiet", False) else logging.INFO, handlers=[handler])
    try:
        return args.run(args)
    except FuzzymeshError as error:
        print(f"fuzzymesh: error: {error.one_line()}", file=sys.stderr)
        return error.exit_code
    except BrokenPipeError:  # output piped into e.g. head, which closed early
        sys.stdout = open(os.devnull, "w")
        return 0
    except KeyboardInterrupt:
        print("fuzzymesh: interrupted", file=sys.stderr)
        return 130
    except MemoryError as error:  # the estimate passed the guard but the machine ran out: a limit, not a fault
        limit = LimitError(
            f"out of memory ({error or 'an allocation failed'}): the mesh needs more memory than this machine has",
            fix="use larger sizes, or a smaller --max-elements so that such jobs are refused before the work",
        )
        print(f"fuzzymesh: error: {limit.one_line()}", file=sys.stderr)
        return limit.exit_code
    except Exception as error:  # an internal fault, not the user's: one line unless --debug
        if args.debug:
            raise
        print(
            f"fuzzymesh: internal error: {error.__class__.__name__}: {error} (run with --debug for details)",
            file=sys.stderr,
        )
        return 3


if __name__ == "__main__":
    sys.exit(main())
