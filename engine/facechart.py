"""A CAD face's own parameters as the chart its surface triangulation is made in (engine/meshing/surface.py).

:class:`FaceChart` maps points of a face to chart coordinates and back through the face's parametrisation
(:class:`engine.cad.Parametrized`, from the :class:`engine.cad.CadModel` the face belongs to): conformal where
the parametrisation is a surface of revolution's, polar round a smooth pole, else arc length sheared to the
face's mean metric; refused (None) where no fair chart exists, and the face is then cut into charts of its facets.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .fitting import seam

if TYPE_CHECKING:
    from .cad import CadModel, Parametrized

CHART_STRETCH = 1.3  # a CAD face's own parameters chart its triangulation where they stretch one direction at most
CHART_SPREAD = 4.0  # this x the other and their scale varies at most this x over the face (else: its facets, LSCM),
CONFORMAL_SPREAD = 16.0  # ... or this x where the chart is conformal (sizes enter it divided by its scale)
CHART_KNOTS = 257  # per parameter, the table that makes a surface of revolution's parameters conformal
SEPARABLE = 1e-3  # ... a parametrisation whose lines cross at right angles and whose speeds vary along one parameter
WINDOW_MARGIN = 0.05  # x the period: a periodic parameter unwrapped round its face's middle is charted this far beyond
POLE = 1e-6  # x its largest: a parameter's speed this small at one end of the other's range is a pole (a dome's top)
SMOOTH_POLE = 0.02  # a pole is smooth (polar chart) where the circles round it are 2 pi times their radius within this


@dataclass(frozen=True)
class FaceChart:
    """A CAD face's own parameters (u, v) as the chart its surface triangulation is made in
    (engine/meshing/surface.py): ``uv(points)`` (k, 2) for points on or near the face, ``lift(uv)`` (k, 3) the
    face's points, ``scale(uv)`` (k,) lengths on the face per length in the chart. Each chart coordinate is a
    table of its parameter: the arc length along the parameter's line through the face's median point (a
    spline's uneven knots evened out; the two then sheared, ``shear``, so that the face's mean metric is the
    chart's: a twisted loft's lines crossing at a slant), or, where the parametrisation is a surface of
    revolution's (its lines at right angles, both speeds functions of one parameter: cones, tori, spheres,
    revolved splines), the
    conformal (Mercator) coordinate along that parameter, so that a Delaunay triangulation in the chart is one
    on the face. A periodic parameter is the chart's first coordinate and ``turn`` its period there (a face
    that may go round: a cone's, a periodic loft's), else ``turn`` is None. A surface of revolution's face that
    reaches its axis at one end (a pole: a dome, a ball, a knob's top, a rounded corner's sphere) is charted
    polar (``polar``: the chart's angle per unit of the first parameter), the conformal coordinate as the log
    of the radius (the stereographic map of a sphere), so the pole is one point of the chart. Built by
    :meth:`of`, which refuses (None) a face periodic both ways (a torus), with poles at both ends (a whole
    sphere) or whose chart would stretch one direction more than CHART_STRETCH x the other or vary its scale
    more than CHART_SPREAD x over the face (CONFORMAL_SPREAD x for a conformal chart: a cone's apex, a skewed
    spline)."""

    model: CadModel
    tag: int
    order: tuple  # (i, j): the chart's first coordinate comes from the face's parameter i, its second from j
    tables: tuple  # per chart coordinate, (parameter values, chart values): monotone, interpolated linearly
    sign: float  # -1.0: the chart mirrored, so that it is oriented as seen from outside
    turn: float | None
    polar: float | None = None
    shear: np.ndarray | None = None  # (2, 2) upper triangular: an arc-length chart's coordinates times it (rows)
    middle: tuple = (np.nan, np.nan)  # per chart coordinate, the value its periodic parameter is unwrapped round
    period: np.ndarray | None = None  # per chart coordinate, its parameter's period (range)

    @classmethod
    def of(cls, model: CadModel, tag: int, vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray):
        """The chart of (part of) CAD face ``tag`` tessellated by ``vertices`` (n, 3) and ``triangles`` (t, 3) with
        outward unit ``normals`` (t, 3), or None where the face's parameters do not make a fair chart. A periodic
        parameter that the triangles do not go round (half a torus) is unwrapped round the middle of their
        range (``middle``) and charted as a bounded one."""
        with model.current() as gm:
            face = model.parametrized(gm, 2, tag)
            vertex_at = face.parameters(gm, vertices)
            middle = _window(face, vertex_at, triangles)
            periodic = face.periodic & np.isnan(middle)
            if periodic.all():
                return None
            vertex_at = _unwrapped(vertex_at, middle, face.period)
            centre_at = _unwrapped(face.parameters(gm, vertices[triangles].mean(axis=1)), middle, face.period)
            margin = WINDOW_MARGIN * face.period
            bounds = (
                np.where(np.isnan(middle), face.low, vertex_at.min(axis=0) - margin),
                np.where(np.isnan(middle), face.high, vertex_at.max(axis=0) + margin),
            )
            for order in ((1, 0), (0, 1)) if periodic[1] else ((0, 1), (1, 0)):
                at = vertex_at[:, order]
                low, high = bounds[0][list(order)], bounds[1][list(order)]
                lines = []
                for k in range(2):  # the speeds along each parameter's line through the face's median point
                    line = np.tile(np.median(at, axis=0), (CHART_KNOTS, 1))
                    line[:, k] = np.linspace(low[k], high[k], CHART_KNOTS)
                    lines.append((line[:, k], np.linalg.norm(_derivative(gm, tag, order, line), axis=2)))
                derivative = _derivative(gm, tag, order, at)
                if not np.isfinite(derivative).all():
                    return None
                layout = _chart_tables(at, derivative, lines, low, high, bool(periodic[order[0]]))
                if layout is None or layout[1] is None or layout[2] == 1:
                    break  # a polar chart's angle is its first coordinate: else the other order
            centre_derivative = _derivative(gm, tag, order, centre_at[:, order])
        if layout is None or (layout[1] is not None and layout[2] != 1):
            return None
        tables, polar, _ = layout
        facing = np.einsum("kd,kd->k", np.cross(centre_derivative[:, 0], centre_derivative[:, 1]), normals)
        sign = 1.0 if (facing > 0).sum() >= (facing < 0).sum() else -1.0
        if (sign * facing > 0).mean() < 0.99:
            return None
        slopes = _slopes(tables, polar, at)
        away = (slopes > POLE * slopes.max(axis=0)).all(axis=1)  # not at the pole itself
        jacobian = derivative[away] / slopes[away][:, :, None] * np.array([sign, 1.0])[None, :, None]
        shear = None
        if layout[2] is None:  # an arc-length chart: sheared so that the face's mean metric is the chart's
            shear = np.linalg.cholesky(np.einsum("kid,kjd->ij", jacobian, jacobian) / len(jacobian)).T
            jacobian = np.einsum("ij,kjd->kid", np.linalg.inv(shear.T), jacobian)
        sigma = _singular_values(jacobian)
        if (sigma[:, 0] <= 0).any() or (sigma[:, 1] / sigma[:, 0]).max() > CHART_STRETCH:
            return None
        if sigma.max() / sigma.min() > (CHART_SPREAD if layout[2] is None else CONFORMAL_SPREAD):
            return None
        if polar is not None:  # the angle and the radius turn the other way round than (u, v) where the radius
            sign *= 1.0 if tables[1][1][0] > tables[1][1][-1] else -1.0  # grows with v
        period = float(tables[0][1][-1] - tables[0][1][0])
        turn = period * (1.0 if shear is None else shear[0, 0]) if periodic[order[0]] and polar is None else None
        return cls(
            model, tag, order, tables, sign, turn, polar, shear, tuple(middle[list(order)]), face.period[list(order)]
        )

    def uv(self, points: np.ndarray) -> np.ndarray:
        """(k, 2) chart coordinates of the closest points of the face to ``points`` (k, 3)."""
        with self.model.current() as gm:
            at = self.model.parametrized(gm, 2, self.tag).parameters(gm, np.asarray(points, float))
        at = _unwrapped(at[:, list(self.order)], np.array(self.middle), self.period)
        first, second = (np.interp(at[:, k], *self.tables[k]) for k in range(2))
        if self.polar is not None:
            return second[:, None] * np.column_stack([np.cos(self.sign * first), np.sin(self.sign * first)])
        chart = np.column_stack([self.sign * first, second])
        return chart if self.shear is None else chart @ self.shear.T

    def lift(self, uv: np.ndarray) -> np.ndarray:
        """(k, 3) the face's points at chart coordinates ``uv`` (k, 2) (a periodic coordinate taken into its
        period, the other clamped to the face's parameter range)."""
        at = self._parameters(uv)
        with self.model.current() as gm:
            return np.reshape(gm.getValue(2, self.tag, at[:, np.argsort(self.order)].ravel()), (-1, 3))

    def scale(self, uv: np.ndarray) -> np.ndarray:
        """(k,) lengths on the face per length in the chart at ``uv`` (k, 2): the geometric mean of the two
        directions' (they differ by CHART_STRETCH at most; a polar chart's by its radial direction, which
        holds at the pole too)."""
        at = self._parameters(uv)
        with self.model.current() as gm:
            derivative = _derivative(gm, self.tag, self.order, at)
        slopes = _slopes(self.tables, self.polar, at)
        if self.polar is not None:
            return np.linalg.norm(derivative[:, 1], axis=1) / np.maximum(slopes[:, 1], 1e-300)
        jacobian = derivative / slopes[:, :, None] * np.array([self.sign, 1.0])[None, :, None]
        if self.shear is not None:
            jacobian = np.einsum("ij,kjd->kid", np.linalg.inv(self.shear.T), jacobian)
        return np.sqrt(_singular_values(jacobian).prod(axis=1))

    def _parameters(self, uv: np.ndarray) -> np.ndarray:
        """(k, 2) the face's parameters, in chart order, at chart coordinates ``uv`` (k, 2)."""
        uv = np.asarray(uv, float)
        (knots0, values0), (knots1, values1) = self.tables
        if self.polar is not None:
            middle = (values0[0] + values0[-1]) / 2  # the angle taken round the face's middle one
            first = middle + np.angle(np.exp(1j * (self.sign * np.arctan2(uv[:, 1], uv[:, 0]) - middle)))
            second = np.hypot(uv[:, 0], uv[:, 1])
        else:
            chart = uv if self.shear is None else uv @ np.linalg.inv(self.shear).T
            first, second = self.sign * chart[:, 0], chart[:, 1]
            if self.turn is not None:
                first = values0[0] + np.mod(first - values0[0], values0[-1] - values0[0])
        return np.column_stack([_inverse(first, knots0, values0), _inverse(second, knots1, values1)])


def _window(face: Parametrized, at: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(2,) per parameter of ``face``, the middle of the range the ``triangles`` (t, 3) over vertices with parameters
    ``at`` (n, 2) cover where the parameter is periodic and they do not go round (no triangle crosses a seam in
    the widest gap between them), else NaN."""
    middle = np.full(2, np.nan)
    for k in np.flatnonzero(face.periodic):
        angle, goes_round = seam(2 * np.pi * (at[:, k] - face.low[k]) / face.period[k], triangles)
        if not goes_round:
            middle[k] = face.low[k] + face.period[k] * np.mod(angle + np.pi, 2 * np.pi) / (2 * np.pi)
    return middle


def _unwrapped(at: np.ndarray, middle: np.ndarray, period: np.ndarray) -> np.ndarray:
    """``at`` (k, 2) with each parameter that has a ``middle`` (not NaN) taken within half a ``period`` of it."""
    centre = np.where(np.isnan(middle), 0.0, middle)
    return np.where(np.isnan(middle), at, centre + np.mod(at - centre + period / 2, period) - period / 2)


def _inverse(values: np.ndarray, knots: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The parameters at which the monotone ``table`` (over ``knots``) takes ``values``."""
    return np.interp(values, table, knots) if table[-1] >= table[0] else np.interp(values, table[::-1], knots[::-1])


def _derivative(gm, tag: int, order: tuple, at: np.ndarray) -> np.ndarray:
    """(k, 2, 3) CAD face ``tag``'s derivatives along its parameters at ``at`` (k, 2), both in chart ``order``."""
    face_order = np.ascontiguousarray(at[:, np.argsort(order)])
    return np.reshape(gm.getDerivative(2, tag, face_order.ravel()), (-1, 2, 3))[:, list(order)]


def _chart_tables(at, derivative, lines, low, high, periodic: bool):
    """(tables, polar, k) of :class:`FaceChart` for the face whose parameters ``at`` (n, 2) have derivatives
    ``derivative`` (n, 2, 3); ``lines``: per parameter (values (m,), speeds (m, 2)) along its line through the
    face; ``periodic``: the first parameter is. Where both speeds are functions of parameter k alone within
    SEPARABLE (and the lines cross at right angles): conformal along k, polar where the other parameter's speed
    vanishes at one end of k's range (a pole; ``polar`` the angle per unit of the other parameter); else each
    coordinate the arc length along its own line (k None). None: a pole at both ends, or a speed that vanishes
    on a face that is no surface of revolution."""
    speed = np.linalg.norm(derivative, axis=2)
    crossing = np.abs(np.einsum("kd,kd->k", derivative[:, 0], derivative[:, 1])) / np.maximum(
        speed.prod(axis=1), 1e-300
    )
    for k, (values, along) in enumerate(lines):
        other = 1 - k
        pole = along[[0, -1], other] <= POLE * along[:, other].max()
        inner = slice(1 if pole[0] else 0, len(values) - 1 if pole[1] else len(values))
        away = speed[:, other] > POLE * along[:, other].max()
        predicted = np.column_stack([np.interp(at[away, k], values[inner], along[inner, j]) for j in range(2)])
        if (
            crossing[away].max(initial=0) > SEPARABLE
            or (np.abs(predicted - speed[away]) > SEPARABLE * speed[away]).any()
        ):
            continue
        if pole.all() or (along[inner] <= 0).any():
            return None
        ratio = along[inner, k] / along[inner, other]
        tables = [None, None]
        if pole.any():
            span = high[other] - low[other]
            angle = 2 * np.pi / span if periodic and other == 0 else 1.0  # radians per unit of the other parameter
            if angle * span > 2 * np.pi * (1 + 1e-9):
                return None
            near = 1 if pole[0] else len(values) - 2  # the knot next to the pole: a smooth pole's circles there
            from_pole = abs(values[near] - values[near - 1 if pole[0] else near + 1]) * along[near, k]  # are 2 pi
            if abs(along[near, other] / (angle * from_pole) - 1) > SMOOTH_POLE:  # times as long as their distance
                return None  # from the pole (a cone's apex: sin of its half-angle times)
            log = angle * _integral(values[inner], ratio) * (1.0 if pole[0] else -1.0)
            middle = np.median(at[:, k])
            radius = float(np.interp(middle, values, along[:, other])) / angle  # chart lengths as the face's there
            rho = radius * np.exp(log - np.interp(middle, values[inner], log))
            rho = np.concatenate([[0.0], rho]) if pole[0] else np.concatenate([rho, [0.0]])
            tables[k] = (values, rho)
            tables[other] = (np.array([low[other], high[other]]), angle * np.array([low[other], high[other]]))
            return tuple(tables), angle, k
        reference = float(np.median(speed[:, other]))
        tables[k] = (values, reference * _integral(values, ratio))
        tables[other] = (np.array([low[other], high[other]]), reference * np.array([low[other], high[other]]))
        return tuple(tables), None, k
    if any((along <= 0).any() for _, along in lines):
        return None
    return tuple((values, _integral(values, along[:, k])) for k, (values, along) in enumerate(lines)), None, None


def _integral(values: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The running integral (trapezoids) of ``rate`` over ``values`` (m,), from 0."""
    return np.concatenate([[0.0], np.cumsum(np.diff(values) * (rate[1:] + rate[:-1]) / 2)])


def _slopes(tables: tuple, polar: float | None, at: np.ndarray) -> np.ndarray:
    """(k, 2) the chart's lengths per unit of each parameter at ``at`` (k, 2): each table's rate of change (a
    polar chart's angle times its radius there)."""
    slopes = []
    for k, (values, mapped) in enumerate(tables):
        rate = np.abs(np.diff(mapped) / np.diff(values))
        slopes.append(rate[np.clip(np.searchsorted(values, at[:, k]) - 1, 0, len(rate) - 1)])
    slopes = np.column_stack(slopes)
    if polar is not None:
        slopes[:, 0] *= np.interp(at[:, 1], *tables[1])
    return slopes


def _singular_values(jacobian: np.ndarray) -> np.ndarray:
    """(k, 2) ascending singular values of ``jacobian`` (k, 2, 3)."""
    gram = np.einsum("kid,kjd->kij", jacobian, jacobian)
    return np.sqrt(np.clip(np.linalg.eigvalsh(gram), 0.0, None))
