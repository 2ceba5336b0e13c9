"""The ``fuzzymesh`` command line: a thin shell over :mod:`engine`.

Every user error is printed as one line ``fuzzymesh: error: ...`` with exit
code 2 (1 for lint findings); no traceback unless ``--debug``.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

from .errors import FuzzymeshError

log = logging.getLogger("fuzzymesh")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


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
    mesh.add_argument("--max-elements", type=_positive_float, default=None,
                      help="refuse jobs expected to exceed this many tetrahedra (default 2e7)")
    mesh.add_argument("-q", "--quiet", action="store_true", help="print warnings and errors only")
    mesh.set_defaults(run=_cmd_mesh)
    return parser


def _cmd_mesh(args) -> int:
    from .job import default_job, load_job
    from .pipeline import DEFAULT_MAX_ELEMENTS, run

    job = load_job(args.job) if args.job else default_job()
    overrides = {}
    if args.out is not None:
        overrides["output_dir"] = args.out
    if args.size is not None:
        overrides["size"] = args.size
    if args.seed is not None:
        overrides["seed"] = args.seed
    job = dataclasses.replace(job, **overrides)
    result = run(job, max_elements=args.max_elements or DEFAULT_MAX_ELEMENTS)
    total = sum(result.timings.values())
    log.info("done: %d tetrahedra, %d nodes in %.2f s", len(result.mesh.tets), len(result.mesh.points), total)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING if getattr(args, "quiet", False) else logging.INFO,
                        format="%(message)s", stream=sys.stderr)
    try:
        return args.run(args)
    except FuzzymeshError as error:
        print(f"fuzzymesh: error: {error.one_line()}", file=sys.stderr)
        return error.exit_code
    except KeyboardInterrupt:
        print("fuzzymesh: interrupted", file=sys.stderr)
        return 130
    except Exception as error:  # an internal fault, not the user's: one line unless --debug
        if args.debug:
            raise
        print(f"fuzzymesh: internal error: {error.__class__.__name__}: {error} (run with --debug for details)",
              file=sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
