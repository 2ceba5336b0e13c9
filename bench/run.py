"""fuzzymesh against Gmsh (3-D Delaunay and HXT) on the junction, side by side in one run.

    python bench/run.py [--quick] [--repeats N] [--cases ...] [--tiers ...] [--scale S] [--out DIR]

For the junction with the cylinder at the plate centre and near its edge, at sizes giving about 10k, 100k
and 1M tetrahedra, and 10M with the cylinder near the edge only (bench/cases.py), every mesher meshes the same
solid with the same h(x), each run in its own process, ``--repeats`` times (medians). Writes
``results.json`` (every raw figure and the machine), ``results.md`` (the tables, the ratios fuzzymesh / Gmsh,
seconds and MB per 1k tets) and ``scaling.png`` into ``--out`` (default: this folder), with the paper-scale
end-to-end time (bench/paper_scale.py) and issue 20's targets checked (bench/results.py). A full run takes
about 45 minutes on the 2-core reference machine, most of it the 10M row. ``--quick``: the 10k and 100k rows
of both junctions, one run each (under 3 minutes). ``--scale S`` replaces the tiers by one row with every
size x S (S = 1: the junction-edge recipe at H = 1.8, about 1.5M tets).
Needs the bench extra: ``pip install ".[bench]"`` (Gmsh with OpenCASCADE and HXT, matplotlib).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import logging
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
QUICK = {"tiers": ["10k", "100k"], "repeats": 1}


def missing_requirement() -> str | None:
    """What this machine lacks to run the benchmark, in one line; None when nothing."""
    for module in ("gmsh", "matplotlib", "resource"):
        if importlib.util.find_spec(module) is None:
            if module == "resource":
                return "the benchmark measures memory with the 'resource' module, which this platform lacks (Unix only)"
            return f"'{module}' is not installed; install the bench extra: pip install \".[bench]\""
    import gmsh

    gmsh.initialize(readConfigFiles=False)
    try:
        options = set(gmsh.option.getString("General.BuildOptions").split())
    finally:
        gmsh.finalize()
    lacking = [name for name in ("OpenCASCADE", "Hxt") if name not in options]
    if lacking:
        return (
            f"this Gmsh ({gmsh.__version__}) is built without {' and '.join(lacking)}; "
            "install the pip wheel: pip install gmsh"
        )
    return None


def parse(argv=None) -> argparse.Namespace:
    from cases import OFFSETS, TIERS
    from harness import MESHERS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the 10k and 100k rows, one run each (< 3 min)")
    parser.add_argument("--repeats", type=int, help="runs per mesher and row (default 3, --quick 1)")
    parser.add_argument("--cases", nargs="+", choices=list(OFFSETS), help="default: both")
    parser.add_argument("--tiers", nargs="+", choices=list(TIERS), help="default: all")
    parser.add_argument("--scale", type=float, help="one row with every size x SCALE instead of the tiers")
    parser.add_argument("--meshers", nargs="+", choices=MESHERS, default=list(MESHERS))
    parser.add_argument("--out", type=Path, default=HERE, help="folder for results.json, results.md, scaling.png")
    parser.add_argument("--note", default="", help="a line shown at the top of results.md")
    parser.add_argument(
        "--no-warm-up",
        dest="warm_up",
        action="store_false",
        help="skip the small run that makes sure numba's kernels are compiled",
    )
    parser.add_argument("--no-plot", dest="plot", action="store_false")
    parser.add_argument(
        "--no-paper-scale",
        dest="paper_scale",
        action="store_false",
        help="skip the paper-scale end-to-end timing (bench/paper_scale.py, the Fig. 9 example)",
    )
    args = parser.parse_args(argv)
    if args.repeats is not None and args.repeats < 1:
        parser.error("--repeats must be at least 1")
    if args.scale is not None and not args.scale > 0:
        parser.error("--scale must be > 0")
    defaults = {"cases": list(OFFSETS), "tiers": list(TIERS), "repeats": 3, **(QUICK if args.quick else {})}
    for key, value in defaults.items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    return args


def paper_scale(repeats: int, folder: Path) -> dict:
    """bench/paper_scale.py in its own process: the Fig. 9 example end to end, medians of ``repeats`` runs."""
    from harness import OMP_WAIT_POLICY

    out = folder / "paper-scale.json"
    logging.getLogger("bench").info("paper scale (examples/connected-uniform-nonuniform.yaml) x %d", repeats)
    subprocess.run(
        [sys.executable, str(HERE / "paper_scale.py"), "--repeats", str(repeats), "--json", str(out)],
        check=True,
        capture_output=True,
        env={**os.environ, "OMP_WAIT_POLICY": OMP_WAIT_POLICY},
    )
    return json.loads(out.read_text())


def main(argv=None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    logging.getLogger("fuzzymesh").setLevel(logging.WARNING)
    problem = missing_requirement()
    if problem:
        print(f"bench: error: {problem}", file=sys.stderr)
        return 2
    args = parse(argv)
    from cases import TIER_CASES, TIERS
    from harness import machine_info, measure_case, warm_up
    from results import markdown, plot_scaling, scaling, targets

    begin = time.perf_counter()
    rows = [(f"x{args.scale:g}", args.scale)] if args.scale else [(tier, TIERS[tier]) for tier in args.tiers]
    command = "python bench/run.py" + "".join(f" {shlex.quote(a)}" for a in (sys.argv[1:] if argv is None else argv))
    results = {
        "format": "fuzzymesh-bench/1",
        "machine": machine_info(),
        "settings": {
            "command": command,
            "repeats": args.repeats,
            "cases": args.cases,
            "rows": [name for name, _ in rows],
            "meshers": args.meshers,
            "note": args.note,
        },
        "rows": [],
    }
    with tempfile.TemporaryDirectory(prefix="fuzzymesh-bench-") as folder:
        if args.warm_up and "fuzzymesh" in args.meshers:
            results["warm_up_seconds"] = warm_up(Path(folder))
        for case in args.cases:
            for tier, scale in rows:
                if case not in TIER_CASES.get(tier, (case,)):
                    continue
                results["rows"].append(measure_case(case, tier, scale, args.meshers, args.repeats, Path(folder)))
        if args.paper_scale and "fuzzymesh" in args.meshers:
            results["paper_scale"] = paper_scale(args.repeats, Path(folder))
    results["seconds"] = time.perf_counter() - begin
    results["machine"]["load_average_end"] = list(os.getloadavg())
    results["scaling"] = scaling(results)
    results["targets"] = targets(results)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.plot:
        plot_scaling(results, args.out / "scaling.png")
        results["plot"] = "scaling.png"
    (args.out / "results.json").write_text(json.dumps(results, indent=1))
    (args.out / "results.md").write_text(markdown(results))
    print(
        f"wrote {args.out / 'results.md'}, {args.out / 'results.json'}"
        + (f", {args.out / 'scaling.png'}" if args.plot else "")
        + f" ({results['seconds']:.0f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
