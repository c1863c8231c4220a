"""One clip's frames: figures (body + pose sequence) placed on a stage and rendered frame by frame.

Layouts (DESIGN.md): ``treadmill`` (one figure), ``side_by_side`` (two, screen left → right),
``row`` (k labelled figures), ``point_light`` (one or k dot walkers on black). Side by side, the
figures stand on a line across the screen (the camera's right axis on the ground), each turned so
that it is seen from the same angle and at the same depth; rows are tiled (:func:`tiles`): each
figure filmed by its own camera, the tiles put side by side. Skinning is batched per chunk of frames into one
preallocated buffer per figure, whose rows are then uploaded into the figure's GL vertex buffer.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from stimuli.render.camera import orbit_view
from stimuli.render.labels import LabelOverlay
from stimuli.render.scene import Stage, grey_material, hex_colour, over

LAYOUTS = ("treadmill", "side_by_side", "row", "point_light")
# Rows of k figures are rendered as k tiles, each by the protocol's camera centred on its figure,
# and put side by side, as the thesis edited its walkers together. One wide camera over the row
# stretched the outer walkers: a 1920×540 frame with a 40° vertical view spans 104°, and the
# edge slots came out 1.47× as wide as the central ones (1/cos of their angle), more than the
# 0.5 → 58 % body-fat strengths themselves (×1.57) in a survey asking which walker looks obese.
TILED_LAYOUTS = ("row", "point_light")
SKIN_CHUNK = 32


@dataclass
class Figure:
    """A body and its per-frame pose (on the body's own rig) for exactly the clip's frames."""

    body: object                   # stimuli.bodies.Body
    rotations: np.ndarray          # (N, J, 4) local quaternions, w-first
    root_translation: np.ndarray   # (N, 3) metres
    belt_speed_mps: float = 0.0
    label: str = ""


@dataclass(frozen=True)
class Look:
    """Everything about a clip's appearance that comes from the protocol (or the command line)."""

    layout: str
    width: int
    height: int
    fps: int
    duration_s: float
    azimuth_deg: float = 30.0
    elevation_deg: float = 10.0
    distance_m: float = 4.0
    fov_deg: float = 40.0
    background: str = "#ffffff"
    labels: tuple[str, ...] = field(default_factory=tuple)
    loop: bool = True           # whole loops over the clip (cadence rounded) or the own cadence, cut
    floor: bool = True          # treadmills on a checker floor under meshes; False: the plain background
    labels_below: bool = False  # the labels under the figures instead of above them
    label_colour: str = ""      # #rrggbb; "" = black or white, whichever the background shows

    @property
    def n_frames(self) -> int:
        return int(round(self.duration_s * self.fps))


def slot_offsets(n: int, view_width_m: float) -> np.ndarray:
    """Positions of n figures along the screen's horizontal, centred, spread over the view.

    >>> slot_offsets(2, 8.0).tolist()
    [-2.0, 2.0]
    """
    spacing = view_width_m / n
    return (np.arange(n) - (n - 1) / 2) * spacing


def placements(look: Look, n: int, body_height_m: float = 1.75):
    """A 4×4 pose per figure slot, and the view.

    Slots lie on the camera's horizontal axis. Each slot is turned about the vertical by the angle
    between the camera's line of sight to the centre and to that slot, so that under perspective
    every figure is seen from exactly the protocol's azimuth (a fair side-by-side comparison).
    On a floor (``treadmill``, ``side_by_side``) the camera is framed by ``camera.framed_view``: as
    near as every slot's whole treadmill and the body's head allow, centred; ``distance_m`` is not used.
    """
    target = np.array([0.0, 0.5 * body_height_m, 0.0])   # framed on the body's middle
    if look.floor and look.layout in ("treadmill", "side_by_side"):
        from stimuli.render.camera import framed_view
        from stimuli.render.treadmill import outline

        box = np.vstack([outline(), [[0.0, body_height_m + 0.04, 0.0]]])
        view, distance = framed_view(lambda v, d: np.vstack([apply_pose(p, box) for p in _slot_poses(look, n, v, d)]),
                                     target, look.azimuth_deg, look.elevation_deg, look.fov_deg, look.width, look.height)
    else:
        distance = look.distance_m
        view = orbit_view(target, look.azimuth_deg, look.elevation_deg, distance, look.fov_deg,
                          look.width, look.height)
    return _slot_poses(look, n, view, distance), view


def _slot_poses(look: Look, n: int, view, distance: float) -> list[np.ndarray]:
    """The slots' poses for a camera ``distance`` from the target (see :func:`placements`)."""
    from stimuli.render.camera import SLOT_SPREAD

    half_h = distance * np.tan(np.radians(look.fov_deg) / 2)
    view_width = 2 * half_h * look.width / look.height * (SLOT_SPREAD if look.floor else 1.0)
    eye = view.pose[:3, 3] * np.array([1.0, 0.0, 1.0])
    poses = []
    for s in (slot_offsets(n, view_width) if n > 1 else [0.0]):
        slot = s * view.right
        d0, d1 = -eye, slot - eye
        yaw = np.arctan2(d0[2] * d1[0] - d0[0] * d1[2], d0 @ d1)   # rotation about +y taking d0 to d1
        pose = np.eye(4)
        c, si = np.cos(yaw), np.sin(yaw)
        pose[:3, :3] = [[c, 0.0, si], [0.0, 1.0, 0.0], [-si, 0.0, c]]
        pose[:3, 3] = slot
        poses.append(pose)
    return poses


def centred_root(figure: Figure) -> np.ndarray:
    """Root path with its mean horizontal position moved to the origin (the slot's centre)."""
    root = np.array(figure.root_translation, float)
    root[:, [0, 2]] -= root[:, [0, 2]].mean(axis=0)
    return root


def apply_pose(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ pose[:3, :3].T + pose[:3, 3]


def tiles(look: Look, n: int) -> list[tuple[int, Look]]:
    """Left edge (px) and look of each of ``n`` figures' tiles in a tiled layout, left to right.

    >>> [(x, t.width) for x, t in tiles(Look("row", 1920, 540, 30, 1.0), 6)][:2]
    [(0, 320), (320, 320)]
    """
    edges = np.linspace(0, look.width, n + 1).round().astype(int)
    return [(int(a), replace(look, width=int(b - a))) for a, b in zip(edges, edges[1:])]


def render_frames(look: Look, figures: list[Figure], frame_height_m: float | None = None):
    """Yield the clip's frames, (H, W, 3) uint8, exactly ``look.n_frames`` of them.

    ``row`` and ``point_light`` rows of several figures are tiled (:data:`TILED_LAYOUTS`);
    ``frame_height_m`` (default: the tallest figure's height) sets the height the camera frames.
    """
    from stimuli.motion.arms import natural_pose
    from stimuli.motion.markers import body_markers
    from stimuli.render.pointlight import DotFigure
    from stimuli.render.treadmill import Treadmill, belt_period

    if look.layout not in LAYOUTS:
        raise ValueError(f"unknown layout {look.layout!r}")
    if not figures:
        raise ValueError("a clip needs at least one figure")
    n = look.n_frames
    for f in figures:
        if len(f.rotations) != n or len(f.root_translation) != n:
            raise ValueError(f"figure {f.body.body_id}: {len(f.rotations)} poses for a clip of {n} frames")
    tallest = frame_height_m or max(f.body.anthropometry.height_m for f in figures)
    if look.layout in TILED_LAYOUTS and len(figures) > 1:
        streams = [render_frames(tile, [f], tallest) for (_, tile), f in zip(tiles(look, len(figures)), figures)]
        for parts in zip(*streams):
            yield np.concatenate(parts, axis=1)
        return
    poses, view = placements(look, len(figures), tallest)
    dots = look.layout == "point_light"
    if not dots:  # relaxed hands, arms clear of the torso: once per mesh figure, whatever the motion's source
        figures = [replace(f, rotations=natural_pose(f.body, f.rotations, f.root_translation)) for f in figures]
    stage = Stage(view, hex_colour(look.background), lit=not dots)
    roots = [centred_root(f) for f in figures]
    treadmills, floor = [], None
    if not dots and look.floor:
        from stimuli.render.treadmill import DECK_HEIGHT_M

        floor = stage.add_checker_floor(np.zeros(3), -DECK_HEIGHT_M)
        treadmills = [Treadmill(stage, p, f.belt_speed_mps, belt_period(f.belt_speed_mps, look.duration_s, look.fps))
                      for f, p in zip(figures, poses)]
    # The background (sky, floor, treadmills) is drawn once; per frame only the region holding
    # what moves is drawn — without the floor, which nothing can hide behind — and composited.
    background = stage.render()
    if floor is not None:
        stage.scene.remove_node(floor)
    stage.make_transparent()
    if dots:
        animated = [DotFigure(stage, apply_pose(p, body_markers(f.body, f.rotations, r)))
                    for f, r, p in zip(figures, roots, poses)]
    else:
        animated = [_SkinnedFigure(stage, f, r, p) for f, r, p in zip(figures, roots, poses)]
    x0, y0, x1, y1 = region = dynamic_region(view, figures, roots, poses, treadmills, dots)
    offsets = [p[:3, 3] for p in poses]
    labels = [f.label for f in figures]
    overlay = LabelOverlay(view, labels, offsets, look.background, look.labels_below, look.label_colour or None,
                           backdrop=background) if any(labels) else None
    under = background[y0:y1, x0:x1]
    for i in range(n):
        for a in animated:
            a.set_frame(i)
        for t in treadmills:
            t.set_time(i / look.fps)
        frame = background.copy()
        frame[y0:y1, x0:x1] = over(stage.render(region, rgba=True), under)
        yield overlay.apply(frame) if overlay else frame


def flesh_margin(body) -> float:
    """How far the skin reaches beyond the skeleton: max over vertices of the distance to the
    nearest bone head in the rest pose (belly, top of the head, …), plus 3 cm for posing."""
    from scipy.spatial import cKDTree

    distance, _ = cKDTree(body.rig.rest_heads).query(body.vertices)
    return float(distance.max()) + 0.03


def dynamic_region(view, figures, roots, poses, treadmills, dots: bool):
    """Pixel rectangle (x0, y0, x1, y1) holding everything that moves during the clip.

    Bodies: every bone head of every frame (forward kinematics, cheap) widened by the body's
    :func:`flesh_margin` (dots: their radius); belts: their four corners.
    """
    focal = 0.5 * view.height / np.tan(0.5 * view.yfov)
    pixels, pads = [], []
    for f, root, pose in zip(figures, roots, poses):
        p = apply_pose(pose, f.body.rig.forward_kinematics(f.rotations, root)[1].reshape(-1, 3))
        depth = (p - view.pose[:3, 3]) @ -view.pose[:3, 2]
        margin = 0.05 if dots else flesh_margin(f.body)
        pixels.append(view.project(p))
        pads.append(focal * margin / np.maximum(depth, 0.1) + 3)
    for t in treadmills:
        pixels.append(view.project(t.belt_corners()))
        pads.append(np.full(4, 3.0))
    xy, pad = np.concatenate(pixels), np.concatenate(pads)
    x0 = int(np.clip(np.floor((xy[:, 0] - pad).min()), 0, view.width))
    x1 = int(np.clip(np.ceil((xy[:, 0] + pad).max()), 0, view.width))
    y0 = int(np.clip(np.floor((xy[:, 1] - pad).min()), 0, view.height))
    y1 = int(np.clip(np.ceil((xy[:, 1] + pad).max()), 0, view.height))
    if x1 - x0 < 2 or y1 - y0 < 2:
        return 0, 0, view.width, view.height
    return x0, y0, x1, y1


class _SkinnedFigure:
    """A body mesh on the stage whose vertices are skinned a chunk of frames at a time."""

    def __init__(self, stage: Stage, figure: Figure, root: np.ndarray, pose: np.ndarray):
        from stimuli.render.dynamic import DynamicMesh

        self.figure, self.root = figure, root
        n_v = figure.body.n_vertices
        self.buffer = np.empty((min(SKIN_CHUNK, len(root)), n_v, 3), np.float64)
        self.start = -1
        self._fill(0)
        self.mesh = DynamicMesh(self.buffer[0], figure.body.faces, grey_material())
        stage.add(self.mesh.mesh, pose=pose)

    def _fill(self, start: int) -> None:
        stop = min(start + len(self.buffer), len(self.root))
        self.figure.body.skin(self.figure.rotations[start:stop], self.root[start:stop], out=self.buffer[:stop - start])
        self.start = start

    def set_frame(self, i: int) -> None:
        if not self.start <= i < self.start + len(self.buffer):
            self._fill(i)
        self.mesh.update(self.buffer[i - self.start])
