"""A contact sheet: every body of a protocol side by side (front and side views), sorted by BMI.

Rendered offscreen with pyrender (EGL by default; set ``PYOPENGL_PLATFORM=osmesa`` to use
OSMesa). One ``OffscreenRenderer`` per process, reused for every tile. All tiles share one
orthographic camera scale, so heights compare across bodies; a floor line marks y = 0.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

TILE_W, TILE_H = 300, 440
VIEW_HEIGHT_M = 2.2          # metres shown vertically in every tile
SEX_COLOURS = {"F": (0.78, 0.50, 0.45, 1.0), "M": (0.42, 0.52, 0.72, 1.0)}


@functools.lru_cache(maxsize=1)
def _renderer():
    from stimuli.render.gl import pyrender_module

    return pyrender_module().OffscreenRenderer(TILE_W, TILE_H)


def render_tile(body, yaw_deg: float = 0.0) -> np.ndarray:
    """RGB image (TILE_H, TILE_W, 3) of a body's rest mesh seen from the front (yaw 0) or rotated."""
    import trimesh

    from stimuli.render.gl import ordered_scene, pyrender_module

    pyrender = pyrender_module()

    yaw = np.deg2rad(yaw_deg)
    turn = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    vertices = body.vertices @ turn.T
    mesh = trimesh.Trimesh(vertices, body.faces, process=False)
    material = pyrender.MetallicRoughnessMaterial(baseColorFactor=SEX_COLOURS.get(body.sex, (0.7, 0.7, 0.7, 1.0)),
                                                  metallicFactor=0.0, roughnessFactor=0.8)
    scene = ordered_scene(ambient_light=[0.25, 0.25, 0.25], bg_color=[1.0, 1.0, 1.0, 1.0])  # lights in a fixed order
    scene.add(pyrender.Mesh.from_trimesh(mesh, material=material, smooth=True))
    camera = pyrender.OrthographicCamera(xmag=VIEW_HEIGHT_M / 2 * TILE_W / TILE_H, ymag=VIEW_HEIGHT_M / 2)
    pose = np.eye(4)
    pose[:3, 3] = [0.0, VIEW_HEIGHT_M / 2 - 0.05, 5.0]  # looking along −z at the body's front
    scene.add(camera, pose=pose)
    key = np.eye(4)
    key[:3, :3] = _look_rotation(np.array([0.6, 0.8, 1.0]))
    scene.add(pyrender.DirectionalLight(intensity=2.0), pose=key)
    scene.add(pyrender.DirectionalLight(intensity=0.8), pose=pose)
    colour, _ = _renderer().render(scene)
    return np.asarray(colour[..., :3])


def _look_rotation(from_direction: np.ndarray) -> np.ndarray:
    """Rotation whose −z axis points away from ``from_direction`` (a light shining from there)."""
    z = from_direction / np.linalg.norm(from_direction)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def contact_sheet(bodies, path: str | Path, title: str | None = None) -> Path:
    """Write a PNG of all bodies sorted by BMI: front views on top, side views below, labelled."""
    from PIL import Image, ImageDraw, ImageFont

    from stimuli.fileio import atomic_write_bytes

    ordered = sorted(bodies, key=lambda b: (b.anthropometry.bmi, b.body_id))
    font = ImageFont.load_default(size=17)
    label_h, title_h = 50, 34 if title else 0
    sheet = Image.new("RGB", (TILE_W * len(ordered), title_h + 2 * TILE_H + label_h), "white")
    draw = ImageDraw.Draw(sheet)
    floor_y = title_h + _floor_row()
    for i, body in enumerate(ordered):
        x0 = i * TILE_W
        sheet.paste(Image.fromarray(render_tile(body, 0.0)), (x0, title_h))
        sheet.paste(Image.fromarray(render_tile(body, 90.0)), (x0, title_h + TILE_H))
        a = body.anthropometry
        draw.text((x0 + 8, title_h + 2 * TILE_H + 4), f"{body.body_id} ({body.sex})", fill="black", font=font)
        draw.text((x0 + 8, title_h + 2 * TILE_H + 25), f"{a.height_m:.2f} m  BMI {a.bmi:.1f}  {a.mass_kg:.0f} kg",
                  fill="black", font=font)
        draw.line([(x0, title_h), (x0, title_h + 2 * TILE_H)], fill=(200, 200, 200))
    for row in (floor_y, floor_y + TILE_H):
        draw.line([(0, row), (sheet.width, row)], fill=(120, 120, 120))
    if title:
        draw.text((8, 8), title, fill="black", font=font)
    import io

    buffer = io.BytesIO()
    sheet.save(buffer, format="PNG")
    atomic_write_bytes(path, buffer.getvalue())
    return Path(path)


def _floor_row() -> int:
    """Pixel row of y = 0 inside a tile (the camera centre is VIEW_HEIGHT_M/2 − 0.05 m up)."""
    centre = VIEW_HEIGHT_M / 2 - 0.05
    return int(round(TILE_H / 2 + centre / VIEW_HEIGHT_M * TILE_H))
