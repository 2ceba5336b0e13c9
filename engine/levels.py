"""Where a node lives: the one list of node levels, shared by packers, meshers, the FE model and the audit.

A packer places nodes level by level (corners, then curves, patches, the volume); a mesher may add Steiner
nodes. Arrays store the level as its integer (int8); names are for logs, files and the audit legend.
"""

from __future__ import annotations

from enum import IntEnum


class Level(IntEnum):
    CORNER = 0
    CURVE = 1
    PATCH = 2
    VOLUME = 3
    STEINER = 4  # added by a mesher, not by the packer


CORNER, CURVE, PATCH, VOLUME, STEINER = Level
NODE_LEVELS = tuple(level.name.lower() for level in Level)  # ("corner", ..., "steiner")
LEVELS = NODE_LEVELS[:STEINER]  # the packer's levels
