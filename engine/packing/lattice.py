"""The ``lattice`` packer: an honest baseline without dynamics, the starting nodes of
:mod:`engine.packing.start` as they are."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import LEVELS, Packing, register_packer
from .start import corner_nodes, curve_nodes, patch_nodes, volume_nodes


@register_packer("lattice")
def pack_lattice(geometry, features, sizing, *, seed: int = 0, knowledge=None) -> Packing:
    rng = np.random.default_rng(seed)
    parts = [corner_nodes(features, sizing)]
    parts.append(curve_nodes(features, sizing, existing=parts[0].points))
    boundary = Packing.concatenate(parts)
    parts.append(patch_nodes(geometry, features, sizing, boundary, rng))
    boundary = Packing.concatenate(parts)
    parts.append(volume_nodes(geometry, sizing, boundary, rng))
    packing = Packing.concatenate(parts)
    return replace(
        packing,
        stats={
            "nodes": len(packing),
            **{f"{name}_nodes": int((packing.level == k).sum()) for k, name in enumerate(LEVELS)},
        },
    )
