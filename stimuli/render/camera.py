"""Camera placement and projection: azimuth/elevation/distance/field of view around a target.

Azimuth 0° puts the camera in front of the character (on +z, looking back at its face); 90° on the
character's left (+x), a side view; elevation > 0 looks down. The vertical field of view is the
protocol's ``fov_deg``.

>>> import numpy as np
>>> pose = look_at(np.array([0.0, 1.0, 4.0]), np.array([0.0, 1.0, 0.0]))
>>> np.round(pose[:3, 2], 6).tolist()    # the camera's +z (backwards) points away from the target
[0.0, 0.0, 1.0]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class View:
    """A pinhole camera: world → camera pose, vertical field of view, image size."""

    pose: np.ndarray          # (4, 4) camera-to-world, OpenGL convention (looks along −z)
    yfov: float               # radians
    width: int
    height: int

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) → pixel coordinates (..., 2) (x right, y down) and depth in front."""
        world_to_cam = np.linalg.inv(self.pose)
        p = np.asarray(points, float) @ world_to_cam[:3, :3].T + world_to_cam[:3, 3]
        f = 0.5 * self.height / np.tan(0.5 * self.yfov)
        depth = -p[..., 2]
        x = 0.5 * self.width + f * p[..., 0] / depth
        y = 0.5 * self.height - f * p[..., 1] / depth
        return np.stack([x, y], axis=-1)

    @property
    def right(self) -> np.ndarray:
        """The camera's right direction on the ground plane (unit, y = 0)."""
        r = self.pose[:3, 0].copy()
        r[1] = 0.0
        return r / np.linalg.norm(r)


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera-to-world pose of a camera at ``eye`` looking at ``target`` (OpenGL axes)."""
    back = np.asarray(eye, float) - np.asarray(target, float)
    back /= np.linalg.norm(back)
    right = np.cross(np.asarray(up, float), back)
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, true_up, back, eye
    return pose


def orbit_view(target, azimuth_deg: float, elevation_deg: float, distance_m: float, fov_deg: float,
               width: int, height: int) -> View:
    """The protocol's third-person camera around ``target``."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    direction = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    eye = np.asarray(target, float) + distance_m * direction
    return View(look_at(eye, target), np.radians(fov_deg), width, height)
