"""One tetrahedron's shape measures (numba, per tet): the one kernel behind both the quality report
(``all_metrics``, for ``engine/quality.py``: what the log, the report and the acceptance gate call min
dihedral, radius ratio...) and the optimiser's aim (``shape_quality``, q = min(radius ratio, min dihedral /
70.53 deg), for ``engine/meshing/improve.py``), both on ``shape``: a "min dihedral 20 deg" aimed at and
reported is the same number.

Conventions (../shared/reference/NOTES.md): radius ratio rho = 3 r_in / R_circ (1 for the regular
tetrahedron), mean ratio eta = 12 (3|V|)^(2/3) / sum of squared edge lengths, dihedral angles in degrees
(70.53 for the regular tetrahedron), aspect ratio = longest edge / (2 sqrt(6) r_in) (1 for the regular
tetrahedron). Volumes are signed: positive for positively oriented tetrahedra; the shape measures of a
negative one are its mirror image's.

A leaf module (numba only), imported by both. numba's cache does not see a change here from the callers'
cached kernels (it keys them by their own file): after editing this file, delete the ``__pycache__/*.nbi``
of quality.py and meshing/improve.py (or touch them).
"""

from __future__ import annotations

import numpy as np

from ._numba import numba

REGULAR_DIHEDRAL = 70.528779365509308  # degrees, arccos(1 / 3)


@numba.njit(inline="always", error_model="numpy")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@numba.njit(cache=True, error_model="numpy")
def shape(a, b, c, d):
    """(6 x signed volume, the largest and the smallest cosine of the dihedral angles, radius ratio, inradius)
    of the tet (a, b, c, d) (points (3,)). The cosines are those between the faces' outward normals'
    opposites (a face of no area counts 90 deg); the radius ratio is 0 for a flat tet (no volume, or a face of
    no area), the inradius 0 for one of no volume."""
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    wx, wy, wz = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    vw = _cross(vx, vy, vz, wx, wy, wz)
    six_volume = ux * vw[0] + uy * vw[1] + uz * vw[2]
    size = abs(six_volume)
    # outward normals (area x 2) of the faces opposite a, b, c, d (all inward for a negative tet: the
    # cosines are the same)
    n0 = _cross(d[0] - b[0], d[1] - b[1], d[2] - b[2], c[0] - b[0], c[1] - b[1], c[2] - b[2])
    n1 = vw
    n2 = _cross(wx, wy, wz, ux, uy, uz)
    n3 = _cross(ux, uy, uz, vx, vy, vz)
    normals = (n0, n1, n2, n3)
    lengths = (
        np.sqrt(n0[0] ** 2 + n0[1] ** 2 + n0[2] ** 2),
        np.sqrt(n1[0] ** 2 + n1[1] ** 2 + n1[2] ** 2),
        np.sqrt(n2[0] ** 2 + n2[1] ** 2 + n2[2] ** 2),
        np.sqrt(n3[0] ** 2 + n3[1] ** 2 + n3[2] ** 2),
    )
    largest = -1.0
    smallest = 1.0
    for i in range(4):
        for j in range(i + 1, 4):
            norms = lengths[i] * lengths[j]
            cosine = (
                -(normals[i][0] * normals[j][0] + normals[i][1] * normals[j][1] + normals[i][2] * normals[j][2]) / norms
                if norms > 0.0
                else 0.0
            )
            largest = max(largest, cosine)
            smallest = min(smallest, cosine)
    area2 = lengths[0] + lengths[1] + lengths[2] + lengths[3]  # twice the surface area
    r_in = size / area2 if area2 > 0.0 else 0.0
    if size <= 0.0 or min(min(lengths[0], lengths[1]), min(lengths[2], lengths[3])) <= 0.0:
        # flat: no volume, or a face of no area (a repeated node: its volume is rounding only)
        return six_volume, largest, smallest, 0.0, r_in
    uu, vv, ww = ux * ux + uy * uy + uz * uz, vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz
    wu = n2
    uv = n3
    cx = uu * vw[0] + vv * wu[0] + ww * uv[0]
    cy = uu * vw[1] + vv * wu[1] + ww * uv[1]
    cz = uu * vw[2] + vv * wu[2] + ww * uv[2]
    r_circ = np.sqrt(cx * cx + cy * cy + cz * cz) / (2 * size)
    return six_volume, largest, smallest, 3 * r_in / r_circ, r_in


@numba.njit(cache=True, error_model="numpy")
def dihedral(cosine):
    """The angle (degrees) of a dihedral cosine from :func:`shape`."""
    return np.degrees(np.arccos(min(1.0, max(-1.0, cosine))))


@numba.njit(cache=True, error_model="numpy")
def min_dihedral(a, b, c, d):
    """Minimum dihedral angle in degrees, -1 when the tet is inverted or flat."""
    six_volume, largest, _, _, _ = shape(a, b, c, d)
    if six_volume <= 0.0:
        return -1.0
    return dihedral(largest)


@numba.njit(cache=True, error_model="numpy")
def shape_quality(a, b, c, d):
    """min(radius ratio, min dihedral / regular dihedral): 1 for the regular tet, -1 for an inverted or flat
    one. What the optimiser (engine/meshing/improve.py) aims at."""
    six_volume, largest, _, radius_ratio, _ = shape(a, b, c, d)
    if six_volume <= 0.0:
        return -1.0
    return min(radius_ratio, dihedral(largest) / REGULAR_DIHEDRAL)


@numba.njit(cache=True, error_model="numpy")
def all_metrics(a, b, c, d):
    """(signed volume, radius ratio, mean ratio, min dihedral, max dihedral, aspect ratio) of the tet, as the
    quality report has them: radius and mean ratio within [0, 1], aspect ratio inf for a flat tet."""
    six_volume, largest, smallest, radius_ratio, r_in = shape(a, b, c, d)
    points = (a, b, c, d)
    sq_sum = 0.0
    longest = 0.0
    for i in range(4):
        for j in range(i + 1, 4):
            ex, ey, ez = points[j][0] - points[i][0], points[j][1] - points[i][1], points[j][2] - points[i][2]
            sq = ex * ex + ey * ey + ez * ez
            sq_sum += sq
            longest = max(longest, np.sqrt(sq))
    volume = six_volume / 6.0
    mean_ratio = min(12.0 * (3.0 * abs(volume)) ** (2.0 / 3.0) / sq_sum, 1.0) if sq_sum > 0 else 0.0
    aspect = longest / (2.0 * np.sqrt(6.0) * r_in) if r_in > 0 else np.inf
    return (
        volume,
        min(max(radius_ratio, 0.0), 1.0),
        mean_ratio,
        dihedral(largest),
        dihedral(smallest),
        aspect,
    )
