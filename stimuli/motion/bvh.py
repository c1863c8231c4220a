"""BVH import and export.

Import reads the hierarchy with ``bvhio`` (its parser checks the syntax and reports the line), then
reads the frames with numpy in one go (bvhio builds one object per joint and frame, far slower) and
converts any channel order to quaternions. It survives what real exporters write:

- **namings**: the known tables (CMU cgspeed, Mixamo, Poser/old CMU, DAZ), else name patterns and
  the tree (:func:`~stimuli.motion.skeleton.pattern_roles`: Character Creator 4, Bandai, 3ds Max
  Biped and CMU 3ds Max names, …), or a mapping file; a message naming the file, the missing roles
  and the joints no role took where neither finds the legs;
- **toe-less feet**: the ankle's End Site is the toe (the foot bone keeps its motion);
- **position channels below the root** (Bandai: a static ``joint_Root`` above the moving ``Hips``):
  the skeleton is re-rooted at the moving joint; constant ones become the bone's offset;
- **the root's OFFSET** is added to its position channels where the feet then stand on the floor
  (Character Creator puts the hip height there);
- **up axis** from the frames (pelvis → head), not from the rest pose, which need not stand;
- **units** from the leg segments' length (m, cm, mm, inches, CMU's 0.45-inch unit), else scaled;
- **a T/A-pose ease-in**: leading frames whose arms are abducted beyond the rest of the capture, and
  the blend out of them, are dropped, and the metadata says so (``dropped_lead_frames``,
  ``import_notes``, which ``motion import`` prints);
- CRLF or LF line endings, any frame rate.

End sites become leaf joints named ``<parent>_end`` (they give toe tips and head tops).

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
from stimuli.motion.skeleton import ancestors, detect_roles, leg_length, load_mapping

# File unit → metres, chosen by the skeleton's stature (in file units) falling in the range: metres,
# centimetres, millimetres, inches (1.2–2.4 m) and the CMU ASF unit (0.45 in: 1/0.45 in = 0.056444 m,
# the unit of the cgspeed CMU conversions; 1.0–2.4 m).
UNIT_RANGES = ((1.0, 2.4, 1.0, "m"), (100.0, 240.0, 0.01, "cm"), (1000.0, 2400.0, 0.001, "mm"),
               (47.0, 95.0, 0.0254, "in"), (17.7, 42.5, 0.0254 / 0.45, "cmu"))
# Hip-joint centre height over stature (Winter 2009's segment table: 0.530 at the greater
# trochanter; the joint centre sits lower): the legs' length times 2 is the stature estimate.
LEG_OVER_STATURE = 0.5
DEFAULT_HEIGHT_M = 1.75  # assumed body height when the units cannot be recognised


def _flatten(root, names: list[str] | None = None) -> list[tuple[str, int, np.ndarray, list[str], object]]:
    """Depth-first list of (name, parent index, offset, channels, bvhio joint), end sites included.

    ``names`` (the joints' names in file order, :func:`_joint_names`) replace bvhio's, which stop at
    the first space: 3ds Max Biped files name their joints "Bip01 L Thigh". Each must start with
    bvhio's name, else bvhio's are kept.
    """
    out: list = []
    order = iter(names or [])

    def visit(joint, parent: int) -> None:
        idx = len(out)
        name = next(order, joint.Name)
        name = name if name.split()[:1] == [joint.Name] else joint.Name
        out.append((name, parent, np.array(joint.Offset, float), list(joint.Channels), joint))
        for child in joint.Children:
            visit(child, idx)
        if not joint.Children:
            out.append((f"{name}_end", idx, np.array(joint.EndSite, float), [], None))

    visit(root, -1)
    return out


def _joint_names(text: str) -> list[str]:
    """The ROOT/JOINT names of a BVH hierarchy in file (depth-first) order, spaces kept.

    >>> _joint_names("HIERARCHY\\nROOT Bip01\\n{\\n JOINT Bip01 L Thigh\\r\\n")
    ['Bip01', 'Bip01 L Thigh']
    """
    hierarchy = text.split("MOTION", 1)[0]
    return [m.group(2) for m in re.finditer(r"^\s*(ROOT|JOINT)[ \t]+([^\r\n]*?)\s*$", hierarchy, re.M)]


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


def _channel_rotations(frames: np.ndarray, joints: list, path: Path) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Local quaternions (T×J×4) and the position channels of every joint that has them ({j: T×3})."""
    t = frames.shape[0]
    rot = np.tile(quat.IDENTITY, (t, len(joints), 1))
    translations: dict[int, np.ndarray] = {}
    col = 0
    for j, (name, parent, offset, channels, _) in enumerate(joints):
        order, rcols = "", []
        for ch in channels:
            c = ch.lower()
            if c in ("xrotation", "yrotation", "zrotation"):
                order += c[0].upper()
                rcols.append(col)
            elif c in ("xposition", "yposition", "zposition"):
                translations.setdefault(j, np.zeros((t, 3)))[:, "xyz".index(c[0])] = frames[:, col]
            else:
                raise StimuliError(f"{path}: {_channel_line(path, name)}joint {name!r} has unknown channel {ch!r} "
                                   "(expected Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation)")
            col += 1
        if len(order) == 3:
            rot[:, j] = quat.from_euler(frames[:, rcols], order)
        elif order:
            raise StimuliError(f"{path}: joint {name!r} has {len(order)} rotation channels, expected 3")
    return rot, translations


def _channels_replace_offsets(offsets: np.ndarray, translations: dict[int, np.ndarray]) -> bool:
    """Whether a file's non-root position channels replace the OFFSET (else they add to it).

    Exporters disagree: Bandai writes each bone's translation in its channels (equal to the OFFSET
    where the bone does not move; the moving hips then hold absolute values), others write a change
    added to the OFFSET (zeros). The joints that do not move tell which: their channels equal
    either the OFFSET or zero. Without such a joint they add (the usual reading).

    >>> off = np.array([[0.0, 0, 0], [0, 90, 0], [10, 0, 0]])
    >>> _channels_replace_offsets(off, {1: np.array([[1.0, 89, 0], [1, 88, 0]]), 2: np.array([[10.0, 0, 0]] * 2)})
    True
    """
    votes = []
    for j, tr in translations.items():
        size = np.linalg.norm(offsets[j])
        if j == 0 or size == 0 or np.ptp(tr, axis=0).max() > 1e-6 * size:
            continue
        votes.append(bool(np.linalg.norm(tr[0] - offsets[j]) < np.linalg.norm(tr[0])))
    return bool(votes) and sum(votes) * 2 >= len(votes)


def _reroot(names: list[str], parents: np.ndarray, offsets: np.ndarray, rot: np.ndarray,
            translations: dict[int, np.ndarray]) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                          list[str]]:
    """Skeleton whose only moving translation is the root's (the Motion contract).

    Non-root position channels that stay constant become the bone's offset. When a joint below
    the root moves (Bandai: a static ``joint_Root`` above the animated ``Hips``), the skeleton is
    re-rooted there: its world rotation and position (through the joints above) become the root's,
    and the joints above it, which carry nothing but that transform, are dropped (returned by name).
    """
    offsets = offsets.copy()
    t = rot.shape[0]
    replace = _channels_replace_offsets(offsets, translations)
    local = {j: tr if replace else offsets[j] + tr for j, tr in translations.items() if j > 0}
    size = max(float(np.abs(offsets).max()), 1e-9)
    moving = [j for j, tr in local.items() if np.ptp(tr, axis=0).max() > 1e-4 * size]
    for j, tr in local.items():
        offsets[j] = np.median(tr, axis=0)
    root_t = translations.get(0, np.zeros((t, 3)))
    if not moving:
        return names, parents, offsets, rot, root_t, []
    top = min(moving)   # depth-first order: the first moving joint is an ancestor of, or beside, the others
    chain = [top]
    while parents[chain[-1]] > 0:
        chain.append(int(parents[chain[-1]]))
    chain.reverse()
    g, pos = rot[:, 0], root_t + offsets[0]
    for k in chain:
        pos = pos + quat.rotate(g, local.get(k, np.broadcast_to(offsets[k], (t, 3))))
        g = quat.mul(g, rot[:, k])
    keep = [top] + [k for k in range(top + 1, len(names)) if top in ancestors(k, parents)]
    index = {old: new for new, old in enumerate(keep)}
    new_rot = rot[:, keep].copy()
    new_rot[:, 0] = g
    new_parents = np.array([-1] + [index[int(parents[k])] for k in keep[1:]])
    new_offsets = offsets[keep].copy()
    new_offsets[0] = 0.0
    dropped = [names[k] for k in range(len(names)) if k not in index]
    return [names[k] for k in keep], new_parents, new_offsets, new_rot, pos, dropped


def _unit_scale(height_units: float, height_m: float | None) -> tuple[float, str]:
    """Metres per file unit: from a known body height, else from a recognised unit range."""
    if height_m is not None:
        return height_m / height_units, "scaled to given height"
    for lo, hi, scale, unit in UNIT_RANGES:
        if lo <= height_units <= hi:
            return scale, unit
    return DEFAULT_HEIGHT_M / height_units, f"unknown units, scaled to {DEFAULT_HEIGHT_M} m"


def skeleton_stature(motion: Motion) -> float:
    """Standing height of a y-up skeleton in its own units: twice the legs' length (:func:`leg_length`;
    hip-joint centres sit at about half the stature, Winter 2009). From the segment lengths, not the
    rest pose: rest poses lie (CC4's bones all point along +y, legs may be splayed) and many files
    end the head bone well below the crown."""
    return leg_length(motion) / LEG_OVER_STATURE


def _to_y_up(motion: Motion, roles: dict[str, str]) -> Motion:
    """Rotate a z-up (or x-up) capture so that the pelvis→head direction is +y.

    The direction is the median over the frames, not the rest pose's: a rig's rest pose need not
    stand (CC4's bones all lie along +y; a root rotated −90° about x stands the body up only in the
    frames).
    """
    up_role = "head" if "head" in roles else "chest" if "chest" in roles else None
    if up_role is None:
        return motion
    pos = motion.positions()
    up = np.median(pos[:, motion.index(roles[up_role])] - pos[:, motion.index(roles["pelvis"])], axis=0)
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


# A leading frame is a rest/T/A pose, or blends from one, when its arms are abducted this far
# beyond the clip's own range (99th percentile of the frames after the first quarter) and at least
# this far from the body: a T-pose is at 90°, an A-pose at 40–50°, a walk's arms at 0–20°.
EASE_IN_MARGIN_DEG = 15.0
EASE_IN_MIN_DEG = 30.0


def arm_abduction(motion: Motion) -> np.ndarray:
    """Mean lateral elevation of the two upper arms per frame, degrees (0 = hanging, 90 = T-pose).

    The elevation is the upper arm's angle out of the body's sagittal plane, the plane's normal
    being the hip line (right hip → left hip), so swinging the arms forward and back does not count.
    """
    roles = motion.metadata["roles"]
    pos = motion.positions()
    lateral = pos[:, motion.index(roles["l_hip"])] - pos[:, motion.index(roles["r_hip"])]
    lateral /= np.linalg.norm(lateral, axis=1, keepdims=True)
    out = []
    for s, sign in (("l", 1.0), ("r", -1.0)):
        arm = pos[:, motion.index(roles[f"{s}_elbow"])] - pos[:, motion.index(roles[f"{s}_shoulder"])]
        arm /= np.maximum(np.linalg.norm(arm, axis=1, keepdims=True), 1e-12)
        out.append(np.degrees(np.arcsin(np.clip(sign * np.sum(arm * lateral, axis=1), -1, 1))))
    return np.mean(out, axis=0)


def ease_in_frames(motion: Motion) -> int:
    """How many leading frames are a rest/T/A pose or the blend out of one (0 if none).

    The frames from the start whose arm abduction (:func:`arm_abduction`) lies beyond the clip's
    own range, plus the following frames while the arms still come down faster than they ever
    move in the rest of the clip (the tail of a blend). Real motion is never dropped: a frame
    within the clip's range that is not still falling out of a T-pose stops the count.
    """
    roles = motion.metadata.get("roles", {})
    if motion.n_frames < 8 or not all(f"{s}_{r}" in roles for s in "lr" for r in ("shoulder", "elbow", "hip")):
        return 0
    a = arm_abduction(motion)
    ref = a[motion.n_frames // 4:]
    high = np.percentile(ref, 99)
    limit = max(high + EASE_IN_MARGIN_DEG, EASE_IN_MIN_DEG)
    n = 0
    while n < motion.n_frames // 4 and a[n] > limit:
        n += 1
    if n == 0:
        return 0
    fastest = np.percentile(np.abs(np.diff(ref)), 99)
    while n < motion.n_frames // 4 and a[n] > high and a[n - 1] - a[n] > 2.0 * fastest:
        n += 1
    return n


def _root_offset_needed(motion: Motion) -> bool:
    """Whether the root's OFFSET must be added to its position channels (CC4 puts the hip height there).

    BVH readers disagree on the root's OFFSET; the floor decides: the feet of a capture stand on
    y = 0, so the reading whose lowest foot point is nearer 0 is the right one.
    """
    if not np.any(motion.offsets[0]):
        return False
    roles = motion.metadata["roles"]
    feet = [motion.index(roles[f"{s}_{r}"]) for s in "lr" for r in ("ankle", "toe") if f"{s}_{r}" in roles]
    low = motion.positions()[:, feet, 1].min()
    return abs(low + motion.offsets[0][1]) < abs(low)


def read_bvh(path: str | Path, mapping: str | Path | None = None, height_m: float | None = None,
             drop_reference: bool = True) -> Motion:
    """Import a BVH file as a :class:`Motion` in metres, y-up, with joint roles detected.

    Parameters
    ----------
    path : the ``.bvh`` file.
    mapping : optional YAML/JSON ``{role: joint}`` file for namings that are not recognised.
    height_m : body height of the performer; scales the skeleton (else units are recognised).
    drop_reference : drop the leading rest/T/A-pose frames and the blend out of them
        (:func:`ease_in_frames`).
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
    joints = _flatten(container.Root, _joint_names(head))
    n_channels = sum(len(j[3]) for j in joints)
    frames, frame_time = _read_frames(path, n_channels)
    rot, translations = _channel_rotations(frames, joints, path)
    names, parents, offsets, rot, root, dropped_joints = _reroot(
        [j[0] for j in joints], np.array([j[1] for j in joints]), np.stack([j[2] for j in joints]), rot, translations)
    detected = load_mapping(mapping, names) if mapping else detect_roles(names, where=str(path), parents=parents)
    fps = 1.0 / frame_time
    # ".0083333" means 120 Hz: snap rates within 0.01 % of an integer.
    fps = float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps
    motion = Motion(fps=fps, joint_names=names, parents=parents, offsets=offsets, rotations=rot, root_translation=root,
                    metadata={"source": f"bvh:{path.name}", "naming": detected["naming"], "roles": detected["roles"]})
    notes = []
    if dropped_joints:
        notes.append(f"re-rooted at {names[0]} (the joint whose position channels move); dropped "
                     f"{', '.join(dropped_joints)} above it")
    motion = _to_y_up(motion, detected["roles"])
    offset_added = _root_offset_needed(motion)
    if offset_added:
        motion = motion.replace(root_translation=motion.root_translation + motion.offsets[0])
        notes.append(f"root {names[0]}'s OFFSET added to its position channels (the feet stand on the floor)")
    n_lead = ease_in_frames(motion) if drop_reference else 0
    if n_lead:
        notes.append(f"dropped the first {n_lead} frame(s) ({n_lead / fps:.3f} s): a rest/T-pose or the blend "
                     "out of one (arms abducted beyond the rest of the capture)")
        motion = motion.slice(n_lead)
    stature = skeleton_stature(motion)
    scale, unit = _unit_scale(stature, height_m)
    motion = motion.replace(offsets=motion.offsets * scale, root_translation=motion.root_translation * scale)
    motion.metadata.update(unit=unit, unit_scale=scale, dropped_reference_frame=bool(n_lead),
                           dropped_lead_frames=n_lead, root_offset_added=offset_added,
                           source_height_m=float(stature * scale), import_notes=notes)
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
