"""A pattern's numbers: its zones' expressions evaluated at given parameters, L and H, each checked (finite,
positive sizes, ordered trapezoid), with located errors; also at sample L and H, before any geometry."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..errors import KnowledgeError
from ..expr import Expression, ExpressionError
from .common import _err

if TYPE_CHECKING:
    from .patterns import Pattern, Zone
    from .placements import Placement

# where the knowledge is checked without a solid: every pattern at these global sizes H, and lengths L of
# these multiples of H, with the gaps of its roles 0 (so ligament zones are on)
SAMPLE_H = (1.0, 10.0, 100.0)
SAMPLE_L = (0.1, 1.0, 10.0)


def check_values(pattern: Pattern, parameters: dict, placement: "Placement | None" = None) -> None:
    """Evaluate every zone of ``pattern`` with ``parameters`` at the sample L and H (L the placement's
    ``scale`` if it gives one), so a broken size law is found before any geometry is read."""
    lengths = (
        [None]
        if pattern.scale == "none"
        else [placement.scale]
        if placement is not None and placement.scale is not None
        else None
    )
    for H in SAMPLE_H:
        for L in lengths or [q * H for q in SAMPLE_L]:
            env = {
                **parameters,
                "H": H,
                **({"L": L} if L is not None else {}),
                **{f"gap_{role}": 0.0 for role in pattern.roles},
            }
            for zone in pattern.zones:
                zone_values(pattern, zone, env, placement, " at a sample L and H")


def _value_error(pattern, zone, what, exprs, problem, fix, env, placement, on) -> KnowledgeError:
    """What is wrong with a zone's value, at the expression's file:line or, when placed, at the placement."""
    names = sorted(set().union(*(e.names for e in exprs)), key=lambda n: (n in ("H", "L"), n))
    at = ", ".join(f"{n} = {env[n]:g}" for n in names)
    shown = f"({exprs[0].text})" if len(exprs) == 1 else f"[{', '.join(e.text for e in exprs)}]"
    text = f"pattern '{pattern.name}', zone '{zone.id}': {what} {shown} {problem}" + (f" at {at}" if at else "")
    if placement is None:
        return _err(f"{text}, with the default parameters{on}", exprs[0].where, fix)
    given = [n for n in names if n in placement.parameters]
    return _err(
        f"{text}, as placed here{on} (the {what} is at {exprs[0].where})",
        placement.where(f"parameters.{given[0]}") if given else placement.source,
        fix,
    )


def expression_value(
    pattern: Pattern,
    zone: Zone,
    expr: Expression,
    what: str,
    env: dict,
    placement: "Placement | None" = None,
    on: str = "",
    finite: bool = True,
) -> float:
    """``expr`` at ``env``: a finite number (``finite=False``: not NaN), else a located error."""
    try:
        number = expr(env)
    except ExpressionError as exc:
        problem = str(exc)
    else:
        if math.isfinite(number) or not finite and not math.isnan(number):
            return number
        problem = "is not a number" if math.isnan(number) else "overflows (beyond 1.8e308)"
    raise _value_error(
        pattern,
        zone,
        what,
        [expr],
        problem,
        "change the expression or the parameters so it is a finite number for every L and H",
        env,
        placement,
        on,
    )


def zone_values(
    pattern: Pattern, zone: Zone, env: dict, placement: "Placement | None" = None, on: str = ""
) -> dict | None:
    """The zone's numbers at ``env`` (``near``, ``far``, ``over``, ``exponent``, ``height``, ``trapezoid``),
    None where its ``active_if`` is off. Each must be finite, the sizes, ``over`` and ``exponent`` > 0, the
    height in [0, 1] and the trapezoid ordered; else an error naming the expression's file:line, the values
    used and, when given, the placement (``on`` says more: the feature it is bound to, or that L and H are
    samples)."""

    def value(expr, what, finite=True):
        return expression_value(pattern, zone, expr, what, env, placement, on, finite)

    def fail(what, exprs, problem, fix):
        return _value_error(pattern, zone, what, exprs, problem, fix, env, placement, on)

    height = "the membership height" if zone.trapezoid else "the membership"
    near = value(zone.near, "'near'")
    if zone.active_if is not None and not value(zone.active_if, "'active_if'", finite=False) > 0:
        return None
    numbers = {
        "near": near,
        "far": value(zone.far, "'far'") if zone.far else near,
        "over": value(zone.over, "'over'") if zone.over else 1.0,
        "exponent": value(zone.exponent, "'exponent'") if zone.exponent else 1.0,
        "height": value(zone.height, height),
        "trapezoid": None,
    }
    for key in ("near", "far", "over", "exponent"):
        expr = getattr(zone, key)
        if expr is not None and numbers[key] <= 0:
            raise fail(f"'{key}'", [expr], f"is {numbers[key]:g}, not > 0", "make it positive for every L and H")
    if not 0 <= numbers["height"] <= 1:
        raise fail(
            height, [zone.height], f"is {numbers['height']:g}, not in [0, 1]", "give a membership between 0 and 1"
        )
    if zone.trapezoid is not None:
        points = tuple(value(e, f"trapezoid point {i + 1}") for i, e in enumerate(zone.trapezoid))
        if not all(points[i] <= points[i + 1] for i in range(3)):
            raise fail(
                "the trapezoid",
                list(zone.trapezoid),
                f"is [{', '.join(f'{x:g}' for x in points)}], not ordered a <= b <= c <= d",
                "order its points for every L and H",
            )
        numbers["trapezoid"] = points
    return numbers
