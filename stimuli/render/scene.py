"""The stage every clip is drawn on: background, checkerboard floor, soft three-point light, camera.

A :class:`Stage` is built once per clip; afterwards only vertex buffers, texture coordinates and
node poses change between frames (see :mod:`stimuli.render.dynamic`). Shading is deliberately
plain: neutral grey, no skin texture (the paper avoided detailed skin to stay clear of the
uncanny valley).
"""

from __future__ import annotations

import numpy as np

from stimuli.errors import StimuliError
from stimuli.render.camera import View, look_at
from stimuli.render.gl import ordered_scene, pyrender_module, renderer

BODY_GREY = (0.62, 0.62, 0.62)
FLOOR_LIGHT, FLOOR_DARK = (236, 236, 236), (200, 200, 200)
CHECKER_M = 0.5            # side of one floor square in metres
FLOOR_HALF_M = 150.0       # the floor fades into the background out to this far from the target


def hex_colour(text: str, where: str = "clip.background") -> tuple[float, float, float]:
    """'#rrggbb' → RGB in [0, 1].

    >>> hex_colour("#ff8000")
    (1.0, 0.5019607843137255, 0.0)
    """
    value = text.strip().lstrip("#")
    if len(value) != 6 or any(c not in "0123456789abcdefABCDEF" for c in value):
        raise StimuliError(f"{where}: expected a colour like '#ffffff', got {text!r}")
    return tuple(int(value[i:i + 2], 16) / 255.0 for i in (0, 2, 4))


def grey_material(rgb=BODY_GREY, roughness: float = 0.75, contact_shadow: float = 0.0):
    """A matte grey for shaders/mesh.frag; ``contact_shadow`` (0–1, carried in the metallic factor,
    which the matte shader does not use otherwise) darkens the surface by up to that fraction under
    a figure standing at the mesh's origin."""
    pyrender = pyrender_module()
    return pyrender.MetallicRoughnessMaterial(baseColorFactor=(*rgb, 1.0), metallicFactor=float(contact_shadow),
                                              roughnessFactor=roughness)


def checker_floor_mesh(centre, y: float, square: float = CHECKER_M, half: float = FLOOR_HALF_M,
                       fade=(6.0, 16.0), background=(1.0, 1.0, 1.0)):
    """Checkerboard squares as coloured geometry (no texture), fading to a flat grey with distance,
    and the grey fading into ``background`` out to ``half`` metres (:func:`far_floor`).

    Far squares shrink below a pixel near the horizon; fading their contrast between ``fade[0]``
    and ``fade[1]`` metres from the centre keeps the horizon free of moiré.
    """
    pyrender = pyrender_module()
    cx, cz = float(centre[0]), float(centre[2])
    n = int(np.ceil(fade[1] / square)) + 1   # squares beyond the fade would be the flat grey anyway
    i, k = np.meshgrid(np.arange(-n, n), np.arange(-n, n), indexing="ij")
    near = np.hypot((i.ravel() + 0.5) * square, (k.ravel() + 0.5) * square) < fade[1] + square
    i, k = i.ravel()[near], k.ravel()[near]   # beyond the fade every square is the flat grey below
    x0 = cx + i * square
    z0 = cz + k * square
    corners = np.stack([np.stack([x0, x0 + square, x0 + square, x0], 1),
                        np.stack([z0, z0, z0 + square, z0 + square], 1)], -1)       # (Q, 4, 2)
    vertices = np.zeros((len(x0) * 4, 3), np.float32)
    vertices[:, 0], vertices[:, 1], vertices[:, 2] = corners[..., 0].ravel(), y, corners[..., 1].ravel()
    dist = np.hypot(x0 + square / 2 - cx, z0 + square / 2 - cz)
    contrast = np.clip((fade[1] - dist) / (fade[1] - fade[0]), 0.0, 1.0)
    light, dark = np.array(FLOOR_LIGHT) / 255.0, np.array(FLOOR_DARK) / 255.0
    mid = (light + dark) / 2
    parity = ((i + k) % 2 == 0)[:, None]
    colour = mid + np.where(parity, light - mid, dark - mid) * contrast[:, None]
    colours = np.ones((len(x0) * 4, 4), np.float32)
    colours[:, :3] = np.repeat(colour, 4, axis=0)
    base = np.arange(len(x0))[:, None] * 4
    faces = np.concatenate([base + [0, 2, 1], base + [0, 3, 2]])
    # The far floor, a few millimetres lower: flat grey that fades into the background towards its
    # edge, so the camera sees no edge (a square floor's far edge showed as a tilted horizon).
    far_v, far_f, far_c = far_floor(centre, y - 0.005, mid, background, (fade[1], half))
    faces = np.concatenate([faces, far_f + len(vertices)]).astype(np.uint32)
    vertices = np.concatenate([vertices, far_v.astype(np.float32)])
    colours = np.concatenate([colours, far_c.astype(np.float32)])
    # emissive_factor > 0 marks an unlit surface for shaders/mesh.frag: the colours are final.
    unlit = pyrender.MetallicRoughnessMaterial(baseColorFactor=(1.0, 1.0, 1.0, 1.0), metallicFactor=0.0,
                                               roughnessFactor=1.0, emissiveFactor=(1.0, 1.0, 1.0))
    prim = pyrender.Primitive(positions=vertices, normals=_flat_up_normals(vertices), color_0=colours,
                              indices=faces, material=unlit, mode=pyrender.GLTF.TRIANGLES)
    return pyrender.Mesh([prim])


def far_floor(centre, y: float, grey, background, radii=(16.0, 150.0), rings: int = 16, sectors: int = 96):
    """A disc of the floor's flat ``grey`` that turns into ``background`` between ``radii`` metres
    from ``centre``: (vertices (V, 3), faces (F, 3), RGBA colours (V, 4)). Its rim has the
    background's colour, so no edge shows however the camera looks (the horizon melts away). The
    colour changes linearly in 1/distance, as the rows of the picture do, so that each row differs
    from the next by under a grey level (a fade linear in distance crowded into a few rows near the
    horizon). The outer radius stays within the camera's far plane (``Stage``: 200 m).

    >>> v, f, c = far_floor([0, 0, 0], 0.0, (0.8, 0.8, 0.8), (1.0, 1.0, 1.0), rings=4, sectors=8)
    >>> v.shape, f.shape, c[0].tolist(), c[-1].tolist()
    ((41, 3), (72, 3), [0.800000011920929, 0.800000011920929, 0.800000011920929, 1.0], [1.0, 1.0, 1.0, 1.0])
    """
    inner, outer = radii
    radius = 1.0 / np.linspace(1.0 / inner, 1.0 / outer, rings + 1)
    angle = np.linspace(0.0, 2.0 * np.pi, sectors, endpoint=False)
    ring_xz = radius[:, None, None] * np.stack([np.cos(angle), np.sin(angle)], -1)[None]    # (R, S, 2)
    vertices = np.zeros((1 + ring_xz.shape[0] * sectors, 3))
    vertices[:, 1] = y
    vertices[1:, 0] = float(centre[0]) + ring_xz[..., 0].ravel()
    vertices[1:, 2] = float(centre[2]) + ring_xz[..., 1].ravel()
    share = np.concatenate([[0.0], np.repeat(np.linspace(0.0, 1.0, rings + 1), sectors)])[:, None]
    colours = np.ones((len(vertices), 4), np.float32)
    colours[:, :3] = (1 - share) * np.asarray(grey, float) + share * np.asarray(background, float)
    k = np.arange(sectors)
    nxt = (k + 1) % sectors
    faces = [np.stack([np.zeros(sectors, int), 1 + nxt, 1 + k], 1)]          # the inner disc, a fan
    for r in range(rings):
        a, b = 1 + r * sectors, 1 + (r + 1) * sectors
        faces += [np.stack([a + k, a + nxt, b + k], 1), np.stack([a + nxt, b + nxt, b + k], 1)]
    return vertices, np.concatenate(faces), colours


def quad(x0, x1, z0, z1, y):
    """An upward-facing rectangle on a horizontal plane: (vertices (4, 3), faces (2, 3))."""
    v = np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], float)
    return v, np.array([[0, 2, 1], [0, 3, 2]])


def static_mesh(vertices, faces, material, smooth: bool = False):
    """A pyrender mesh that never changes (treadmill frame), flat-shaded by default."""
    import trimesh

    pyrender = pyrender_module()
    tm = trimesh.Trimesh(np.asarray(vertices, float), faces, process=False)
    return pyrender.Mesh.from_trimesh(tm, material=material, smooth=smooth)


def _flat_up_normals(vertices: np.ndarray) -> np.ndarray:
    n = np.zeros_like(vertices, dtype=np.float32)
    n[:, 1] = 1.0
    return n


class Stage:
    """A pyrender scene with the camera and lights placed for one view; add meshes, then render."""

    def __init__(self, view: View, background=(1.0, 1.0, 1.0), lit: bool = True):
        pyrender = pyrender_module()
        self.view = view
        self.background = background
        self.scene = ordered_scene(bg_color=(*background, 1.0), ambient_light=(0.28, 0.28, 0.28) if lit else (0, 0, 0))
        # An intrinsics camera can render any sub-rectangle of the image (see ``render``).
        self.focal = 0.5 * view.height / np.tan(0.5 * view.yfov)
        self.camera = pyrender.IntrinsicsCamera(fx=self.focal, fy=self.focal, cx=view.width / 2, cy=view.height / 2,
                                                znear=0.05, zfar=200.0)
        self.scene.add(self.camera, pose=view.pose)
        self.flags = pyrender.RenderFlags.NONE
        if lit:
            self._add_three_point_lights()
        else:
            self.flags = pyrender.RenderFlags.FLAT

    def _add_three_point_lights(self) -> None:
        """Key (camera-left, above), fill (camera-right, lower, weaker) and rim (behind) lights."""
        pyrender = pyrender_module()
        pose = self.view.pose
        right, up, back = pose[:3, 0], pose[:3, 1], pose[:3, 2]
        target = pose[:3, 3] - back * 4.0
        for offset, intensity in (((-0.7 * right + 0.9 * up + 0.6 * back), 0.62),
                                  ((0.9 * right + 0.25 * up + 0.7 * back), 0.28),
                                  ((0.2 * right + 1.0 * up - 1.0 * back), 0.35)):
            light = pyrender.DirectionalLight(color=np.ones(3), intensity=intensity)
            self.scene.add(light, pose=look_at(target + offset, target))

    def add(self, mesh, pose=None):
        """Add a mesh (pyrender.Mesh) and return its node (move it later with ``set_pose``)."""
        return self.scene.add(mesh, pose=np.eye(4) if pose is None else pose)

    def add_checker_floor(self, centre, y: float):
        """The checkerboard ground plane, squares of ``CHECKER_M``, aligned to world x/z; returns its node."""
        return self.add(checker_floor_mesh(centre, y, background=self.background))

    def render(self, region: tuple[int, int, int, int] | None = None, rgba: bool = False) -> np.ndarray:
        """The frame, or only the pixels ``region = (x0, y0, x1, y1)`` of it, as uint8 RGB(A).

        Rendering a region shifts the principal point so that its pixels are exactly those of
        the full image (4× multisampled either way). With ``rgba`` and a transparent background
        the colour is premultiplied by coverage, ready for :func:`over`.
        """
        pyrender = pyrender_module()
        x0, y0, x1, y1 = region or (0, 0, self.view.width, self.view.height)
        self.camera.cx = self.view.width / 2 - x0
        self.camera.cy = self.view.height / 2 - y0
        r = renderer(x1 - x0, y1 - y0)
        colour, _ = r.render(self.scene, flags=self.flags | (pyrender.RenderFlags.RGBA if rgba else 0))
        return colour

    def make_transparent(self) -> None:
        """Clear to transparent black from now on (for layers composited over a background)."""
        self.scene.bg_color = np.zeros(4)


def over(premultiplied: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Composite a premultiplied RGBA layer (uint8) over an RGB background (uint8).

    >>> import numpy as np
    >>> over(np.array([[[100, 0, 0, 128]]], np.uint8), np.array([[[0, 0, 254]]], np.uint8)).tolist()
    [[[100, 0, 127]]]
    """
    alpha = premultiplied[..., 3:4].astype(np.uint16)
    out = premultiplied[..., :3].astype(np.uint16) + (background.astype(np.uint16) * (255 - alpha) + 127) // 255
    return np.minimum(out, 255).astype(np.uint8)
