"""A low-profile treadmill whose belt texture moves backwards at the motion's speed.

The belt surface is at y = 0 (where the bodies' feet touch the ground), the deck and side rails
sit below and beside it, and the checkerboard floor is ``DECK_HEIGHT_M`` lower. There are no
handrails or console, so no part of the treadmill can hide the body from any camera angle.

The belt's stripes have a period chosen so that the belt travels a whole number of periods in
one clip: the last frame flows into the first and the loop is seamless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from stimuli.render.dynamic import DynamicMesh
from stimuli.render.scene import Stage, grey_material, quad, static_mesh

DECK_HEIGHT_M = 0.16
BELT_Y = -0.002            # a hair below the ground so soles that touch y = 0 stay visible
RAIL_WIDTH_M = 0.09
HOOD_LENGTH_M = 0.18
STRIPE_M = 0.25            # wanted belt pattern period; adjusted per clip for a seamless loop
STRIPE_FRACTION = 0.22     # the lighter band's share of one period
BELT_GREY, STRIPE_GREY = (0.20, 0.20, 0.21), (0.36, 0.36, 0.37)
CONTACT_SHADOW = 0.55      # the belt is this much darker under the figure's centre (soft blob, shaders/mesh.frag)


@dataclass(frozen=True)
class TreadmillSize:
    """Belt length and width in metres (defaults fit walking and jogging adults)."""

    length: float = 1.8
    width: float = 0.85


def belt_period(speed_mps: float, duration_s: float, fps: float, wanted: float = STRIPE_M) -> float:
    """Stripe period (m) with a whole number of periods per clip and under 1/3 period per frame.

    >>> p = belt_period(1.2, 4.0, 30)
    >>> round(1.2 * 4.0 / p, 9) == round(1.2 * 4.0 / p) and 1.2 / 30 < p / 3
    True
    """
    travel = abs(speed_mps) * duration_s
    wanted = max(wanted, 3.0 * abs(speed_mps) / fps)  # stripes must not alias (wagon-wheel effect)
    if travel == 0:
        return wanted
    return travel / max(1, int(np.floor(travel / wanted)))


def _box(extents, centre):
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(centre)
    return box


class Treadmill:
    """Treadmill meshes on a stage at horizontal position ``origin``; call :meth:`set_time` per frame.

    The belt is a dark quad with lighter transverse bands on top of it. The bands are geometry
    (anti-aliased by multisampling), moved every frame and clipped at the belt's ends, so the
    pattern runs off one end as it enters at the other.
    """

    def __init__(self, stage: Stage, pose, speed_mps: float, period_m: float, size: TreadmillSize = TreadmillSize()):
        self.pose = np.asarray(pose, float)
        self.origin = np.zeros(3)   # geometry is built about the slot's own origin, placed by ``pose``
        self.speed, self.period, self.size = speed_mps, period_m, size
        ox, oz = self.origin[0], self.origin[2]
        half_w = size.width / 2
        self._corners, belt_faces = quad(ox - half_w, ox + half_w, oz - size.length / 2, oz + size.length / 2, BELT_Y)
        self.n_stripes = int(np.ceil(size.length / period_m)) + 1
        stripes_v, stripes_f = self._stripes(0.0)
        self.stripes = DynamicMesh(stripes_v, stripes_f, grey_material(STRIPE_GREY, roughness=0.95, contact_shadow=CONTACT_SHADOW))
        stage.add(static_mesh(self._corners, belt_faces, grey_material(BELT_GREY, roughness=0.95, contact_shadow=CONTACT_SHADOW)),
                  pose=self.pose)
        stage.add(self.stripes.mesh, pose=self.pose)
        stage.add(static_mesh(*self._frame_geometry(), grey_material((0.30, 0.31, 0.33), roughness=0.6)), pose=self.pose)

    def _stripes(self, t: float):
        """Band quads at time t (vertices (4n, 3), faces (2n, 3)), moving towards −z at belt speed."""
        half_l = self.size.length / 2
        cycle = self.n_stripes * self.period
        start = (np.arange(self.n_stripes) * self.period - self.speed * t) % cycle - half_l
        z0 = np.clip(start, -half_l, half_l) + self.origin[2]
        z1 = np.clip(start + STRIPE_FRACTION * self.period, -half_l, half_l) + self.origin[2]
        x0, x1 = self.origin[0] - self.size.width / 2, self.origin[0] + self.size.width / 2
        y = BELT_Y + 0.001
        v = np.zeros((self.n_stripes, 4, 3))
        v[:, :, 1] = y
        v[:, [0, 3], 0], v[:, [1, 2], 0] = x0, x1
        v[:, [0, 1], 2] = z0[:, None]
        v[:, [2, 3], 2] = z1[:, None]
        base = np.arange(self.n_stripes)[:, None] * 4
        faces = np.concatenate([base + [0, 2, 1], base + [0, 3, 2]])
        return v.reshape(-1, 3), faces

    def belt_corners(self) -> np.ndarray:
        """The belt's four corners (4, 3) in the world — the part of the treadmill that changes per frame."""
        return self._corners @ self.pose[:3, :3].T + self.pose[:3, 3]

    def set_time(self, t: float) -> None:
        self.stripes.update(self._stripes(t)[0])

    def _frame_geometry(self):
        """Deck under the belt, two side rails slightly above it, a motor hood at the front (+z)."""
        ox, oz = self.origin[0], self.origin[2]
        L, W, H = self.size.length, self.size.width, DECK_HEIGHT_M
        rail_top = 0.012
        parts = [
            _box((W + 2 * RAIL_WIDTH_M, H - 0.01, L + 0.10), (ox, -H / 2 - 0.008, oz)),
            _box((RAIL_WIDTH_M, H + rail_top, L), (ox - W / 2 - RAIL_WIDTH_M / 2, (rail_top - H) / 2, oz)),
            _box((RAIL_WIDTH_M, H + rail_top, L), (ox + W / 2 + RAIL_WIDTH_M / 2, (rail_top - H) / 2, oz)),
            _box((W + 2 * RAIL_WIDTH_M, H + 0.07, HOOD_LENGTH_M), (ox, (0.07 - H) / 2, oz + L / 2 + HOOD_LENGTH_M / 2)),
        ]
        merged = trimesh.util.concatenate(parts)
        return merged.vertices, merged.faces


def outline(size: TreadmillSize = TreadmillSize()) -> np.ndarray:
    """The corners (8, 3) of the box holding a treadmill at the origin (deck, rails and hood), for framing.

    >>> outline().shape
    (8, 3)
    """
    half_w = size.width / 2 + RAIL_WIDTH_M
    back, front = -size.length / 2 - 0.05, size.length / 2 + HOOD_LENGTH_M
    return np.array([[x, y, z] for x in (-half_w, half_w) for y in (-DECK_HEIGHT_M - 0.01, 0.06) for z in (back, front)])
