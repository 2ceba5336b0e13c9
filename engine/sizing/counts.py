"""The element-count estimate of a sizing field (nodes and tetrahedra a packing of it should have, fitted to
the bubble packings), the run's peak memory it implies, and the guard that refuses a job before packing when
it would need too many elements or more memory than the machine has."""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np
import trimesh

from ..errors import LimitError

TETS_PER_NODE = 5.5  # tetrahedra per node of a well-spaced Delaunay mesh
MAX_ELEMENTS = 20_000_000  # the guard's default limit on the tetrahedra (the memory is checked apart)
GRADED = 1e-6  # a size this much below the raw size of the pattern that wins there is set by the gradation
NODES_PER_H3 = 1.43  # nodes per h^3 of volume of a mesh whose mean edge is h (fitted, see estimate_counts)
NODES_PER_H2 = 0.32  # extra nodes per h^2 of surface (fitted, see estimate_counts)
NODES_PER_H = 1.15  # nodes per h along a feature curve: 1 / the bubble diameter (0.87 h), see estimate_counts
BOUNDARY_NODES_PER_H2 = 1.25  # boundary nodes per h^2 of surface (measured 1.21-1.27: junction, heat sink, plate)
PEAK_BASE_BYTES = 0.36e9  # the run's peak memory: interpreter, libraries, input (see ExpectedCounts.peak_bytes)
PEAK_BYTES_PER_NODE = 3000.0  # per interior node: packing, Delaunay, improvement, quality, output
PEAK_BYTES_PER_BOUNDARY_NODE = 4700.0  # per boundary node: surface packing and triangulation on top
PEAK_BYTES_PER_TET_PATTERN = 24.0  # per tetrahedron and placed pattern: the audit's memberships and sizes
PEAK_BYTES_PER_QUADRATIC_TET = 450.0  # per tetrahedron of a 10-node mesh: mid-edge nodes, curving, output


class ExpectedCounts(NamedTuple):
    """What a packing of a sizing field should come to (:func:`estimate_counts`), and the peak memory of the run
    that meshes it."""

    nodes: float
    boundary_nodes: float  # of ``nodes``, on the solid's surface
    tets: float
    patterns: int  # placed patterns, each audited at every element

    def peak_bytes(self, order: int = 1) -> float:
        """The expected peak resident memory (bytes) of the run, files of element ``order`` written:
        PEAK_BASE_BYTES + PEAK_BYTES_PER_NODE per interior node + PEAK_BYTES_PER_BOUNDARY_NODE per boundary node
        + PEAK_BYTES_PER_TET_PATTERN per tetrahedron and placed pattern (+ PEAK_BYTES_PER_QUADRATIC_TET per
        tetrahedron at order 2). Fitted to full runs (VmHWM): the junction at 1.5M, 4.4M and 10.2M tets, a heat
        sink's fins, a 2 mm plate, a flange under static-stress (13 patterns), 1-15 % above the measured peaks."""
        interior = max(self.nodes - self.boundary_nodes, 0.0)
        return (
            PEAK_BASE_BYTES
            + PEAK_BYTES_PER_NODE * interior
            + PEAK_BYTES_PER_BOUNDARY_NODE * self.boundary_nodes
            + PEAK_BYTES_PER_TET_PATTERN * self.tets * self.patterns
            + (PEAK_BYTES_PER_QUADRATIC_TET * self.tets if order == 2 else 0.0)
        )


def estimate_counts(geometry, sizing, features=None, samples: int = 1 << 16, seed: int = 0) -> ExpectedCounts:
    """Expected nodes (all, and on the boundary) and tetrahedra of a mesh of the sizing field: h is the mean edge
    length (docs/rules.md section 4), which the bubble packer meets with bubbles of diameter 0.87 h (its
    ``diameter`` setting).

    nodes = NODES_PER_H3 * integral of h^-3 over the volume + NODES_PER_H2 * integral
    of h^-2 over the surface + NODES_PER_H * integral of h^-1 along the feature curves + corners;
    boundary nodes = BOUNDARY_NODES_PER_H2 * the same surface integral.
    The volume integral samples one random point in each cell of a grid of about
    ``samples`` cells over the bounding box (stratified, seeded: far less variance than
    as many independent points); the surface integral ``samples // 4`` area-weighted points.
    The constants were fitted to the bubble packings of the built-in shapes (bench/size_calibration.py's cases)
    (cylinder, plate, plate_with_hole, junction, l_bracket, hollow sphere octant, each at two sizes; 880
    to 17,400 nodes): packings hold 0.945 to 1.038 of the estimate. Bubbles of diameter d = 0.87 h
    pack the volume at about 0.94 / d^3 = 1.43 / h^3, the surface layer adds 0.32 / h^2, a curve
    1 / d = 1.15 / h. TETS_PER_NODE is the large meshes' ratio (5.5 at 1M tetrahedra; 3.7 to 5.3 on
    the small meshes above, where more nodes lie on the surface): an upper bound for the guard.
    """
    rng = np.random.default_rng(seed)
    points = stratified_points(*geometry.bounds, samples, rng)
    inside = geometry.contains(points)
    volume_density = float(np.mean(sizing(points[inside]) ** -3.0)) if inside.any() else sizing.h_min**-3.0
    on_surface, _ = trimesh.sample.sample_surface(geometry.mesh, samples // 4, seed=seed)
    surface = geometry.area * float(np.mean(sizing(on_surface) ** -2.0))
    nodes = NODES_PER_H3 * geometry.volume * volume_density + NODES_PER_H2 * surface
    if features is not None:
        for curve in features.curves:
            if curve.on_surface:
                s = np.linspace(0.0, curve.length, 200)
                nodes += NODES_PER_H * curve.length * float(np.mean(1.0 / sizing(curve.point_at(s))))
        nodes += len(features.corners)
    return ExpectedCounts(nodes, BOUNDARY_NODES_PER_H2 * surface, nodes * TETS_PER_NODE, len(sizing.placed))


def stratified_points(lo: np.ndarray, hi: np.ndarray, count: int, rng) -> np.ndarray:
    """One uniform random point in each cell of a grid of about ``count`` near-cubic cells over [lo, hi]."""
    extent = np.maximum(hi - lo, 1e-300)
    cell = float(np.cbrt(np.prod(extent) / count))
    shape = np.maximum(1, np.round(extent / cell)).astype(int)
    index = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1).reshape(-1, 3)
    return lo + (index + rng.random(index.shape)) * (extent / shape)


def available_memory() -> tuple[float, float]:
    """(available, total) bytes of physical memory of this machine now: Linux's MemAvailable (what can be had
    without swapping), else the free pages; inf where the platform does not say. An outside test's job expected
    at 14 GB ran 11 minutes on a 23 GB machine where another user held half of it."""
    try:
        total = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return math.inf, math.inf
    try:
        with open("/proc/meminfo") as meminfo:
            fields = dict(line.split(":", 1) for line in meminfo)
        return float(fields["MemAvailable"].split()[0]) * 1024, total
    except (OSError, KeyError, ValueError):
        try:
            return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")), total
        except (ValueError, OSError, AttributeError):
            return total, total


def pattern_shares(sizing, samples: int = 1 << 15, seed: int = 0) -> dict[str, float]:
    """{pattern: share} of the expected elements in the volume (its h^-3, sampled as :func:`estimate_counts`
    does) where a placement of the pattern wins the dominance and so sets the size, largest first: the audit's
    'sized by', before packing."""
    evaluation, density = _sampled(sizing, samples, seed)
    if evaluation is None:
        return {}
    won = evaluation.winner >= 0
    names = np.array([placed.placement.pattern for placed in sizing.placed] or [""])
    pattern, owner = np.unique(names[evaluation.winner[won]], return_inverse=True)
    shares = np.bincount(owner, density[won], minlength=len(pattern)) / density.sum()
    return {str(pattern[k]): float(shares[k]) for k in np.argsort(-shares, kind="stable")}


def _sampled(sizing, samples: int, seed: int):
    """(the sizing's evaluation, h^-3) at stratified points inside the solid, or (None, None) where none is."""
    geometry = sizing.geometry
    points = stratified_points(*geometry.bounds, samples, np.random.default_rng(seed))
    points = points[geometry.contains(points)]
    if len(points) == 0:
        return None, None
    evaluation = sizing.evaluate(points)
    return evaluation, evaluation.h**-3.0


def check_element_limit(sizing, max_elements: float | None = None, order: int = 1) -> float:
    """The expected tetrahedra; refuse (one line) when the sizes would need more than ``max_elements`` of them,
    or, when that is None, more than MAX_ELEMENTS or more memory at the peak of a run writing elements of
    ``order`` than this machine has available now (:meth:`ExpectedCounts.peak_bytes`, :func:`available_memory`)."""
    expected = sizing.expected_counts
    tets, peak, (memory, total) = expected.tets, expected.peak_bytes(order), available_memory()
    limit = MAX_ELEMENTS if max_elements is None else max_elements
    if not math.isfinite(tets) or tets > limit:
        over = f"limit {limit:.3g}"
    elif max_elements is None and peak > memory:
        over = (
            f"and about {peak / 2**30:.3g} GiB of memory at the run's peak: this machine has {memory / 2**30:.1f} GiB "
            f"available now (of {total / 2**30:.1f} GiB)"
        )
    else:
        return tets
    placed, share, graded = densest_pattern(sizing)
    if placed is None:
        where = ""
    elif graded:
        where = (
            f"; {100 * share:.0f} % of them lie where the size grows (by the gradation, "
            f"{sizing.gradation:g}) from the {sizing.h_min:.4g} that '{placed.id}' (pattern "
            f"'{placed.placement.pattern}', placed by {placed.placement.origin}) sets"
        )
    else:
        where = (
            f"; {100 * share:.0f} % of them lie where '{placed.id}' (pattern '{placed.placement.pattern}', "
            f"placed by {placed.placement.origin}) sets the size"
        )
    raise LimitError(
        f"the sizes would need about {tets:.3g} tetrahedra ({over}); the smallest size is {sizing.h_min:.4g}{where}",
        fix=_coarser(placed) + "use larger sizes, or raise the limit with --max-elements",
    )


def _coarser(placed) -> str:
    """How to ask ``placed`` (a placed pattern, or None) for fewer elements, as the start of a fix."""
    if placed is None:
        return ""
    origin, pattern = placed.placement.origin, placed.placement.pattern
    if origin == "sizing defaults":
        return f"place '{pattern}' in the job with coarser parameters (it then replaces the sizing defaults'), "
    if origin.startswith("recipe"):
        return f"give '{placed.id}' coarser parameters (copy the {origin}'s placements into the job instead), "
    return f"give '{placed.id}' coarser parameters, "


def densest_pattern(sizing, samples: int = 1 << 15, seed: int = 0):
    """(placed pattern, share, graded): the pattern that sets the size where most of the expected elements are
    (the volume's h^-3, sampled as :func:`estimate_counts` does), with their share. Where the gradation from
    smaller sizes nearby sets it (below the raw size of the pattern that wins there), that is the pattern of the
    smallest size, and ``graded`` is True: a 0.1 mm slit's 0.05 grown at 1.3 sets most of a part's elements,
    where the base pattern wins. (None, 0, False) where no point is inside."""
    geometry = sizing.geometry
    evaluation, density = _sampled(sizing, samples, seed)
    if evaluation is None:
        return None, 0.0, False
    graded = evaluation.h < evaluation.raw * (1.0 - GRADED)
    owner = np.where(graded | (evaluation.winner < 0), -1, evaluation.winner)
    shares = np.bincount(owner + 1, density, minlength=len(sizing.placed) + 1) / density.sum()
    top = int(np.argmax(shares))
    if top > 0:
        return sizing.placed[top - 1], float(shares[top]), False
    surface = geometry.mesh.triangles_center  # the smallest sizes are a feature's: on the surface
    raw = sizing.evaluate(surface[np.random.default_rng(seed).permutation(len(surface))[:samples]])
    winner = int(raw.winner[np.argmin(np.where(raw.winner >= 0, raw.raw, np.inf))])
    if winner < 0 or not graded.any():
        return None, 0.0, False
    return sizing.placed[winner], float(shares[0]), True
