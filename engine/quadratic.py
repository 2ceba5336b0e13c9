"""Quality of 10-node tetrahedra: the scaled Jacobian, bounded from below by Bezier coefficients.

The Jacobian determinant of a 10-node tet is a polynomial of degree 3 in the barycentric coordinates.
Written in the degree-3 Bernstein basis, its 20 coefficients bound it: every value lies between the
smallest and the largest coefficient, and the 4 vertex coefficients are the values at the corners
(Johnen, Remacle, Geuzaine 2013). Nodes are in VTK / meshio / Abaqus C3D10 order (``engine.fe.TET10_EDGES``).
"""

from __future__ import annotations

from itertools import product
from math import factorial

import numpy as np

QUADRATIC_FLOOR = 0.2  # the smallest scaled Jacobian a curved 10-node element may have


def _gradients(r: float, s: float, t: float) -> np.ndarray:
    """(10, 3) gradients of the 10-node shape functions at reference point (r, s, t)."""
    u = 1 - r - s - t
    return np.array(
        [
            [-(4 * u - 1), -(4 * u - 1), -(4 * u - 1)],
            [4 * r - 1, 0, 0],
            [0, 4 * s - 1, 0],
            [0, 0, 4 * t - 1],
            [4 * (u - r), -4 * r, -4 * r],
            [4 * s, 4 * r, 0],
            [-4 * s, 4 * (u - s), -4 * s],
            [-4 * t, -4 * t, 4 * (u - t)],
            [4 * t, 0, 4 * r],
            [0, 4 * t, 4 * s],
        ]
    )


def _bernstein():
    """The degree-3 lattice (20, 4) of barycentric multi-indices and the (20, 20) map from the values at
    its points (index / 3) to the Bernstein coefficients."""
    lattice = np.array([a for a in product(range(4), repeat=4) if sum(a) == 3])
    weight = np.array([factorial(3) / np.prod([factorial(k) for k in a]) for a in lattice])
    values = weight * np.prod((lattice[:, None, :] / 3.0) ** lattice[None, :, :], axis=2)  # B_q at point p
    return lattice, np.linalg.inv(values)


LATTICE, TO_BERNSTEIN = _bernstein()
LATTICE_GRADIENTS = np.array([_gradients(*(a[1:] / 3.0)) for a in LATTICE])  # (20, 10, 3)


def jacobians(points: np.ndarray, tets10: np.ndarray) -> np.ndarray:
    """(m, 20) Jacobian determinants of each 10-node tet at the degree-3 lattice points (``LATTICE`` / 3)."""
    x = points[tets10]  # (m, 10, 3)
    out = np.empty((len(tets10), len(LATTICE)))
    for p, gradient in enumerate(LATTICE_GRADIENTS):
        columns = np.einsum("mai,aj->jmi", x, gradient)  # dx/dr, dx/ds, dx/dt: (3, m, 3)
        out[:, p] = np.einsum("mi,mi->m", columns[0], np.cross(columns[1], columns[2]))
    return out


def bernstein_jacobians(points: np.ndarray, tets10: np.ndarray) -> np.ndarray:
    """(m, 20) Bernstein coefficients of det J (a cubic) of each 10-node tet: det J lies between their min and max,
    and their mean is its mean over the element (every cubic Bernstein polynomial integrates to 1/20 of it)."""
    return jacobians(points, tets10) @ TO_BERNSTEIN.T


def scaled_jacobian(points: np.ndarray, tets10: np.ndarray) -> np.ndarray:
    """(m,) lower bound of min det J / det J of the straight-sided tet, per 10-node tet (``points`` (n, 3),
    ``tets10`` (m, 10)): the smallest Bernstein coefficient of det J over 6 x the corners' volume.

    1 for a straight-sided element, at most the value at any corner, and positive only if the element
    is valid everywhere (the corner tets must be positively oriented).
    """
    coefficients = bernstein_jacobians(points, tets10)
    x = points[tets10[:, :4]]
    straight = np.einsum("mi,mi->m", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))
    return coefficients.min(axis=1) / straight


def curved_volumes(points: np.ndarray, tets10: np.ndarray) -> np.ndarray:
    """(m,) exact volume of each 10-node tet, curved sides included: the integral of det J over the reference
    tet (volume 1/6), the mean of its Bernstein coefficients / 6."""
    return bernstein_jacobians(points, tets10).mean(axis=1) / 6
