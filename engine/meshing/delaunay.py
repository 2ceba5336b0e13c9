"""The ``delaunay`` mesher (default): boundary-conforming Delaunay of the bubbles, then quality improvement.

1. The surface nodes are triangulated patch by patch (``surface.py``): a
   closed, outward triangulation whose nodes are bubbles on the surface and
   whose edges include every feature curve.
2. All nodes are tetrahedralized by Gmsh's constrained Delaunay kernel (HXT)
   with those triangles as constrained faces; Steiner points it adds are
   kept, tagged ``steiner``, and counted.
3. IN/OUT: regions of tets between the boundary triangles are classified by
   the side of the triangles they touch (exact, see ``tetra.inside_by_boundary``);
   a flat tet inside is unfolded (``tetra.unfold_flat``), or, where its sides
   are no pyramids, swapped out (``improve.swap_bad_faces``), else dropped.
4. Quality improvement (``improve.py``): boundary nodes move only in the
   last relocation pass (sliding on the surface and put back onto it); flat
   caps get a node beneath them (tagged ``steiner``); what is still under
   the floor is repaired by peels, collapses and swaps, then Gmsh's
   optimiser and the relocation run once more, and the repairs again.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..levels import STEINER
from ..mesh import TetMesh, signed_volumes
from ..packing import CURVE, PATCH, VOLUME
from . import register_mesher
from .improve import (
    FLOOR,
    TARGET,
    collapse_bad_nodes,
    fill_flat_caps,
    gmsh_optimize,
    mend_below_target,
    min_dihedrals,
    peel_boundary_slivers,
    quality_below,
    relocate,
    swap_bad_faces,
)
from .surface import DEVIATION, check_closed, triangulate_boundary
from .tetra import canonical, compact, flat_tets, inside_by_boundary, orient, tetrahedralize, unfold_flat

log = logging.getLogger(__name__)

RESTORE_ROUNDS = 4  # rounds of putting back slid nodes whose tets turned non-positive
SURFACE_TOLERANCE = 0.05  # x h: how far from the input surface a peel or collapse may put boundary faces
REPAIR_ROUNDS = 4  # rounds of peels, collapses and swaps of what is still under the floor
FLAT_QUALITY = 1e-6  # quality under which a tet is flat for the swaps that take out what unfold_flat left


@register_mesher("delaunay")
def mesh_delaunay(packing, geometry, features, *, seed: int = 0, prescribed=None) -> TetMesh:
    """``prescribed``: (triangles (k, 3) into the packing's nodes, patch (k,)) that replace the triangulation of
    the patches they name (an interface an assembly's other body has meshed, engine/assembly.py); their nodes
    stay where they are and their triangles stay faces of the mesh."""
    seconds = {}
    packing_in = packing
    start = time.perf_counter()
    surface = triangulate_boundary(packing, geometry, features)
    packing = surface.nodes  # with the curve nodes added where chain edges were split
    keep = np.ones(len(packing), bool)
    keep[surface.dropped] = False
    held = np.zeros(len(packing), bool)  # the prescribed triangles' nodes
    if prescribed is not None:
        surface, keep, held = _prescribe(surface, keep, prescribed)
    # a surface node no boundary triangle uses lies on the surface, on or beside a triangle: Gmsh's constrained
    # Delaunay fails to recover a triangle with a node on it (two of the filleted flange's 680k nodes)
    unused = np.ones(len(packing), bool)
    unused[surface.triangles] = False
    stray = np.flatnonzero(keep & unused & (packing.level != VOLUME))
    keep[stray] = False
    nodes = np.flatnonzero(keep)
    new_index = np.cumsum(keep) - 1
    points = packing.points[nodes]
    boundary = new_index[surface.triangles]
    seconds["surface"] = time.perf_counter() - start

    start = time.perf_counter()
    tets, steiner = tetrahedralize(points, boundary)
    points = np.vstack([points, steiner])
    level = np.concatenate([packing.level[nodes], np.full(len(steiner), STEINER)]).astype(np.int8)
    entity = np.concatenate([packing.entity[nodes], np.full(len(steiner), -1)]).astype(np.int64)
    bubble = np.concatenate(
        [packing.ids[nodes] if packing.ids is not None else np.full(len(nodes), -1), np.full(len(steiner), -1)]
    ).astype(np.int64)
    hull_tets = len(tets)
    tets = unfold_flat(points, tets[inside_by_boundary(points, tets, boundary)])
    tets = canonical(orient(points, tets)[0])  # Gmsh's order varies from run to run
    if flat_tets(points, tets).any():  # one unfold_flat could not unfold: swapped out before anything else,
        tets = canonical(orient(points, swap_bad_faces(points, tets, FLAT_QUALITY)[0])[0])
        tets = tets[~flat_tets(points, tets)]  # else dropped (a pillow block's, no swap taking it, as before)
    seconds["connect"] = time.perf_counter() - start

    start = time.perf_counter()
    before = _worst(points, tets)
    fixed = (level != VOLUME) & (level != STEINER)
    points, tets = gmsh_optimize(points, tets, fixed)
    slide = _slide_directions(points, level, entity, geometry, features)
    held = np.concatenate([held[nodes], np.zeros(len(steiner), bool)])
    slide[0][held] = slide[1][held] = np.nan
    surface_node = np.nan_to_num(slide[1]).any(axis=1)  # patch and smooth-cut nodes: they slide on the surface
    points, moves = relocate(points, tets, slide[0], seed)
    if (quality_below(points, tets, TARGET)).any():  # last pass: curved-patch nodes slide too
        unslid = points
        points, more = relocate(points, tets, slide[1], seed)
        moves += more
        moved = np.any(points != unslid, axis=1)
        slid = np.flatnonzero(moved & surface_node)
        points[slid], _, face = geometry.closest_point(points[slid])  # back onto the surface
        node_h = 2 * np.concatenate([packing.radius[nodes], np.zeros(len(steiner))])
        points = _on_own_patches(
            points, unslid, slid, features.face_patch[face], level, entity, tets, boundary, geometry, node_h
        )
        points = _positive(points, unslid, tets, np.flatnonzero(moved))
    points, tets, capped = fill_flat_caps(points, tets, boundary, TARGET)
    if capped:  # nodes beneath flat caps: the mesher's own, free like Steiner nodes
        level, entity, bubble, fixed, held, surface_node = (
            np.concatenate([values, np.full(capped, new, values.dtype)])
            for values, new in ((level, STEINER), (entity, -1), (bubble, -1), (fixed, 0), (held, 0), (surface_node, 0))
        )
        slide = tuple(np.vstack([directions, np.zeros((capped, 3))]) for directions in slide)
        points, more = relocate(points, tets, slide[0], seed)
        moves += more
    h = 2 * np.concatenate([packing.radius[nodes], np.zeros(len(points) - len(nodes))])  # Steiner nodes stay inside
    repair = _Repair(
        surface_node & ~held,
        (surface_node | (level == VOLUME) | (level == STEINER)) & ~held,
        _on_surface(geometry),
        SURFACE_TOLERANCE * h,
    )
    # a prescribed triangle is a patch of its own while the repairs run: no peel flips an edge between two of them
    patch = surface.patch.copy()
    own = np.flatnonzero(held[boundary].all(axis=1) & np.isin(patch, prescribed[1] if prescribed else []))
    own_patch = patch[own]
    patch[own] = len(features.patches) + np.arange(len(own))
    tets, boundary, patch = repair(points, tets, boundary, patch)
    if quality_below(points, tets, FLOOR).any():
        # relocation and the repairs change the tets Gmsh's swaps saw: they may now take what is left
        points, tets = gmsh_optimize(points, tets, fixed)
        points, more = relocate(points, tets, slide[0], seed)
        moves += more
        tets, boundary, patch = repair(points, tets, boundary, patch)
    if quality_below(points, tets, TARGET).any():
        points, tets, swapped, more = mend_below_target(points, tets, slide[0], seed)
        repair.swapped += swapped
        moves += more
    peeled, collapsed = repair.peeled, repair.collapsed
    seconds["improve"] = time.perf_counter() - start

    if len(own):
        alone = patch >= len(features.patches)
        patch[alone] = own_patch[patch[alone] - len(features.patches)]
    points, tets, level, entity, bubble, renumber = compact(points, tets, level, entity, bubble)
    boundary = renumber[boundary]
    stats = {
        "boundary_triangles": len(boundary),
        "crowded_surface_nodes_dropped": len(surface.dropped),
        "unused_surface_nodes_dropped": len(stray),
        "curve_nodes_added": int((packing.level == CURVE).sum() - (packing_in.level == CURVE).sum()),
        "patch_nodes_added": int((packing.level == PATCH).sum() - (packing_in.level == PATCH).sum()),
        "steiner_points": len(steiner),
        "hull_tets": hull_tets,
        "outside_tets_dropped": hull_tets - len(tets),
        "nodes_added_under_flat_caps": capped,
        "unused_nodes_dropped": int(len(nodes) + len(steiner) + capped - len(points)),
        "min_dihedral_before_improvement": before,
        "relocated_nodes": moves,
        "boundary_slivers_removed": peeled,
        "nodes_collapsed": collapsed,
        "faces_swapped": repair.swapped,
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
    }
    log.debug(
        "delaunay: %d boundary triangles (%.2f s), %d tets, %d Steiner points (%.2f s), improvement from "
        "min dihedral %.2f deg, %d nodes relocated (%.2f s)",
        len(boundary),
        seconds["surface"],
        len(tets),
        len(steiner),
        seconds["connect"],
        before,
        moves,
        seconds["improve"],
    )
    order = np.argsort(patch, kind="stable")
    return TetMesh(
        points=points,
        tets=tets,
        node_level=level,
        node_entity=entity,
        stats=stats,
        boundary=boundary[order],
        boundary_patch=patch[order],
        node_bubble=bubble,
    )


def _prescribe(surface, keep, prescribed):
    """The surface triangulation with the patches of the ``prescribed`` (triangles, patch) replaced by them; the
    nodes to keep (the packing's nodes on those patches that no prescribed triangle uses left out); which nodes
    are held (the prescribed triangles'). A curve node the triangulation added on a prescribed triangle's edge
    (a split chain edge) would leave the surface open there: refused."""
    triangles, patch = (np.asarray(a, np.int64) for a in prescribed)
    nodes = surface.nodes
    held = np.zeros(len(nodes), bool)
    held[triangles.ravel()] = True
    on_patch = (nodes.level == PATCH) & np.isin(nodes.entity, patch)
    keep = keep & ~(on_patch & ~held)
    keep[held] = True
    mine = np.isin(surface.patch, patch)
    replaced = np.vstack([surface.triangles[~mine], triangles])
    try:
        check_closed(replaced)
    except RuntimeError as error:
        raise RuntimeError(f"the prescribed interface does not fit the rest of the surface ({error})") from None
    surface = type(surface)(
        replaced, np.concatenate([surface.patch[~mine], patch]), np.setdiff1d(surface.dropped, triangles), nodes
    )
    return surface, keep, held


def _slide_directions(points, level, entity, geometry, features):
    """Per node: NaN (fixed), 0 (free: volume and Steiner nodes) or the normal of the plane a surface node
    slides in; two arrays: (nodes of planar patches only; nodes of every patch and of every smooth cut, a
    curved one's in the plane of the input face the node is on)."""
    slide = np.full((len(level), 3), np.nan)
    slide[(level == VOLUME) | (level == STEINER)] = 0.0
    on_patch = np.flatnonzero(level == PATCH)
    planar = np.array([p.planar for p in features.patches], dtype=bool)[entity[on_patch]]
    smooth = np.array([not c.sharp for c in features.curves] + [False], dtype=bool)
    on_cut = np.flatnonzero((level == CURVE) & smooth[np.where(level == CURVE, entity, -1)])
    sliding = np.concatenate([on_patch, on_cut])
    _, _, face = geometry.closest_point(points[sliding])
    every = slide.copy()
    every[sliding] = geometry.mesh.face_normals[face]
    slide[on_patch[planar]] = every[on_patch[planar]]
    return slide, every


class _Repair:
    """Peels, collapses and swaps (improve.py) of what is still under the floor, in rounds; counts them.

    Peels and collapses move boundary faces: the new ones must face outward as the input surface does
    and be no farther from it than the old ones or than ``tolerance`` (per node)."""

    def __init__(self, removable, collapsible, on_surface, tolerance):
        self.removable, self.collapsible = removable, collapsible
        self.on_surface, self.tolerance = on_surface, tolerance
        self.peeled = self.collapsed = self.swapped = 0

    def __call__(self, points, tets, boundary, patch):
        for _ in range(REPAIR_ROUNDS):
            tets, boundary, patch, peeled = peel_boundary_slivers(
                points, tets, boundary, patch, FLOOR, self.removable, self.on_surface, self.tolerance
            )
            tets, boundary, patch, collapsed = collapse_bad_nodes(
                points, tets, boundary, patch, FLOOR, self.collapsible, self.on_surface, self.tolerance
            )
            tets, swapped = swap_bad_faces(points, tets, FLOOR)
            self.peeled += peeled
            self.collapsed += collapsed
            self.swapped += swapped
            if not peeled + collapsed + swapped:
                break
        return tets, boundary, patch


def _on_surface(geometry):
    """points -> (their distances to the input surface, its outward unit normals at the closest points)."""

    def at(points):
        _, distance, face = geometry.closest_point(points)
        return distance, geometry.mesh.face_normals[face]

    return at


def _on_own_patches(points, before, slid, landed, level, entity, tets, boundary, geometry, h) -> np.ndarray:
    """``points`` with the ``slid`` patch nodes put back where ``before`` has them when the slide, once put back
    onto the surface (on the patch ``landed``, per slid node), took them off their own patch (past a feature
    curve), left their tets' smallest dihedral angle lower than before the slide (all of them; node by node,
    with the other nodes slid, the gear below kept 9.5 deg), or left one of their ``boundary`` triangles'
    centroids further from the input surface than before and than surface.DEVIATION x the smallest ``h`` (n,)
    of its nodes, the chord the surface triangulation itself allows: relocation weighed the tets with the node
    off the surface. A gear's flank node slid 1.1 h along the flank past its foot onto the root (a 7.6 deg
    tet), another to 0.07 h from the foot's curve (5.3 deg); beside a centre hole's cone tip two nodes slid
    so that a triangle spanned the tip 0.28 h off the surface (the mesh refused)."""
    on_patch = level[slid] == PATCH
    patch_node = slid[on_patch]
    astray = patch_node[landed[on_patch] != entity[patch_node]]
    star = tets[np.isin(tets, patch_node).any(axis=1)]
    star_before, star_after = np.full(len(points), np.inf), np.full(len(points), np.inf)
    np.minimum.at(star_before, star, min_dihedrals(before, star)[:, None])
    np.minimum.at(star_after, star, min_dihedrals(points, star)[:, None])
    poorer = patch_node[star_after[patch_node] < star_before[patch_node]]
    faces = boundary[np.isin(boundary, patch_node).any(axis=1)]
    off_before = geometry.closest_point(before[faces].mean(axis=1))[1]
    off_after = geometry.closest_point(points[faces].mean(axis=1))[1]
    strays = (off_after > off_before) & (off_after > DEVIATION * h[faces].min(axis=1))
    off_surface = np.intersect1d(faces[strays], patch_node)
    back = np.union1d(np.union1d(astray, poorer), off_surface)
    points[back] = before[back]
    return points


def _positive(points, before, tets, moved) -> np.ndarray:
    """``points`` with the ``moved`` nodes of every tet that is not positive put back where ``before`` has
    them (all positive there): a node slid and put back onto a curved surface can fold a flat tet, and
    the pass's other moves around it were made for the node off the surface."""
    for _ in range(RESTORE_ROUNDS):
        back = np.intersect1d(tets[signed_volumes(points, tets) <= 0], moved)
        if len(back) == 0:
            break
        points[back] = before[back]
    return points


def _worst(points, tets) -> float:
    return float(min_dihedrals(points, tets).min()) if len(tets) else 0.0
