"""Body segments: SPEC §3 Table 1 (Vyas et al. 2023, appendix) on an Anny body, plus mesh-based values.

Each segment runs from a proximal to a distal joint (bone heads, project frame; the joints of each
skeleton — Anny's, SMPL-X's — are in its ``SkeletonProfile``). Table-based
values: mass m′ = W · X_w and centre of mass c′ = c + l · X_l · u, where c is the segment's
geometric centre (midpoint of the two joints), l its length and u the unit vector from the
proximal to the distal joint (so a negative X_l moves the CoM towards the proximal joint).
Volume-based values split the closed mesh into segments by the skinning weights (each triangle
goes to the segment of the bones that move it most), close every piece with caps at the cuts
and integrate signed tetrahedra: the pieces' volumes add up exactly to the body's volume.

Table 1 gives no weight factor for the pelvis: its spine factor 0.507 is the whole trunk (with
head 0.073 and the limbs the factors sum to 1), so ``mass_table_kg`` is NaN for the pelvis.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

# (X_w, X_l) of SPEC §3 Table 1; X_w None where the paper gives "–".
TABLE1 = {
    "pelvis": (None, -0.088),
    "head": (0.073, -0.034),
    "spine": (0.507, -0.12),
    "upper_arm": (0.026, 0.013),
    "lower_arm": (0.016, -0.46),
    "hand": (0.007, -0.32),
    "upper_leg": (0.103, -0.128),
    "lower_leg": (0.043, -0.129),
    "foot": (0.015, -0.051),
}
SEGMENT_ORDER = ("pelvis", "spine", "head", "upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot")

@dataclasses.dataclass(frozen=True)
class SkeletonProfile:
    """What segments mean on one skeleton: segment ends, which bones' flesh goes where, landmarks.

    ``joints``: segment → (proximal, distal) joint names with ``{s}`` for the side; besides bone
    names, "hip_centre" (midpoint of ``hip_joints``) and "top_of_head" (highest vertex above
    ``head_joint``). ``bone_patterns``: (regex on the side-less bone name, segment), first match
    wins. Sides are a ".L"/".R" suffix (Anny) or a "left_"/"right_" prefix (SMPL family).
    """

    name: str
    joints: dict
    bone_patterns: tuple
    side_prefix: bool
    hip_joints: tuple
    chest_joint: str
    head_joint: str

    def side_name(self, side: str) -> str:
        return {"L": "left", "R": "right"}[side] if self.side_prefix else side

    def split_side(self, bone: str) -> tuple[str, str]:
        """(bone name without its side, 'L'/'R'/'')."""
        if self.side_prefix:
            m = re.match(r"^(left|right)_(.*)$", bone)
            return (m.group(2), "L" if m.group(1) == "left" else "R") if m else (bone, "")
        m = re.match(r"^(.*)\.([LR])$", bone)
        return (m.group(1), m.group(2)) if m else (bone, "")


ANNY = SkeletonProfile(
    name="anny",
    joints={
        "pelvis": ("spine04", "hip_centre"),
        "spine": ("spine04", "neck01"),
        "head": ("neck01", "top_of_head"),
        "upper_arm": ("upperarm01.{s}", "lowerarm01.{s}"),
        "lower_arm": ("lowerarm01.{s}", "wrist.{s}"),
        "hand": ("wrist.{s}", "finger3-1.{s}"),
        "upper_leg": ("upperleg01.{s}", "lowerleg01.{s}"),
        "lower_leg": ("lowerleg01.{s}", "foot.{s}"),
        "foot": ("foot.{s}", "toe2-1.{s}"),
    },
    bone_patterns=(
        (r"^(root|pelvis$|spine05)", "pelvis"),
        (r"^(spine0[1-4]|clavicle|shoulder|breast)", "spine"),
        (r"^(neck|head|eye|jaw|tongue|special|oris|levator|temporalis|risorius|orbicularis)", "head"),
        (r"^upperarm", "upper_arm"),
        (r"^lowerarm", "lower_arm"),
        (r"^(wrist|finger|metacarpal|thumb)", "hand"),
        (r"^upperleg", "upper_leg"),
        (r"^lowerleg", "lower_leg"),
        (r"^(foot|toe)", "foot"),
    ),
    side_prefix=False, hip_joints=("upperleg01.L", "upperleg01.R"), chest_joint="spine01", head_joint="head",
)

# The SMPL-X joint tree (public joint names, in model order); the "left_/right_" joints are the
# joints at the proximal end of the flesh they move (shoulder = upper arm, hip = thigh).
SMPLX = SkeletonProfile(
    name="smplx",
    joints={
        "pelvis": ("spine1", "hip_centre"),
        "spine": ("spine1", "neck"),
        "head": ("neck", "top_of_head"),
        "upper_arm": ("{s}_shoulder", "{s}_elbow"),
        "lower_arm": ("{s}_elbow", "{s}_wrist"),
        "hand": ("{s}_wrist", "{s}_middle1"),
        "upper_leg": ("{s}_hip", "{s}_knee"),
        "lower_leg": ("{s}_knee", "{s}_ankle"),
        "foot": ("{s}_ankle", "{s}_foot"),
    },
    bone_patterns=(
        (r"^pelvis$", "pelvis"),
        (r"^(spine\d|collar)", "spine"),
        (r"^(neck|head|jaw|eye)", "head"),
        (r"^shoulder$", "upper_arm"),
        (r"^elbow$", "lower_arm"),
        (r"^(wrist|index|middle|pinky|ring|thumb)", "hand"),
        (r"^hip$", "upper_leg"),
        (r"^knee$", "lower_leg"),
        (r"^(ankle|foot)$", "foot"),
    ),
    side_prefix=True, hip_joints=("left_hip", "right_hip"), chest_joint="spine3", head_joint="head",
)

@dataclasses.dataclass(frozen=True)
class Segment:
    """One rigid segment of the physics model, in the project frame (metres, kg)."""

    name: str
    side: str
    proximal: np.ndarray
    distal: np.ndarray
    length_m: float
    x_w: float
    x_l: float
    mass_table_kg: float
    com_geometric: np.ndarray
    com_table: np.ndarray
    volume_m3: float
    mass_volume_kg: float
    com_volume: np.ndarray

    @property
    def label(self) -> str:
        """``upper_leg.L`` style name (sides only for limbs)."""
        return f"{self.name}.{self.side}" if self.side else self.name

    def as_row(self) -> dict[str, object]:
        """Flat dict for tables (vectors split into _x/_y/_z columns)."""
        row = {"segment": self.label, "name": self.name, "side": self.side, "length_m": self.length_m,
               "x_w": self.x_w, "x_l": self.x_l, "mass_table_kg": self.mass_table_kg,
               "volume_m3": self.volume_m3, "mass_volume_kg": self.mass_volume_kg}
        for key in ("proximal", "distal", "com_geometric", "com_table", "com_volume"):
            for axis, value in zip("xyz", getattr(self, key)):
                row[f"{key}_{axis}"] = float(value)
        return row


def bone_segment(bone: str, profile: SkeletonProfile = ANNY) -> tuple[str, str]:
    """(segment name, side) for a bone name of a skeleton.

    >>> bone_segment("lowerleg02.L")
    ('lower_leg', 'L')
    >>> bone_segment("spine03")
    ('spine', '')
    >>> bone_segment("right_elbow", SMPLX)
    ('lower_arm', 'R')
    """
    base, side = profile.split_side(bone)
    for pattern, segment in profile.bone_patterns:
        if re.match(pattern, base):
            return segment, side if segment not in ("pelvis", "spine", "head") else ""
    raise ValueError(f"{profile.name} bone {bone!r} has no segment; add it to its SkeletonProfile.bone_patterns")


def segment_labels() -> list[str]:
    """All segment labels in table order: pelvis, spine, head, then L/R limbs."""
    labels = []
    for name in SEGMENT_ORDER:
        labels += [name] if name in ("pelvis", "spine", "head") else [f"{name}.L", f"{name}.R"]
    return labels


def face_segments(faces: np.ndarray, weights: np.ndarray, indices: np.ndarray, bone_names: list[str],
                  profile: SkeletonProfile = ANNY) -> np.ndarray:
    """Segment index (into :func:`segment_labels`) of every triangle: the segment with most skinning weight.

    ``weights``/``indices``: (V, K) sparse skinning weights and the bones they refer to.
    """
    labels = segment_labels()
    bone_to_seg = np.array([labels.index(_label(*bone_segment(b, profile))) for b in bone_names])
    vertex_seg_weight = np.zeros((weights.shape[0], len(labels)))
    np.add.at(vertex_seg_weight, (np.arange(weights.shape[0])[:, None], bone_to_seg[indices]), weights)
    return np.argmax(vertex_seg_weight[faces].sum(axis=1), axis=1)


def _label(name: str, side: str) -> str:
    return f"{name}.{side}" if side else name


def split_volumes(vertices: np.ndarray, faces: np.ndarray, face_seg: np.ndarray, n_segments: int):
    """Volume (m³) and centroid of each closed mesh piece; caps close the cuts between pieces.

    Returns (volumes (S,), centroids (S, 3)). Caps are fans from the centroid of the boundary
    vertices shared by the two pieces, with opposite orientations on the two sides, so the
    volumes sum to the whole mesh's volume.
    """
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    tet_vol = np.einsum("ij,ij->i", v0, np.cross(v1, v2)) / 6.0
    tet_cen = (v0 + v1 + v2) / 4.0
    seg = [face_seg]
    vols = [tet_vol]
    cens = [tet_cen]
    cap = _caps(vertices, faces, face_seg)
    if cap is not None:
        cap_seg, c, a, b = cap
        cap_vol = np.einsum("ij,ij->i", c, np.cross(b, a)) / 6.0
        seg.append(cap_seg)
        vols.append(cap_vol)
        cens.append((c + a + b) / 4.0)
    seg, vols, cens = np.concatenate(seg), np.concatenate(vols), np.concatenate(cens)
    volume = np.bincount(seg, weights=vols, minlength=n_segments)
    moment = np.stack([np.bincount(seg, weights=vols * cens[:, k], minlength=n_segments) for k in range(3)], 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        centroid = moment / volume[:, None]
    return volume, centroid


def _caps(vertices, faces, face_seg):
    """Cap triangles (segment, centre, a, b) for every directed edge a→b on a cut between pieces."""
    n_v = len(vertices)
    a = faces.reshape(-1)
    b = np.roll(faces, -1, axis=1).reshape(-1)
    edge_seg = np.repeat(face_seg, 3)
    key = a * n_v + b
    order = np.argsort(key)
    rev = np.searchsorted(key[order], b * n_v + a)
    rev = np.clip(rev, 0, len(key) - 1)
    twin = order[rev]
    found = key[twin] == b * n_v + a
    other = np.where(found, edge_seg[twin], edge_seg)
    cut = found & (other != edge_seg)
    if not cut.any():
        return None
    lo, hi = np.minimum(edge_seg[cut], other[cut]), np.maximum(edge_seg[cut], other[cut])
    pair = lo * 1000 + hi
    # Centre of each cut: mean of the vertices on it (the same point for both sides).
    pair_ids, inverse = np.unique(pair, return_inverse=True)
    sums = np.zeros((len(pair_ids), 3))
    counts = np.zeros(len(pair_ids))
    np.add.at(sums, inverse, vertices[a[cut]])
    np.add.at(counts, inverse, 1.0)
    centres = (sums / counts[:, None])[inverse]
    return edge_seg[cut], centres, vertices[a[cut]], vertices[b[cut]]


def segment_joint(name: str, heads: np.ndarray, bone_names: list[str], vertices: np.ndarray,
                  profile: SkeletonProfile = ANNY) -> np.ndarray:
    """Position of a segment end: a bone head, the hip centre, or the top of the head."""
    if name == "hip_centre":
        left, right = profile.hip_joints
        return 0.5 * (heads[bone_names.index(left)] + heads[bone_names.index(right)])
    if name == "top_of_head":
        head = heads[bone_names.index(profile.head_joint)]
        return np.array([head[0], vertices[:, 1].max(), head[2]])
    return heads[bone_names.index(name)]


def build_segments(weight_kg: float, heads, bone_names, vertices, faces, face_seg, density: float,
                   profile: SkeletonProfile = ANNY) -> list[Segment]:
    """The segment table of one body (project frame)."""
    labels = segment_labels()
    volumes, centroids = split_volumes(vertices, faces, face_seg, len(labels))
    rows = []
    for i, label in enumerate(labels):
        name, _, side = label.partition(".")
        prox_name, dist_name = (j.format(s=profile.side_name(side) if side else "") for j in profile.joints[name])
        proximal = segment_joint(prox_name, heads, bone_names, vertices, profile)
        distal = segment_joint(dist_name, heads, bone_names, vertices, profile)
        axis = distal - proximal
        length = float(np.linalg.norm(axis))
        x_w, x_l = TABLE1[name]
        centre = 0.5 * (proximal + distal)
        rows.append(Segment(
            name=name, side=side, proximal=proximal, distal=distal, length_m=length,
            x_w=float("nan") if x_w is None else x_w, x_l=x_l,
            mass_table_kg=float("nan") if x_w is None else weight_kg * x_w,
            com_geometric=centre, com_table=centre + x_l * axis,
            volume_m3=float(volumes[i]), mass_volume_kg=float(volumes[i] * density),
            com_volume=centroids[i],
        ))
    return rows
