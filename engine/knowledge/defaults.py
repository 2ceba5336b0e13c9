"""The sizing defaults file (``kind: sizing``): gradation, base pattern, always-placed patterns and the
acceptance gate's tolerances."""

from __future__ import annotations

from ..acceptance import Tolerances
from ..schema import LIST, MAPPING, NUMBER, STRING, Field, in_range

SIZING_FILE = {
    "kind": Field(STRING, required=True),
    "doc": Field(STRING, default=""),
    "gradation": Field(
        NUMBER,
        default=1.3,
        check=in_range(1.01, 3.0),
        doc="the largest ratio of sizes one element apart: h(y) <= h(x) + (g - 1)|x - y|",
    ),
    "base_pattern": Field(STRING, default="uniform-domain", doc="the pattern placed when a job places none"),
    "always_place": Field(
        LIST, default=[], doc="placements added to every job, unless it places the same pattern itself"
    ),
    "acceptance": Field(
        MAPPING,
        default=None,
        doc="the acceptance gate's tolerances (engine/acceptance.py)",
        fields={
            "min_dihedral": Field(
                NUMBER,
                default=Tolerances.min_dihedral,
                check=in_range(0.0, 60.0),
                doc="smallest dihedral angle of any tetrahedron, degrees",
            ),
            "cusp_min_dihedral": Field(
                NUMBER,
                default=Tolerances.cusp_min_dihedral,
                check=in_range(0.0, 60.0),
                doc="smallest dihedral angle of a tetrahedron next to a cusp (two feature curves leaving a corner "
                "under 10 degrees apart) or across a face narrower than a quarter of it, where the geometry forces "
                "flat elements, degrees",
            ),
            "volume": Field(
                NUMBER,
                default=Tolerances.volume,
                check=in_range(0.0, 1.0),
                doc="largest |mesh volume / input volume - 1|",
            ),
            "hausdorff": Field(
                NUMBER,
                default=Tolerances.hausdorff,
                check=in_range(0.0, 100.0),
                doc="largest distance between the mesh boundary and the input surface, each way, "
                "over the target size h there",
            ),
            "quadratic_jacobian": Field(
                NUMBER,
                default=Tolerances.quadratic_jacobian,
                check=in_range(0.0, 1.0),
                doc="smallest scaled Jacobian of a 10-node tetrahedron",
            ),
            "hex_jacobian": Field(
                NUMBER,
                default=Tolerances.hex_jacobian,
                check=in_range(0.0, 1.0),
                doc="smallest scaled corner Jacobian of a hexahedron, prism or pyramid of a hex-dominant mesh",
            ),
        },
    ),
}
