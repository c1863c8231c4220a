"""Anthropometry of a rest-pose mesh (project frame): height, volume, mass, BMI, girths and indices.

Girths are what a tape measure reads: the perimeter of the convex hull of a horizontal slice of
the trunk (arms excluded through the skinning-weight segments). The waist is Anny's own waist
vertex loop (``anny.Anthropometry``), so it matches what the Anny authors call the waist.
Indices (SPEC §1.3): BSA (Mosteller) = √(height_cm · mass_kg / 3600), BAI = hip_cm / height_m^1.5
− 18, ABSI = waist_m / (BMI^(2/3) · height_m^(1/2)), WHR = waist / hip.

Examples
--------
>>> round(bsa_mosteller(1.80, 80.0), 3)
2.0
>>> round(absi(0.94, 24.7, 1.80), 4)
0.0826
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.spatial import ConvexHull


@dataclasses.dataclass(frozen=True)
class Anthropometry:
    """Measured on the rest-pose mesh (metres, kg, kg/m², m²)."""

    height_m: float
    volume_m3: float
    mass_kg: float
    bmi: float
    waist_m: float
    hip_m: float
    chest_m: float
    bsa_m2: float
    bai: float
    absi: float
    whr: float

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


def bsa_mosteller(height_m: float, mass_kg: float) -> float:
    """Body surface area (m²), Mosteller 1987."""
    return math.sqrt(height_m * 100.0 * mass_kg / 3600.0)


def bai(hip_m: float, height_m: float) -> float:
    """Body adiposity index (Bergman 2011): hip circumference (cm) / height (m)^1.5 − 18."""
    return hip_m * 100.0 / height_m**1.5 - 18.0


def absi(waist_m: float, bmi: float, height_m: float) -> float:
    """A body shape index (Krakauer 2012): WC / (BMI^(2/3) · H^(1/2)), metres."""
    return waist_m / (bmi ** (2.0 / 3.0) * height_m**0.5)


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume of a closed triangle mesh (signed tetrahedra, absolute value)."""
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    return abs(float(np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum()) / 6.0)


def slice_girth(vertices: np.ndarray, edges: np.ndarray, level: float) -> float:
    """Tape-measure girth at height ``level``: convex-hull perimeter of the edges crossing y = level."""
    y0, y1 = vertices[edges[:, 0], 1], vertices[edges[:, 1], 1]
    cross = (y0 - level) * (y1 - level) < 0
    if cross.sum() < 3:
        return 0.0
    p0, p1 = vertices[edges[cross, 0]], vertices[edges[cross, 1]]
    t = ((level - y0[cross]) / (y1[cross] - y0[cross]))[:, None]
    points = (p0 + t * (p1 - p0))[:, [0, 2]]
    return float(ConvexHull(points).area)  # in 2-D scipy's "area" is the perimeter


def max_girth(vertices: np.ndarray, edges: np.ndarray, low: float, high: float, n: int = 15) -> float:
    """Largest girth over ``n`` levels between ``low`` and ``high`` (hip and chest: the widest level)."""
    return max(slice_girth(vertices, edges, level) for level in np.linspace(low, high, n))


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """Undirected edges (E, 2) of a set of triangles."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def measure(vertices, faces, waist_m, landmarks, trunk_edges, hip_edges, density) -> Anthropometry:
    """All measurements of one rest-pose body.

    ``landmarks``: dict with the y of ``hip_joint`` and ``chest`` (spine01 head) in the project
    frame; ``trunk_edges``/``hip_edges``: mesh edges of the trunk (spine01–04) and of the
    pelvis + thighs, so that the arms never enter a girth.
    """
    height = float(vertices[:, 1].max() - vertices[:, 1].min())
    volume = mesh_volume(vertices, faces)
    mass = volume * density
    bmi = mass / height**2
    hip_y, chest_y = landmarks["hip_joint"], landmarks["chest"]
    hip = max_girth(vertices, hip_edges, hip_y - 0.06 * height, hip_y + 0.03 * height)
    chest = max_girth(vertices, trunk_edges, chest_y - 0.03 * height, chest_y + 0.04 * height)
    return Anthropometry(
        height_m=height, volume_m3=volume, mass_kg=mass, bmi=bmi, waist_m=float(waist_m), hip_m=hip,
        chest_m=chest, bsa_m2=bsa_mosteller(height, mass), bai=bai(hip, height),
        absi=absi(float(waist_m), bmi, height), whr=float(waist_m) / hip if hip > 0 else float("nan"),
    )
