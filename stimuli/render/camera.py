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



# Framing of the layouts on a floor (treadmill, side_by_side): the camera keeps the protocol's
# azimuth, elevation and field of view, and comes as near as it can while the treadmill (its near
# end included) and the body span at most this share of the frame, centred. The protocol's
# distance_m left Exp 1's treadmill cut by the bottom edge and Exp 2's bodies at ~45 % of the height.
FRAME_SPAN = 0.92
# Side by side on a floor the slots' centres are this share of the width the view would give them
# (0.8: 40 % of the frame apart, not 50 %): at 20° azimuth each treadmill reaches further left of
# its slot than right, and with the wider spacing the outer ends limited a 1.60-m body to 54 % of
# the height, with a fifth of the frame empty between the treadmills.
SLOT_SPREAD = 0.8


def framed_view(points, target, azimuth_deg: float, elevation_deg: float, fov_deg: float, width: int,
                height: int, span: float = FRAME_SPAN, rounds: int = 8) -> tuple[View, float]:
    """The view (and its distance) at which ``points`` fill ``span`` of the frame's height or
    width, whichever is reached first, with as much room above them as below and on the wider
    side as across the centre line. ``points`` are world points (P, 3) around ``target``, or a
    function of (view, distance) giving them (side-by-side slots move apart with the distance).

    >>> import numpy as np
    >>> pts = np.array([[-0.5, -0.2, 1.0], [0.5, -0.2, -1.0], [0.0, 1.8, 0.0]])
    >>> view, distance = framed_view(pts, [0, 0.9, 0], 35, 10, 40, 640, 360)
    >>> rows = view.project(pts)[:, 1]
    >>> round(float(rows.max() - rows.min()) / 360, 3), bool(abs(rows.min() - (360 - rows.max())) < 0.5)
    (0.92, True)
    """
    target = np.array(target, float)
    distance = 4.0
    for _ in range(rounds):   # the picture shrinks as 1/distance: each round rescales and re-aims
        view = orbit_view(target, azimuth_deg, elevation_deg, distance, fov_deg, width, height)
        xy = view.project(np.asarray(points(view, distance) if callable(points) else points, float))
        fill = max(np.ptp(xy[:, 1]) / height, 2 * np.abs(xy[:, 0] - width / 2).max() / width)
        focal = 0.5 * height / np.tan(0.5 * view.yfov)
        target[1] -= ((xy[:, 1].min() + xy[:, 1].max()) / 2 - height / 2) * distance / focal
        distance *= fill / span
    return orbit_view(target, azimuth_deg, elevation_deg, distance, fov_deg, width, height), float(distance)
