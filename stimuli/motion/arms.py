"""Hands and arms on an Anny body: a relaxed hand pose and upper arms kept clear of the torso.

Every motion source leaves Anny's finger bones at their rest orientation (generated gaits, BVH
captures without fingers, averages), and the rest hand is flat with spread fingers: an open palm
in every clip. :func:`relax_hands` curls the fingers into a relaxed cascade (more flexion towards
the little finger, as in a resting hand) and draws them together, once, for any pose whose
fingers carry nothing.

A motion's arm directions come from a skeleton that knows the body's height but not its girth,
so on a heavy torso the upper arm sinks into the flank. :func:`clear_arms` measures, frame by
frame, how deep the upper arm's skin lies inside the torso's (:func:`arm_penetration`) and
abducts the upper arm about the chest's forward axis just enough to clear it, plus a margin:
the added abduction grows with the body's girth at the arm because it is measured on that body.

Both are applied where the renderer receives a figure's pose
(``stimuli.render.clip.render_frames``), so every path — generated, retargeted, averaged,
physics — gets them once.

Two helpers serve the retargeting (``stimuli.motion.retarget``) instead: :func:`clavicle_world`
(the clavicles' motion without the source rig's build) and :func:`elbow_hinge_twist` (the arms'
twist from the plane the capture's elbow bends in, not from the source rig's bone frames).

Examples
--------
>>> from stimuli.bodies.api import fit_body
>>> body = fit_body("M", 1.83, 35.8)
>>> rest = body.rest_pose()[0]
>>> [round(float(f(body.rig, x)[0])) for f in (finger_curl_deg, finger_spread_deg) for x in (rest, relax_hands(body.rig, rest))]
[26, 90, 33, 18]
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial import cKDTree

from stimuli.motion import quat

# Relaxed-hand flexion (degrees) of the proximal, middle and distal phalanx of fingers 2–5 (index to
# little): the cascade of a hand hanging at rest, more flexion towards the little finger. The values
# were chosen and checked by eye on rendered frames (a curled, not clenched, hand), not fitted to data.
FINGER_CURL_DEG = {2: (20.0, 30.0, 12.0), 3: (24.0, 35.0, 14.0), 4: (28.0, 40.0, 16.0), 5: (32.0, 45.0, 18.0)}
THUMB_CURL_DEG = (8.0, 12.0, 10.0)
# Fraction of each proximal phalanx's rest splay from the middle finger that the relaxed hand removes.
FINGER_CLOSE = 0.6
# Upper-arm skin kept at least this far outside the torso's (m).
ARM_CLEARANCE_M = 0.005
# Torso skin that can hold an arm: below the upper-arm joint by this much (higher up the shoulder's
# own skin joins the arm's).
ARMPIT_DROP_M = 0.06
# Where the upper arm's skin meets the armpit's the measure reads up to 0.3 cm on every body, lean
# ones included (skin folding at the seam, not an arm in the flank): shallower is left alone.
SEAM_DEPTH_M = 0.003
# An arm vertex counts as inside the torso when its nearest torso vertex is within this distance and
# it lies along that vertex's normal (lateral offset below the mesh's spacing): far from the flank the
# nearest-vertex sign means nothing.
NEAR_M = 0.06
LATERAL_M = 0.02


def _heads(rig, rotations) -> np.ndarray:
    return rig.forward_kinematics(rotations, np.zeros((len(rotations), 3)))[1]


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _angle_deg(a, b) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.einsum("...i,...i->...", _unit(a), _unit(b)), -1.0, 1.0)))


def _palm_normal(rig, side: str) -> np.ndarray:
    """Unit normal of the rest palm pointing out of the palm (the side the fingers curl to).

    The plane holds the fingers' direction and the knuckle line; of its two normals the palm's is
    the one the thumb's tip lies on (the thumb sits in front of the palm)."""
    h = rig.rest_heads
    wrist = h[rig.index(f"wrist.{side}")]
    index, little = h[rig.index(f"finger2-1.{side}")], h[rig.index(f"finger5-1.{side}")]
    along = 0.5 * (index + little) - wrist
    n = _unit(np.cross(along, index - little))
    thumb = h[rig.index(f"finger1-3.{side}")]
    return n if (thumb - wrist) @ n > 0 else -n


def _finger_chain(rig, side: str, finger: int) -> list[int]:
    return [rig.index(f"finger{finger}-{k}.{side}") for k in (1, 2, 3)]


def _bone_direction(rig, bone: int) -> np.ndarray:
    """Rest direction of a finger bone: to its child's head, or along its parent for the last one."""
    h = rig.rest_heads
    children = np.flatnonzero(rig.parents == bone)
    if len(children):
        return _unit(h[children[0]] - h[bone])
    return _unit(h[bone] - h[rig.parents[bone]])


def relaxed_hand(rig) -> dict[int, np.ndarray]:
    """Local rotations (w-first quaternions, rest-world axes) of the finger bones of a relaxed hand."""
    out = {}
    for side in ("L", "R"):
        n = _palm_normal(rig, side)
        middle = _bone_direction(rig, rig.index(f"finger3-1.{side}"))
        for finger in (1, 2, 3, 4, 5):
            chain = _finger_chain(rig, side, finger)
            curls = THUMB_CURL_DEG if finger == 1 else FINGER_CURL_DEG[finger]
            for k, (bone, curl) in enumerate(zip(chain, curls)):
                d = _bone_direction(rig, bone)
                q = quat.from_axis_angle(_unit(np.cross(d, n)) * np.radians(curl))
                if k == 0 and finger in (2, 4, 5):
                    # Close the splay: turn the proximal phalanx about the palm normal towards the middle finger.
                    flat = _unit(d - (d @ n) * n)
                    mid = _unit(middle - (middle @ n) * n)
                    splay = np.arctan2(np.cross(flat, mid) @ n, flat @ mid)
                    q = quat.mul(q, quat.from_axis_angle(n * FINGER_CLOSE * splay))
                out[bone] = q
    return out


def finger_bones(rig) -> list[int]:
    """Indices of the finger bones (fingers 1–5, three phalanges each, both hands)."""
    return [i for s in ("L", "R") for f in range(1, 6) for i in _finger_chain(rig, s, f)]


def carries_fingers(rig, rotations) -> bool:
    """Whether any finger bone of any frame is off its rest orientation (by more than 0.5°)."""
    q = np.asarray(rotations, float)[:, finger_bones(rig)]
    return bool((np.abs(q[..., 0]) < np.cos(np.radians(0.25))).any())


def relax_hands(rig, rotations) -> np.ndarray:
    """``rotations`` (T, J, 4) with the relaxed hand pose on fingers that carry none (else unchanged)."""
    rot = np.array(rotations, float)
    if carries_fingers(rig, rot):
        return rot
    for bone, q in relaxed_hand(rig).items():
        rot[:, bone] = q
    return rot


def finger_curl_deg(rig, rotations) -> np.ndarray:
    """Per frame, the mean over fingers 2–5 and both hands of the angle between the metacarpal
    (wrist to knuckle) and the middle phalanx: knuckle plus middle-joint flexion (26° on Anny's flat
    rest hand, whose metacarpals and phalanges are not in line)."""
    heads = _heads(rig, rotations)
    out = []
    for s in ("L", "R"):
        w = heads[:, rig.index(f"wrist.{s}")]
        for f in (2, 3, 4, 5):
            a, b, c = (heads[:, i] for i in _finger_chain(rig, s, f))
            out.append(_angle_deg(a - w, c - b))
    return np.mean(out, axis=0)


def finger_spread_deg(rig, rotations) -> np.ndarray:
    """Per frame, the mean over both hands of the angle between the index and little fingers'
    proximal phalanges (how far the fingers fan out)."""
    heads = _heads(rig, rotations)
    out = []
    for s in ("L", "R"):
        i1, i2, _ = _finger_chain(rig, s, 2)
        l1, l2, _ = _finger_chain(rig, s, 5)
        out.append(_angle_deg(heads[:, i2] - heads[:, i1], heads[:, l2] - heads[:, l1]))
    return np.mean(out, axis=0)


@functools.lru_cache(maxsize=1)
def _segment_vertex_sets() -> dict[str, np.ndarray]:
    """Vertices of the torso (spine and pelvis segments) and of each upper arm (Anny topology)."""
    from stimuli.bodies.body import mesh_parts
    from stimuli.bodies.segments import segment_labels

    parts, labels = mesh_parts(), segment_labels()

    def of(names):
        return np.unique(parts["faces"][np.isin(parts["face_seg"], [labels.index(n) for n in names])])

    torso = of(["spine", "pelvis"])
    return {"torso": torso, "L": np.setdiff1d(of(["upper_arm.L"]), torso), "R": np.setdiff1d(of(["upper_arm.R"]), torso)}


def _arm_sets(body) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    sets = _segment_vertex_sets()
    armpit = body.rig.rest_heads[body.rig.index("upperarm01.L"), 1] - ARMPIT_DROP_M
    torso = sets["torso"][body.vertices[sets["torso"], 1] < armpit]
    return torso, {"L": sets["L"], "R": sets["R"]}


def arm_penetration(body, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How deep (m, ≥ 0) each upper arm's skin lies inside the torso's, per frame and side (T, 2: L, R),
    and the deepest vertex's index (T, 2; −1 where none is inside).

    Signed distance of each upper-arm vertex along the outward normal of its nearest torso vertex
    (flank below the armpit), counted where that vertex is near and the arm vertex lies along its normal.
    """
    check = _arm_check(body)
    verts = np.asarray(vertices, float).reshape(-1, body.n_vertices, 3)
    depth, worst = _depths(check, verts[:, check.keep])
    return depth, np.where(worst >= 0, check.keep[worst], -1)


class _ArmCheck:
    """What :func:`arm_penetration` needs of one body, in a subset of its vertices (``keep``: the flank,
    the faces around it and the upper arms): that subset's indices of the flank and arm vertices and of
    the faces around the flank, the (flank × those faces) normal operator, and the subset's skinning
    weights (vertices × bones) — so that a pose is checked without skinning the whole mesh."""

    def __init__(self, body):
        import scipy.sparse

        torso, arms = _arm_sets(body)
        faces = np.asarray(body.faces)
        around = faces[np.isin(faces, torso).any(axis=1)]
        self.keep = np.unique(np.concatenate([around.ravel(), arms["L"], arms["R"]]))
        self.torso = np.searchsorted(self.keep, torso)
        self.arms = {side: np.searchsorted(self.keep, arms[side]) for side in ("L", "R")}
        self.faces = np.searchsorted(self.keep, around)
        on_flank = np.isin(around.ravel(), torso)   # torso is sorted (np.unique, then a mask)
        rows = np.searchsorted(torso, around.ravel()[on_flank])
        cols = np.repeat(np.arange(len(around)), 3)[on_flank]
        self.operator = scipy.sparse.csr_matrix((np.ones(len(rows)), (rows, cols)),
                                                shape=(len(torso), len(around)))
        self.rest = np.asarray(body.vertices, float)[self.keep]
        self.weights = None
        if getattr(body, "skinner", None) is None:   # Anny's skinning: the subset's rows of its weights
            from stimuli.bodies.backend import topology

            topo = topology()
            w, idx = topo["weights"][self.keep], topo["indices"][self.keep]
            self.weights = scipy.sparse.csr_matrix(
                (w.ravel().astype(float), (np.repeat(np.arange(len(self.keep)), w.shape[1]), idx.ravel())),
                shape=(len(self.keep), body.rig.n_bones))

    def skin(self, body, rotations, root_translation) -> np.ndarray:
        """Posed subset vertices (T, S, 3): Anny's linear-blend skinning of the subset alone."""
        if self.weights is None:
            return body.skin(rotations, root_translation)[:, self.keep]
        transforms = body.rig.skinning_transforms(rotations, root_translation)[:, :, :3, :]   # (T, J, 3, 4)
        n = len(transforms)
        blended = (self.weights @ transforms.transpose(1, 0, 2, 3).reshape(body.rig.n_bones, -1))
        blended = blended.reshape(len(self.keep), n, 3, 4)
        return (np.einsum("stij,sj->tsi", blended[..., :3], self.rest) + blended[..., 3].transpose(1, 0, 2))


def _arm_check(body) -> _ArmCheck:
    """The body's :class:`_ArmCheck`, cached on the body (recomputed each call on a frozen one)."""
    cached = getattr(body, "_arm_check", None)
    if cached is None:
        cached = _ArmCheck(body)
        try:
            body._arm_check = cached
        except (AttributeError, TypeError):
            pass
    return cached


def _depths(check: _ArmCheck, verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`arm_penetration` on subset vertices (T, S, 3); the deepest vertex as a subset index."""
    f = check.faces
    face_n = np.cross(verts[:, f[:, 1]] - verts[:, f[:, 0]], verts[:, f[:, 2]] - verts[:, f[:, 0]])   # (T, F, 3)
    normals = (check.operator @ face_n.transpose(1, 0, 2).reshape(len(f), -1)).reshape(len(check.torso), -1, 3)
    normals /= np.maximum(np.linalg.norm(normals, axis=2, keepdims=True), 1e-12)
    both = np.concatenate([check.arms["L"], check.arms["R"]])
    points, flank = verts[:, both], verts[:, check.torso]
    dist, near = np.empty(points.shape[:2]), np.empty(points.shape[:2], int)
    for t in range(len(verts)):   # the flank moves with the pose: one tree per frame (unbalanced: built faster)
        tree = cKDTree(flank[t], balanced_tree=False, compact_nodes=False)
        dist[t], near[t] = tree.query(points[t], distance_upper_bound=NEAR_M)
    near = np.minimum(near, flank.shape[1] - 1)   # none within NEAR_M: inf and an index past the end
    frames = np.arange(len(verts))[:, None]
    n = normals.transpose(1, 0, 2)[frames, near]
    off = points - flank[frames, near]
    signed = np.einsum("tij,tij->ti", off, n)
    lateral = np.linalg.norm(off - signed[..., None] * n, axis=2)
    inside = (dist < NEAR_M) & (lateral < LATERAL_M) & (signed < 0)
    depth = np.zeros((len(verts), 2))
    worst = np.full((len(verts), 2), -1)
    split = len(check.arms["L"])
    for k, part in enumerate((slice(0, split), slice(split, None))):
        masked = np.where(inside[:, part], signed[:, part], np.inf)
        j = np.argmin(masked, axis=1)
        hit = inside[:, part].any(axis=1)
        depth[hit, k] = -masked[hit, j[hit]]
        worst[hit, k] = both[part][j[hit]]
    return depth, worst


def clear_arms(body, rotations, root_translation, clearance_m: float = ARM_CLEARANCE_M, passes: int = 5) -> np.ndarray:
    """``rotations`` (T, J, 4) with each upper arm abducted, frame by frame, just enough to keep its skin
    ``clearance_m`` outside the torso's (:func:`arm_penetration`).

    The abduction turns the upper arm about the chest's forward axis; its angle is the depth over the
    deepest vertex's distance from the shoulder joint, spread over neighbouring frames (a running
    maximum, then smoothed) so the arm does not twitch. Frames already clear are left as they are.
    Only the flank and the arms are skinned, and after each pass only the frames it turned are
    measured again (a frame's skin depends on its own pose alone).
    """
    rig = body.rig
    check = _arm_check(body)
    rot = np.array(rotations, float)
    root = np.asarray(root_translation, float)
    chest = rig.index("spine01")
    verts = check.skin(body, rot, root)
    depth, worst = _depths(check, verts)
    for done in range(passes):
        if depth.max(initial=0.0) <= SEAM_DEPTH_M:
            break
        before = rot.copy()
        grot, heads = rig.forward_kinematics(rot, root)
        for k, (side, sign) in enumerate((("L", 1.0), ("R", -1.0))):
            arm = rig.index(f"upperarm01.{side}")
            need = np.zeros(len(rot))
            hit = (worst[:, k] >= 0) & (depth[:, k] > SEAM_DEPTH_M)
            if not hit.any():
                continue
            reach = np.linalg.norm(verts[hit, worst[hit, k]] - heads[hit, arm], axis=1)
            need[hit] = (depth[hit, k] + clearance_m) / np.maximum(reach, 0.05)
            need = gaussian_filter1d(maximum_filter1d(need, 5, mode="nearest"), 1.0, mode="nearest")
            # World axis: the chest's forward; abduction turns a hanging left arm towards +x.
            forward = np.einsum("tij,j->ti", grot[:, chest], np.array([0.0, 0.0, 1.0]))
            parent = rig.parents[arm]
            axis_parent = np.einsum("tji,tj->ti", grot[:, parent], forward)  # into the parent's axes
            turn = quat.from_axis_angle(_unit(axis_parent) * (sign * need)[:, None])
            rot[:, arm] = quat.mul(turn, rot[:, arm])
        changed = np.flatnonzero((rot != before).any(axis=(1, 2)))
        if done + 1 < passes and len(changed):
            verts[changed] = check.skin(body, rot[changed], root[changed])
            depth[changed], worst[changed] = _depths(check, verts[changed])
    return rot


def shoulder_rise(body, rotations, root_translation) -> np.ndarray:
    """How far (m) the top of each shoulder rises above the neck's base beyond the rest pose's, per
    frame and side (T, 2: L, R): the hump of shrugged shoulders.

    The shoulder top is the rest mesh's skin over the shoulder (outward of the ``shoulder01`` joint,
    inward of the upper-arm joint, above it); its highest point is measured from the posed
    ``neck01`` head.
    """
    rig = body.rig
    verts = body.skin(rotations, root_translation)
    neck = rig.forward_kinematics(rotations, root_translation)[1][:, rig.index("neck01"), 1]
    rest = np.asarray(body.vertices, float)
    out = np.zeros((len(verts), 2))
    for k, side in enumerate(("L", "R")):
        arm = rig.rest_heads[rig.index(f"upperarm01.{side}")]
        inner = rig.rest_heads[rig.index(f"shoulder01.{side}")]
        x = rest[:, 0] * np.sign(arm[0])
        top = np.flatnonzero((x > abs(inner[0])) & (x < abs(arm[0])) & (rest[:, 1] > arm[1]))
        rest_rise = rest[top, 1].max() - rig.rest_heads[rig.index("neck01"), 1]
        out[:, k] = verts[:, top, 1].max(axis=1) - neck - rest_rise
    return out


def clavicle_world(source_grot: np.ndarray, roles: dict[str, int], chest_world: np.ndarray) -> dict[str, np.ndarray]:
    """World rotations (T, 4) of Anny's clavicles, per side ("l", "r"): the target's chest with the
    source clavicle's motion about its clip mean (relative to the source's chest).

    Retargeting the clavicle's direction instead copied the source skeleton's build: a CMU clavicle
    runs from low on the thorax up to the shoulder, 20–27° steeper than Anny's, so every CMU walk
    shrugged Anny's shoulders — the "hump" on heavy bodies, whose shoulder flesh then bulges above
    the neck's base. The shrug and protraction that belong to the gait (a few degrees) are kept.
    ``roles`` without a clavicle or chest leave that side out (its clavicle follows the chest).
    """
    chest = roles.get("chest", roles.get("pelvis"))
    out = {}
    for side in ("l", "r"):
        if f"{side}_clavicle" not in roles or chest is None:
            continue
        relative = quat.mul(quat.inv(source_grot[:, chest]), source_grot[:, roles[f"{side}_clavicle"]])
        about_mean = quat.mul(relative, quat.inv(quat.mean(relative))[None])
        out[side] = quat.mul(chest_world, about_mean)
    return out


# Elbows bent less than this (degrees) leave their bend plane to noise: they do not vote on the twist.
HINGE_MIN_FLEX_DEG = 10.0


def elbow_hinge_twist(upper: np.ndarray, fore: np.ndarray, upper_rest: np.ndarray, fore_rest: np.ndarray,
                      upper_dir: np.ndarray, fore_dir: np.ndarray, forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper-arm and forearm world rotations (T×4 each) turned about their own bones by the one
    fixed twist each that makes the target's elbow flex in the plane the source's arm bends in.

    ``upper``/``fore``: retargeted world rotations (rest-relative, world axes) that already point the
    bones along the source's segments ``upper_dir``/``fore_dir`` (T×3); ``upper_rest``/``fore_rest``:
    the target's rest bone directions; ``forward``: the target's rest forward axis. The target's
    elbow hinge is the rest axis about which the forearm swings forward, cross(upper_rest,
    forward); the source's, per frame, the normal of its shoulder–elbow–wrist plane. The twist is
    their mean angle about the bone over the frames bent at least :data:`HINGE_MIN_FLEX_DEG`
    (weighted by how bent); an arm that never bends that much keeps its twist.

    Why: retargeting copies a bone's twist from the source rig, and rigs disagree about it: Bandai's
    right arm came out twisted 179° against its left, CMU's 29° and CC4's forearms 62° against
    the generator's. The positions were right, but the local elbow rotations of one capture were a
    half turn from another's, so the average of the men's runs (two CMU, two Bandai) swung its right
    forearm from 25° to 176° of flexion where every capture keeps 48-132°.

    >>> t = np.linspace(0.0, 1.0, 5)
    >>> flex = np.radians(30 + 40 * t)                       # a bending arm hanging down, forearm forward
    >>> down, fwd = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    >>> fore_dir = np.stack([0 * t, -np.cos(flex), np.sin(flex)], 1)
    >>> twisted = quat.from_axis_angle(np.array([0.0, np.pi, 0.0]))          # a half turn about the bone
    >>> upper = np.tile(twisted, (5, 1))
    >>> fore = quat.mul(upper, quat.from_axis_angle(flex[:, None] * np.array([1.0, 0, 0])))  # so bent about +x
    >>> u, f = elbow_hinge_twist(upper, fore, down, down, np.tile(down, (5, 1)), fore_dir, fwd)
    >>> bool(np.allclose(quat.rotate(f, down), fore_dir))                   # the bones still point as before
    True
    >>> local = quat.mul(quat.inv(u), f)                   # now a flexion about the hinge, cross(down, fwd) = -x
    >>> (np.round(np.degrees(quat.to_axis_angle(local)), 1) + 0.0)[[0, -1]].tolist()
    [[-30.0, 0.0, 0.0], [-70.0, 0.0, 0.0]]
    """
    bend = np.cross(upper_dir, fore_dir)
    sin_flex = np.linalg.norm(bend, axis=1) / (np.linalg.norm(upper_dir, axis=1) * np.linalg.norm(fore_dir, axis=1))
    weight = np.where(sin_flex >= np.sin(np.radians(HINGE_MIN_FLEX_DEG)), sin_flex, 0.0)
    bend = bend / np.maximum(np.linalg.norm(bend, axis=1, keepdims=True), 1e-12)
    hinge = _unit(np.cross(upper_rest, forward))
    out = []
    for world, rest in ((upper, upper_rest), (fore, fore_rest)):
        axis = _unit(rest)
        if not weight.any():
            out.append(world)
            continue
        h = _unit(hinge - axis * (hinge @ axis))
        seen = quat.rotate(quat.inv(world), bend)          # the source's bend normal in rest axes
        seen = seen - np.outer(seen @ axis, axis)
        angle = np.arctan2(np.cross(h, seen) @ axis, seen @ h)
        twist = np.arctan2((weight * np.sin(angle)).sum(), (weight * np.cos(angle)).sum())
        out.append(quat.mul(world, quat.from_axis_angle(twist * axis)[None]))
    return out[0], out[1]


def natural_pose(body, rotations, root_translation) -> np.ndarray:
    """The pose the renderer draws: relaxed hands (where the motion has none), arms clear of the torso."""
    return clear_arms(body, relax_hands(body.rig, rotations), root_translation)
