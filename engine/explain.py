"""Plain-words explanations of the sizing: why a point gets its element size."""

from __future__ import annotations

import numpy as np

from .sizing import GRADED_THRESHOLD, SizingField


def explain_point(sizing: SizingField, point, inside: bool | None = None) -> str:
    """The chain of reasoning for one point, in lines of text."""
    audit = sizing.evaluate(np.asarray(point, dtype=float).reshape(1, 3))
    lines = [
        f"point ({', '.join(f'{c:.6g}' for c in point)})"
        + ("" if inside is None else (" inside the solid" if inside else " OUTSIDE the solid"))
    ]
    lines.append("placed patterns (membership mu, size h each asks for):")
    winner, runner_up = int(audit.winner[0]), int(audit.runner_up[0])
    for k, placed in enumerate(sizing.placed):
        mu, h = audit.mu[0, k], audit.sizes[0, k]
        tag = " <- winner" if k == winner else (" <- runner-up" if k == runner_up else "")
        reach = f"mu = {mu:.4f}, h = {h:.6g}" if mu > 0 else "mu = 0 (out of reach)"
        reach += " (dominance tie: the others' highest mu)" if placed.ties and mu > 0 else ""
        lines.append(f"  {placed.id}: pattern '{placed.pattern}', {reach}{tag}")
        lines.append(
            f"      placed by {placed.placement.origin} at {placed.placement.source}"
            + (f", on {placed.feature}" if placed.feature else "")
            + (f", L = {placed.length:.6g}" if placed.length is not None else "")
        )
    if winner >= 0:
        placed = sizing.placed[winner]
        zone = placed.zones[int(audit.zone[0])]
        lines.append(
            f"winner: {placed.id} (highest mu {audit.mu[0, winner]:.4f}"
            + (
                f" over runner-up {sizing.placed[runner_up].id} with {audit.mu[0, runner_up]:.4f}"
                if runner_up >= 0
                else ", no other pattern reaches here"
            )
            + (
                ", a tie: the smaller h wins"
                if runner_up >= 0 and audit.mu[0, runner_up] == audit.mu[0, winner]
                else ""
            )
            + ")"
        )
        lines.append(
            f"  its zone '{zone.zone.id}' ({zone.zone.law} law, {zone.zone.source}) sets the raw size "
            f"h = {audit.raw[0]:.6g}"
        )
    else:
        lines.append(f"no pattern reaches here: the global size H = {sizing.global_size:.6g} applies")
    h, raw = audit.h[0], audit.raw[0]
    if audit.graded[0]:
        lines.append(
            f"gradation limit g = {sizing.gradation:g} (h(y) <= h(x) + {sizing.gradation - 1:g} |x - y|) "
            f"lowers it by {raw - h:.6g} to {h:.6g}"
        )
    else:
        lines.append(
            f"gradation limit g = {sizing.gradation:g}: not active here"
            + (f" (it lowers it by {raw - h:.3g}, not more than {100 * GRADED_THRESHOLD:g} %)" if h < raw else "")
        )
    lines.append(f"element size h = {h:.6g}")
    return "\n".join(lines)
