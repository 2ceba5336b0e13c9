"""The ``bubble`` packer: the paper's dynamic bubbles with fuzzy population control.

Level by level (corners fixed; then curves, patches, the volume, each with the
lower levels frozen), bubbles of diameter d = c h(x) start near their final
count (curves at equal steps of the integral of 1/h, patches and volume from
density-following samples, as the lattice packer) and move under Shimada's
interbubble force: m s'' + c s' = f, integrated with the classical 4th-order
Runge-Kutta method (forces re-evaluated at every stage), 70 % of critical
damping. Every ``control_interval`` steps the population rules in force
(``knowledge/population.yaml`` or a job's replacement) delete strongly overlapping bubbles and add
bubbles next to open ones; each event is logged with its rule and firing
degree. After the last round a level settles for SETTLE_STEPS more steps,
or less when the largest step falls below TOLERANCE x h. The settling is
short on purpose: the rounds leave the bubbles near equilibrium, and without
population control a longer run lets the attractive tail of the force pull
bubbles together (the share at 0.85-1.15 r0 went from 99.6 % after 8 settling
steps to 97.7 % after 42 on the junction).

c is the ``diameter`` packer setting of the population rule file (knowledge/population.yaml): h is the
target mean edge length of the elements (docs/rules.md section 4), and the Delaunay edges between bubbles
at the stable distance are longer than that distance (the nearest neighbour is the shortest edge), so
bubbles are packed at c < 1 times h (bench/size_calibration.py). The nodes' ``radius`` stays h / 2, the
target size; the packer's own statistics (``nearest_over_r0``) measure against the bubble diameter.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse

from ..errors import KnowledgeError
from ..features import leaving_angles
from ..progress import progress
from ..sampling import point_tree
from ..sizing import NODES_PER_H3
from . import CURVE, EVENT, LEVELS, PATCH, VOLUME, Packing, register_packer
from .constraints import CurveConstraint, PatchConstraint, VolumeConstraint
from .forces import deletions, forces, morton_order, neighbour_lists, proximity, update_neighbours
from .start import corner_nodes, curve_nodes, patch_nodes, volume_nodes

log = logging.getLogger(__name__)

MASS = 1.0
STIFFNESS = 1.0  # k0, per unit of r0
DAMPING_RATIO = 0.7  # of critical damping 2 sqrt(m k0)
TIME_STEP = 0.5  # in units of sqrt(m / k0): |lambda| dt <= 1.7 for a bubble pressed by all
# its neighbours at the stiffest spacing, inside RK4's stability bound 2.78
SETTLE_STEPS = 8  # steps after the last population-control round
TOLERANCE = 2e-3  # converged when every bubble moves less than this x h per step
NEIGHBOURS = {CURVE: 4, PATCH: 12, VOLUME: 16}
SKIN = 0.3  # a bubble that moved this x h since the last build is stale
STALE_SHARE = 0.05  # rebuild the neighbour lists once this share of bubbles is stale
REBUILD_EVERY = 50  # ... or after this many steps
INSIDE_CHECK_EVERY = 5  # volume bubbles outside the solid go back to their last checked place
LEAVING_TOGETHER = 30.0  # degrees: curves leaving a corner closer than this do not push each other's bubbles
END_GAP = 0.1  # a curve bubble nearer than this x its diameter to an end of its curve (a corner node) is dropped
SHELL_ANGLE = 5.0  # degrees: first bubbles of curves leaving a corner together go to one distance if seen this apart


@dataclass(kw_only=True)
class PackingRun:
    """What the levels of one packing share and add to: the solid, the bubble diameters (c h), the population
    rules in force, the seeded generator, the population-control events (EVENT blocks, one per round and
    action), the next bubble id, per level its start count, its starting places and its time, and the curve
    bubbles dropped for lying on a corner, and which feature curves share a corner."""

    geometry: object
    bubbles: "_Scaled"
    control: "PopulationControl"
    rng: np.random.Generator
    events: list = field(default_factory=list)
    next_id: int = 0
    initial_counts: dict = field(default_factory=dict)
    starts: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    dropped_at_curve_ends: int = 0
    touching: sparse.csr_matrix | None = None  # (c, c) feature curves sharing a corner

    def new_ids(self, count: int) -> np.ndarray:
        ids = np.arange(self.next_id, self.next_id + count)
        self.next_id += count
        return ids


@dataclass(kw_only=True)
class LevelState:
    """The bubbles of one level while it packs, the frozen bubbles they push against, the level's constraint
    and the packing's shared run: the one object :func:`_relax` and :func:`_control` work on."""

    level: int
    constraint: object
    run: PackingRun
    x: np.ndarray
    entity: np.ndarray
    ids: np.ndarray
    frozen: np.ndarray
    v: np.ndarray = field(init=False)

    def __post_init__(self):
        self.v = np.zeros_like(self.x)


POPULATION = "population"  # the id of the rule file read: its rule bases 'delete' and 'insert', its packer settings
INPUTS = {"delete": "overlap", "insert": "vacancy"}


class PopulationControl:
    """The population rules and packer settings in force: the rule file ``population``, the shipped one or the
    one that replaces it (``overrides: true``, docs/rules.md section 2)."""

    def __init__(self, knowledge):
        for name, variable in INPUTS.items():
            base = knowledge.rulebases[f"{POPULATION}.{name}"]
            if set(base.inputs) != {variable} or "action" not in base.extra:
                raise KnowledgeError(
                    f"rule base '{base.id}' must have the one input '{variable}' and an 'action'",
                    where=base.source,
                    fix="keep the inputs and the action of the shipped "
                    "knowledge/population.yaml; change its terms, rules and thresholds",
                )
            setattr(self, name, base)
        self.settings = knowledge.packer_settings[POPULATION]
        for file_id, source in {b.id.split(".")[0]: b.source for b in knowledge.rulebases.values()}.items():
            if file_id != POPULATION:
                log.warning(
                    "%s: rule file '%s' is not read: the bubble packer reads the rule bases %s.delete and "
                    "%s.insert; to replace them give this file 'id: %s' and 'overrides: true'",
                    source,
                    file_id,
                    POPULATION,
                    POPULATION,
                    POPULATION,
                )

    def decide(self, rule_base, inputs):
        outputs, firing = rule_base.evaluate(inputs)
        action = rule_base.extra["action"]
        q = outputs[action["output"]]
        strongest = np.argmax(firing, axis=1)
        return q, q >= action["threshold"], strongest, firing[np.arange(len(q)), strongest]


@register_packer("bubble")
def pack_bubbles(geometry, features, sizing, *, seed: int = 0, knowledge=None, initial_density: float = 1.0) -> Packing:
    """Pack bubbles level by level; ``initial_density`` scales the starting count (for tests of the rules)."""
    from ..knowledge import load_knowledge

    control = PopulationControl(knowledge or load_knowledge())
    run = PackingRun(
        geometry=geometry,
        bubbles=_Scaled(sizing, control.settings["diameter"]),  # bubble diameters d = c h
        control=control,
        rng=np.random.default_rng(seed),
        touching=_touching_curves(features),
    )
    corners = corner_nodes(features, sizing)
    parts = [replace(corners, ids=run.new_ids(len(corners)))]
    run.starts.append(corners.points)
    constraints = {
        CURVE: CurveConstraint(features),
        PATCH: PatchConstraint(geometry, features),
        VOLUME: VolumeConstraint(geometry),
    }
    for level in (CURVE, PATCH, VOLUME):
        start = time.perf_counter()
        frozen = Packing.concatenate(parts)
        start_nodes = _initial(level, geometry, features, run.bubbles, frozen, run.rng, initial_density)
        run.initial_counts[LEVELS[level]] = len(start_nodes)
        run.starts.append(start_nodes.points)
        state = LevelState(
            level=level,
            constraint=constraints[level],
            run=run,
            x=start_nodes.points,
            entity=start_nodes.entity,
            ids=run.new_ids(len(start_nodes)),
            frozen=frozen.points,
        )
        steps = _relax(state)
        if level == CURVE:  # the projection onto a curve can leave a bubble pushed past its end on the corner
            clear = _clear_of_ends(state.x, state.entity, features, run.bubbles(state.x))
            run.dropped_at_curve_ends = int(np.count_nonzero(~clear))
            state.x, state.entity, state.ids = state.x[clear], state.entity[clear], state.ids[clear]
            state.x = _shells_at_acute_corners(state.x, state.entity, features)
        points = state.x
        parts.append(
            Packing(
                points=points,
                level=np.full(len(points), level),
                entity=state.entity,
                radius=sizing(points) / 2,
                ids=state.ids,
            )
        )
        run.timings[LEVELS[level]] = time.perf_counter() - start
        log.info(
            "packing %s: %d bubbles (started with %d) in %d steps, %.2f s",
            LEVELS[level],
            len(points),
            run.initial_counts[LEVELS[level]],
            steps,
            run.timings[LEVELS[level]],
        )
    packing = Packing.concatenate(parts, events=np.concatenate([np.zeros(0, EVENT)] + run.events).view(np.recarray))
    return replace(packing, stats=_statistics(packing, sizing, run))


def _clear_of_ends(points, entity, features, diameter) -> np.ndarray:
    """(k,) whether each curve bubble lies more than END_GAP x its diameter from both ends of its open curve,
    where corner nodes are (a bubble on a corner would give a chain edge of no length)."""
    clear = np.ones(len(points), bool)
    for key in np.unique(entity):
        curve = features.curves[key]
        if curve.closed:
            continue
        rows = np.flatnonzero(entity == key)
        s, gap = curve.parameter(points[rows]), END_GAP * diameter[rows]
        clear[rows] = (s > gap) & (s < curve.length - gap)
    return clear


def _initial(level, geometry, features, bubbles, frozen, rng, density):
    """Starting bubbles of a level, about ``density`` times the count the sizing field asks for (``bubbles``:
    the bubble diameters, c h). The volume starts at the estimate's NODES_PER_H3 / h^3, that is
    NODES_PER_H3 c^3 per bubble diameter cubed."""
    scaled = _Scaled(bubbles, density ** (-1.0 / {CURVE: 1, PATCH: 2, VOLUME: 3}[level]))
    if level == CURVE:
        return curve_nodes(features, scaled, existing=frozen.points)
    if level == PATCH:
        return patch_nodes(geometry, features, scaled, frozen, rng)
    return volume_nodes(geometry, bubbles, frozen, rng, density=NODES_PER_H3 * bubbles.factor**3 * density)


class _Scaled:
    """A sizing field times a constant: the bubble diameters c h, or a start with more or fewer bubbles."""

    def __init__(self, sizing, factor: float):
        self.sizing, self.factor = sizing, factor
        self.h_min, self.h_max = sizing.h_min * factor, sizing.h_max * factor

    def __call__(self, points):
        return self.sizing(points) * self.factor


def _relax(state: LevelState) -> int:
    """Integrate the level's bubbles to equilibrium with population control; return the step count."""
    constraint, geometry, sizing = state.constraint, state.run.geometry, state.run.bubbles
    settings = state.run.control.settings
    interval, rounds = settings["control_interval"], settings["control_rounds"]
    damping = DAMPING_RATIO * 2.0 * np.sqrt(MASS * STIFFNESS)
    k = NEIGHBOURS[state.level]
    state.frozen = state.frozen[morton_order(state.frozen)]  # neighbours close in memory: fewer cache misses
    step, built = 0, 0
    neighbours, anchor, h = None, None, None  # set at the first step's rebuild
    checked = state.x.copy()
    frame = None
    last_step = interval * rounds + SETTLE_STEPS
    with progress(last_step, f"packing {LEVELS[state.level]}") as bar:
        for step in range(1, last_step + 1):
            n = len(state.x)
            bar.update()
            if n == 0:
                return 0
            if (
                neighbours is None
                or len(neighbours) != n
                or step - built >= REBUILD_EVERY
                or np.count_nonzero(((state.x - anchor) ** 2).sum(axis=1) > (SKIN * h[:n]) ** 2) > STALE_SHARE * n
            ):
                order = morton_order(state.x)
                state.x, state.v, state.entity, state.ids = (
                    state.x[order],
                    state.v[order],
                    state.entity[order],
                    state.ids[order],
                )
                checked, frame = checked[order], None
                everything = np.concatenate([state.x, state.frozen])
                h = sizing(everything)  # bubbles move < SKIN h between rebuilds: their diameters are kept till then
                neighbours, anchor, built = _neighbours(state, k), state.x.copy(), step
            if frame is None or len(frame) != n:
                _, frame = constraint.frame(state.x, state.entity)

            def acceleration(x, v):
                f = STIFFNESS * forces(x, state.frozen, h, neighbours)
                return (constraint.tangential(f, frame) - damping * v) / MASS

            x0, v0 = state.x, state.v
            k1x, k1v = v0, acceleration(x0, v0)
            k2x, k2v = v0 + 0.5 * TIME_STEP * k1v, acceleration(x0 + 0.5 * TIME_STEP * k1x, v0 + 0.5 * TIME_STEP * k1v)
            k3x, k3v = v0 + 0.5 * TIME_STEP * k2v, acceleration(x0 + 0.5 * TIME_STEP * k2x, v0 + 0.5 * TIME_STEP * k2v)
            k4x, k4v = v0 + TIME_STEP * k3v, acceleration(x0 + TIME_STEP * k3x, v0 + TIME_STEP * k3v)
            x1 = x0 + TIME_STEP / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
            v1 = v0 + TIME_STEP / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
            x1, frame = constraint.frame(x1, state.entity)
            v1 = constraint.tangential(v1, frame) if frame is not None else v1
            moved = np.linalg.norm(x1 - x0, axis=1) / h[:n]
            state.x, state.v = x1, v1
            if state.level == VOLUME and step % INSIDE_CHECK_EVERY == 0:
                escaped = ~geometry.contains(state.x)
                state.x[escaped], state.v[escaped] = checked[escaped], 0.0
                checked = state.x.copy()
            changed = False
            if step % interval == 0 and step // interval <= rounds:
                keep = _control(state, step, neighbours)
                changed = keep is not None
                if changed:
                    everything = np.concatenate([state.x, state.frozen])
                    neighbours = (
                        _neighbours(state, k)
                        if state.level == CURVE
                        else update_neighbours(neighbours, keep, everything, len(state.x), k)
                    )
                    fresh = len(state.x) - int(keep.sum())
                    anchor = np.concatenate([anchor[keep], state.x[len(state.x) - fresh :]])
                    h = sizing(everything)
                    frame = None
                    # survivors keep their last verified place; new bubbles were placed inside
                    checked = np.concatenate([checked[keep], state.x[len(state.x) - fresh :]])
            if not changed and step > interval * rounds and moved.max() < TOLERANCE:
                break
    if state.level == VOLUME:
        escaped = ~geometry.contains(state.x)
        state.x[escaped] = checked[escaped]
    return step


def _neighbours(state: LevelState, k: int) -> np.ndarray:
    """The level's neighbour lists (n, k), nearest first (-1 pads): the k nearest bubbles, frozen ones included
    (indices >= n). A curve bubble's list holds only bubbles of its own curve, of the curves that share a corner
    with it and the corners, the k nearest of these among the 3k nearest of all: each curve is packed between
    its corners, as in the paper. Two curves nearer than h that do not meet (a 1 mm chamfer's two edges at h 4.2,
    the close circles of a V-belt groove) pushed each other's bubbles along and the rules deleted them where they
    overlapped, leaving gaps of 4-10 h along both edges, and bubbles pushed onto their own curve's next one;
    flat tetrahedra there. Curves that meet at a corner at an angle still see each other (near the corner their
    bubbles would crowd); curves that leave it together do not (:func:`_touching_curves`)."""
    n = len(state.x)
    everything = np.concatenate([state.x, state.frozen])
    if state.level != CURVE:
        return neighbour_lists(everything, n, k)
    neighbours = neighbour_lists(everything, n, 3 * k)
    other = (neighbours >= 0) & (neighbours < n)
    mine = np.broadcast_to(state.entity[:, None], neighbours.shape)[other]
    theirs = state.entity[neighbours[other]]
    other[other] = ~np.asarray(state.run.touching[mine, theirs]).ravel().astype(bool)  # diagonal: own curve
    neighbours = np.where(other, -1, neighbours)
    nearest_first = np.argsort(neighbours < 0, axis=1, kind="stable")[:, :k]
    return np.take_along_axis(neighbours, nearest_first, axis=1)


def _touching_curves(features) -> sparse.csr_matrix:
    """(c, c) whether two feature curves meet at a corner (an end of an open curve, or the corner a loop starts
    at) at an angle of at least LEAVING_TOGETHER between their first segments, the diagonal included.

    Curves that leave a corner together (a round dying tangentially into a wall: the wall's edge and the round's
    arc) run closer than h near it however their bubbles sit: bubbles that saw each other pushed one of them
    onto the corner (3.5 deg tets); each packed on its own, their first nodes sit h from the corner."""
    curve, end, other, other_end, together = _leaving_together(features)
    apart = ~together
    count = len(features.curves)
    rows = np.concatenate([np.arange(count), curve[apart], other[apart]])
    cols = np.concatenate([np.arange(count), other[apart], curve[apart]])
    return sparse.csr_matrix((np.ones(len(rows), bool), (rows, cols)), shape=(count, count)).astype(bool)


def _leaving_together(features):
    """:func:`engine.features.leaving_angles`'s pairs of curve ends at one corner, and (k,) whether the two
    curves leave the corner closer than LEAVING_TOGETHER between their first segments."""
    curve, end, other, other_end, angle = leaving_angles(features)
    return curve, end, other, other_end, angle <= LEAVING_TOGETHER


def _shells_at_acute_corners(points, entity, features) -> np.ndarray:
    """``points`` (curve bubbles) with the first bubble of each of two curves that leave a corner together at
    one distance from it, the mean of theirs (a concentric shell, as Ruppert's refinement splits the segments
    of a small input angle): packed each on its own, they sat 0.43 and 0.97 h from a 10.8 deg corner and the
    face's triangle there had a 164 deg angle. Not made: a move that would bring a bubble past half the way to
    its neighbour along the curve, and a shell whose two bubbles the corner sees under SHELL_ANGLE (a cusp: two
    nodes 0.02 mm apart at h 0.38, 3.5 deg tets, where packed each on its own they were not)."""
    curve, end, other, other_end, together = _leaving_together(features)
    points = points.copy()
    for a, end_a, b, end_b in zip(curve[together], end[together], other[together], other_end[together]):
        first = [_first_along(points, entity, features.curves[c], c, e) for c, e in ((a, end_a), (b, end_b))]
        if any(f is None for f in first):
            continue
        shell = (first[0][1] + first[1][1]) / 2
        if not all(shell <= (distance + next_distance) / 2 for _, distance, next_distance in first):
            continue
        corner = features.curves[a].points[0 if end_a == 0 else -1]
        moved = [
            features.curves[c].point_at(np.array([shell if e == 0 else features.curves[c].length - shell]))[0]
            for c, e in ((a, end_a), (b, end_b))
        ]
        arms = [(x - corner) / (np.linalg.norm(x - corner) or 1.0) for x in moved]
        if np.degrees(np.arccos(np.clip(arms[0] @ arms[1], -1.0, 1.0))) >= SHELL_ANGLE:
            points[first[0][0]], points[first[1][0]] = moved
    return points


def _first_along(points, entity, curve, key: int, end: int):
    """(row, distance, next distance) along ``curve`` from its start (``end`` 0) or end (1) of its bubble
    nearest that end and of the one after it (inf if none), or None if the curve has no bubble."""
    rows = np.flatnonzero(entity == key)
    if len(rows) == 0:
        return None
    s = curve.parameter(points[rows])
    distance = s if end == 0 else curve.length - s
    order = np.argsort(distance)
    after = distance[order[1]] if len(rows) > 1 else np.inf
    return rows[order[0]], distance[order[0]], after


def _control(state: LevelState, step: int, neighbours: np.ndarray):
    """One round of fuzzy population control at ``step``: the survivor mask of the old bubbles (new ones are
    appended after the survivors), or None if nothing changed; the events go to the run."""
    run = state.run
    control, rng = run.control, run.rng
    n = len(state.x)
    everything = np.concatenate([state.x, state.frozen])
    h = run.bubbles(everything)
    settings = control.settings
    overlap, count = proximity(everything, h, neighbours, n, settings["count_radius"])
    level_name = LEVELS[state.level]
    # deletions: highest q first, never both of an overlapping pair
    q, act, rule, firing = control.decide(control.delete, {"overlap": overlap})
    delete = np.zeros(n, bool)
    if act.any():
        priority = q + 1e-9 * rng.random(n)  # equal q: a seeded random order, not the index order
        delete = deletions(everything, h, neighbours, n, act, priority)
    # insertions next to open bubbles (not next to one being deleted)
    vacancy = settings["expected_neighbours"][level_name] / np.maximum(count, 1)
    qi, act_i, rule_i, firing_i = control.decide(control.insert, {"vacancy": vacancy})
    act_i &= ~delete
    new_x = np.zeros((0, 3))
    sources = np.flatnonzero(act_i)
    if len(sources):
        new_x, sources = _insertion_spots(state, everything, h, neighbours, sources)
    deleted = np.flatnonzero(delete)
    new_ids = run.new_ids(len(new_x))
    run.events.append(
        _events(state.ids[deleted], level_name, step, "delete", control.delete, rule[deleted], firing[deleted])
    )
    run.events.append(_events(new_ids, level_name, step, "insert", control.insert, rule_i[sources], firing_i[sources]))
    if not delete.any() and not len(new_x):
        return None
    keep = ~delete
    state.x = np.concatenate([state.x[keep], new_x])
    state.v = np.concatenate([state.v[keep], np.zeros_like(new_x)])
    state.entity = np.concatenate([state.entity[keep], state.entity[sources]])
    state.ids = np.concatenate([state.ids[keep], new_ids])
    return keep


def _events(bubbles, level_name, step, action, rule_base, rules, firing) -> np.ndarray:
    """EVENT rows: ``bubbles`` acted on by ``action`` at ``step``; ``rules`` index ``rule_base.rules``, cited as
    ``RULE-BASE-ID/RULE-ID``."""
    rows = np.zeros(len(bubbles), EVENT)
    rows["bubble"], rows["level"], rows["iteration"], rows["action"] = bubbles, level_name, step, action
    rows["rule"] = np.array([f"{rule_base.id}/{r.id}" for r in rule_base.rules], dtype=object)[rules]
    rows["firing"] = firing
    return rows


def _insertion_spots(state: LevelState, everything, h, neighbours, sources):
    """A new bubble at distance h on the open side of each source bubble; spots too close to others dropped."""
    constraint, geometry, rng = state.constraint, state.run.geometry, state.run.rng
    x = everything[sources]
    rows = neighbours[sources]
    valid = rows >= 0
    towards = np.where(valid[..., None], everything[np.maximum(rows, 0)] - x[:, None, :], 0.0)
    towards /= np.maximum(np.linalg.norm(towards, axis=2, keepdims=True), 1e-300)
    direction = -towards.sum(axis=1)
    lonely = np.linalg.norm(direction, axis=1) < 1e-9
    direction[lonely] = rng.normal(size=(int(lonely.sum()), 3))
    _, frame = constraint.frame(x, state.entity[sources])
    if frame is not None:
        direction = constraint.tangential(direction, frame)
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    spots = constraint.project(x + h[sources, None] * direction, state.entity[sources])
    ok = np.ones(len(spots), bool)
    if state.level == VOLUME:
        ok &= geometry.contains(spots)
    gap, _ = point_tree(everything).query(spots)
    ok &= gap > 0.5 * h[sources]
    # two new bubbles may not crowd each other either: keep the first of each close group
    spots, sources = spots[ok], sources[ok]
    if len(spots) > 1:
        pairs = point_tree(spots).query_pairs(0.5 * float(h[sources].min()), output_type="ndarray")
        drop = np.zeros(len(spots), bool)
        drop[np.maximum(pairs[:, 0], pairs[:, 1])] = True
        spots, sources = spots[~drop], sources[~drop]
    return spots, sources


def _statistics(packing: Packing, sizing, run: PackingRun) -> dict:
    """Counts (against the sizing field's estimate), nearest-neighbour distance / r0 (r0 from the run's bubble
    diameters) of the packing and of its starting places (each level's start beside the settled lower levels),
    events, timings."""
    expected_nodes = sizing.expected_counts.nodes
    bubbles, initial_points, events = run.bubbles, np.concatenate(run.starts), packing.events
    return {
        "nodes": len(packing),
        "expected_nodes": expected_nodes,
        **{f"{name}_nodes": int((packing.level == k).sum()) for k, name in enumerate(LEVELS)},
        "initial": run.initial_counts,
        "diameter": bubbles.factor,
        "nearest_over_r0": nearest_over_r0(packing.points, bubbles(packing.points)),
        "initial_nearest_over_r0": nearest_over_r0(initial_points, bubbles(initial_points)),
        "deleted": int(np.count_nonzero(events.action == "delete")),
        "inserted": int(np.count_nonzero(events.action == "insert")),
        "dropped_at_curve_ends": run.dropped_at_curve_ends,
        "seconds": run.timings,
    }


def nearest_over_r0(points: np.ndarray, h: np.ndarray) -> dict:
    """Distance to the nearest other bubble over the stable distance r0 = (h_i + h_j) / 2: median,
    share within [0.85, 1.15], 1st and 99th percentiles."""
    distance, index = point_tree(points).query(points, k=2, workers=-1)
    ratio = distance[:, 1] / (0.5 * (h + h[index[:, 1]]))
    return {
        "median": float(np.median(ratio)),
        "within_0.85_1.15": float(np.mean((ratio >= 0.85) & (ratio <= 1.15))),
        "p01": float(np.percentile(ratio, 1)),
        "p99": float(np.percentile(ratio, 99)),
    }
