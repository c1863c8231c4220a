"""BVH import and export.

Import reads the hierarchy with ``bvhio`` (its parser checks the syntax and reports the line), then
reads the frames with numpy in one go (bvhio builds one object per joint and frame, far slower) and
converts any channel order to quaternions. The skeleton naming is detected (CMU cgspeed, Mixamo,
Poser/old CMU, DAZ) or given by a mapping file; the units are found from the skeleton's height;
a z-up file is turned y-up; the reference T-pose frame that many converted files start with is
dropped. End sites become leaf joints named ``<parent>_end`` (they give toe tips and head tops).

Examples
--------
>>> from stimuli.motion.bvh import read_bvh          # doctest: +SKIP
>>> m = read_bvh("stimuli/data/cmu_35_01_walk.bvh")  # doctest: +SKIP
>>> m.metadata["naming"]                              # doctest: +SKIP
'cmu'
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.fileio import atomic_write_text
from stimuli.motion import quat
from stimuli.motion.motion import Motion
from stimuli.motion.skeleton import detect_roles, load_mapping

# File unit → metres, chosen by the skeleton's rest height (in file units) falling in the range.
UNIT_RANGES = ((1.0, 2.4, 1.0, "m"), (100.0, 240.0, 0.01, "cm"), (1000.0, 2400.0, 0.001, "mm"),
               (39.0, 95.0, 0.0254, "in"))
DEFAULT_HEIGHT_M = 1.75  # assumed body height when the units cannot be recognised


def _flatten(root) -> list[tuple[str, int, np.ndarray, list[str], object]]:
    """Depth-first list of (name, parent index, offset, channels, bvhio joint), end sites included."""
    out: list = []

    def visit(joint, parent: int) -> None:
        idx = len(out)
        out.append((joint.Name, parent, np.array(joint.Offset, float), list(joint.Channels), joint))
        for child in joint.Children:
            visit(child, idx)
        if not joint.Children:
            out.append((f"{joint.Name}_end", idx, np.array(joint.EndSite, float), [], None))

    visit(root, -1)
    return out


def _read_frames(path: Path, n_channels: int) -> tuple[np.ndarray, float]:
    """The MOTION block as a (frames × channels) array and the frame time.

    Every frame row must hold exactly ``n_channels`` finite numbers and there must be exactly as
    many rows as ``Frames:`` announces: a row short by a few values would otherwise shift every
    later channel, and extra or missing rows would be dropped or invented without a word.
    """
    text = path.read_text(errors="replace")
    m = re.search(r"^\s*MOTION\s*$\s*Frames:\s*(\d+)\s*$\s*Frame Time:\s*([-+0-9.eE]+)\s*$", text, re.M)
    if not m:
        raise StimuliError(f"{path}: no 'MOTION / Frames: N / Frame Time: S' block")
    n_frames, frame_time = int(m.group(1)), float(m.group(2))
    if frame_time <= 0:
        raise StimuliError(f"{path}: Frame Time must be > 0, got {frame_time}")
    if n_channels == 0:
        raise StimuliError(f"{path}: the HIERARCHY declares no CHANNELS, so the frames hold nothing to read")
    first_line = text.count("\n", 0, m.end()) + 1  # file line number of the text right after the header
    rows = []
    for offset, line in enumerate(text[m.end():].split("\n")):
        if line.strip():
            rows.append(_frame_row(path, line, first_line + offset, len(rows) + 1, n_channels))
    if len(rows) != n_frames:
        header_line = text.count("\n", 0, m.start(1)) + 1
        raise StimuliError(f"{path}: header announces {n_frames} frames (line {header_line}), the file holds "
                           f"{len(rows)} frame rows")
    return np.array(rows), frame_time


def _frame_row(path: Path, line: str, line_no: int, frame: int, n_channels: int) -> list[float]:
    """One frame row as numbers: exactly ``n_channels`` finite values (StimuliError naming the line)."""
    tokens = line.split()
    if len(tokens) != n_channels:
        raise StimuliError(f"{path}: line {line_no} (frame {frame}) holds {len(tokens)} values, the HIERARCHY "
                           f"declares {n_channels} channels")
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _is_number(t))
        raise StimuliError(f"{path}: line {line_no} (frame {frame}): {bad!r} is not a number") from None
    if not all(np.isfinite(values)):
        bad = next(t for t, v in zip(tokens, values) if not np.isfinite(v))
        raise StimuliError(f"{path}: line {line_no} (frame {frame}): {bad!r} is not a finite number")
    return values


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _channel_line(path: Path, joint: str) -> str:
    """'line N' of the CHANNELS declaration of ``joint`` (for messages; '' when not found)."""
    lines = path.read_text(errors="replace").split("\n")
    for i, line in enumerate(lines):
        if line.split()[:2] in (["ROOT", joint], ["JOINT", joint]):
            for k in range(i + 1, len(lines)):
                if lines[k].split()[:1] == ["CHANNELS"]:
                    return f"line {k + 1}, "
    return ""


def _channel_rotations(frames: np.ndarray, joints: list, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Local quaternions (T×J×4) and root translation (T×3) from the channel columns."""
    t = frames.shape[0]
    rot = np.tile(quat.IDENTITY, (t, len(joints), 1))
    root = np.zeros((t, 3))
    col = 0
    for j, (name, parent, offset, channels, _) in enumerate(joints):
        order, rcols = "", []
        for ch in channels:
            c = ch.lower()
            if c in ("xrotation", "yrotation", "zrotation"):
                order += c[0].upper()
                rcols.append(col)
            elif c in ("xposition", "yposition", "zposition"):
                # Only the root's translation moves the body; other position channels repeat offsets.
                if parent == -1:
                    root[:, "xyz".index(c[0])] = frames[:, col]
            else:
                raise StimuliError(f"{path}: {_channel_line(path, name)}joint {name!r} has unknown channel {ch!r} "
                                   "(expected Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation)")
            col += 1
        if len(order) == 3:
            rot[:, j] = quat.from_euler(frames[:, rcols], order)
        elif order:
            raise StimuliError(f"{path}: joint {name!r} has {len(order)} rotation channels, expected 3")
    return rot, root


def _unit_scale(height_units: float, height_m: float | None) -> tuple[float, str]:
    """Metres per file unit: from a known body height, else from a recognised unit range."""
    if height_m is not None:
        return height_m / height_units, "scaled to given height"
    for lo, hi, scale, unit in UNIT_RANGES:
        if lo <= height_units <= hi:
            return scale, unit
    return DEFAULT_HEIGHT_M / height_units, f"unknown units, scaled to {DEFAULT_HEIGHT_M} m"


def skeleton_stature(motion: Motion) -> float:
    """Standing height of a y-up skeleton in its own units.

    The larger of the rest pose's vertical extent and twice the hip-joint height (hip joint centres
    sit at about half the stature, Winter 2009); many files end the head bone well below the crown.
    """
    rest = motion.rest_positions()
    roles = motion.metadata.get("roles", {})
    floor = rest[:, 1].min()
    hips = [rest[motion.index(roles[r]), 1] - floor for r in ("l_hip", "r_hip") if r in roles]
    return float(max(np.ptp(rest[:, 1]), 2.0 * np.mean(hips) if hips else 0.0))


def _to_y_up(motion: Motion, roles: dict[str, str]) -> Motion:
    """Rotate a z-up (or x-up) skeleton so that the pelvis→head direction is +y."""
    rest = motion.rest_positions()
    up_role = "head" if "head" in roles else "chest" if "chest" in roles else None
    if up_role is None:
        return motion
    up = rest[motion.index(roles[up_role])] - rest[motion.index(roles["pelvis"])]
    axis = int(np.argmax(np.abs(up)))
    if axis == 1 and up[1] > 0:
        return motion
    target = np.zeros(3)
    target[axis] = np.sign(up[axis])
    c = quat.between(target, np.array([0.0, 1.0, 0.0]))
    return _conjugate(motion, c)


def _conjugate(motion: Motion, c: np.ndarray) -> Motion:
    """The same motion seen in a world rotated by ``c``: offsets c·o, rotations c q c⁻¹."""
    rot = quat.mul(quat.mul(c, motion.rotations), quat.inv(c))
    return motion.replace(offsets=quat.rotate(c, motion.offsets), rotations=rot,
                          root_translation=quat.rotate(c, motion.root_translation))


def _drop_reference_frame(motion: Motion) -> tuple[Motion, bool]:
    """Drop frame 0 when it is a reference pose far from the motion (converted CMU files)."""
    if motion.n_frames < 3:
        return motion, False
    first = quat.angle(quat.mul(quat.inv(motion.rotations[0]), motion.rotations[1])).max()
    second = quat.angle(quat.mul(quat.inv(motion.rotations[1]), motion.rotations[2])).max()
    if first > np.radians(20) and first > 10 * max(second, 1e-3):
        return motion.slice(1), True
    return motion, False


def read_bvh(path: str | Path, mapping: str | Path | None = None, height_m: float | None = None,
             drop_reference: bool = True) -> Motion:
    """Import a BVH file as a :class:`Motion` in metres, y-up, with joint roles detected.

    Parameters
    ----------
    path : the ``.bvh`` file.
    mapping : optional YAML/JSON ``{role: joint}`` file for namings that are not recognised.
    height_m : body height of the performer; scales the skeleton (else units are recognised).
    drop_reference : drop a leading reference pose (T-pose) frame.
    """
    import bvhio

    path = Path(path)
    if not path.is_file():
        raise StimuliError(f"{path}: BVH file not found")
    head = path.read_text(errors="replace")
    # bvhio reads past the end of a truncated hierarchy forever: check the two sections first.
    if not head.lstrip().startswith("HIERARCHY") or not re.search(r"^\s*MOTION\s*$", head, re.M):
        raise StimuliError(f"{path}: not a readable BVH file (expected a HIERARCHY section followed by MOTION)")
    try:
        container = bvhio.readAsBvh(str(path), loadKeyFrames=False)
    except (SyntaxError, ValueError, IndexError, UnicodeDecodeError) as exc:
        line = exc.args[1][1] if isinstance(exc, SyntaxError) and len(exc.args) > 1 else "?"
        raise StimuliError(f"{path}: not a readable BVH file (line {line}: {exc.args[0] if exc.args else exc})") from None
    joints = _flatten(container.Root)
    n_channels = sum(len(j[3]) for j in joints)
    frames, frame_time = _read_frames(path, n_channels)
    rot, root = _channel_rotations(frames, joints, path)
    names = [j[0] for j in joints]
    detected = load_mapping(mapping, names) if mapping else detect_roles(names, where=str(path))
    fps = 1.0 / frame_time
    # ".0083333" means 120 Hz: snap rates within 0.01 % of an integer.
    fps = float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps
    motion = Motion(fps=fps, joint_names=names, parents=np.array([j[1] for j in joints]),
                    offsets=np.stack([j[2] for j in joints]), rotations=rot, root_translation=root,
                    metadata={"source": f"bvh:{path.name}", "naming": detected["naming"], "roles": detected["roles"]})
    motion, dropped = _drop_reference_frame(motion) if drop_reference else (motion, False)
    motion = _to_y_up(motion, detected["roles"])
    stature = skeleton_stature(motion)
    scale, unit = _unit_scale(stature, height_m)
    motion = motion.replace(offsets=motion.offsets * scale, root_translation=motion.root_translation * scale)
    motion.metadata.update(unit=unit, unit_scale=scale, dropped_reference_frame=dropped,
                           source_height_m=float(stature * scale))
    return motion


def _fmt(values) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def write_bvh(motion: Motion, path: str | Path, order: str = "ZYX", scale: float = 1.0) -> Path:
    """Export a motion as BVH (root: 6 channels, other joints: 3 rotation channels in ``order``).

    Leaf joints named ``*_end`` become End Sites; other leaves get a short End Site so that the
    file opens in Blender and other tools. ``scale`` multiplies lengths (100 for centimetres).
    """
    path = Path(path)
    order = order.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise StimuliError(f"write_bvh: order must be a permutation of XYZ, got {order!r}")
    lines = ["HIERARCHY"]
    written: list[int] = []

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        kids = motion.children(j)
        keyword = "ROOT" if j == 0 else "JOINT"
        lines.append(f"{pad}{keyword} {motion.joint_names[j]}")
        lines.append(f"{pad}{{")
        offset = np.zeros(3) if j == 0 else motion.offsets[j] * scale
        lines.append(f"{pad}\tOFFSET {_fmt(offset)}")
        rch = " ".join(f"{a}rotation" for a in order)
        lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rch}" if j == 0 else f"{pad}\tCHANNELS 3 {rch}")
        written.append(j)
        ends = [k for k in kids if not motion.children(k) and motion.joint_names[k].endswith("_end")]
        for k in kids:
            if k not in ends:
                emit(k, depth + 1)
        if not kids or ends:
            tip = motion.offsets[ends[0]] * scale if ends else 0.1 * offset
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {_fmt(tip)}", f"{pad}\t}}"])
        lines.append(f"{pad}}}")

    emit(0, 0)
    euler = quat.to_euler(motion.rotations[:, written], order)
    body = np.concatenate([motion.root_translation * scale, euler.reshape(motion.n_frames, -1)], axis=1)
    lines += ["MOTION", f"Frames: {motion.n_frames}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    lines += [_fmt(row) for row in body]
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path
