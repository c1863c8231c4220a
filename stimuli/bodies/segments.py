"""Body segments: SPEC §3 Table 1 (Vyas et al. 2023, appendix) on an Anny body, plus mesh-based values.

Each segment runs from a proximal to a distal joint (Anny bone heads, project frame). Table-based
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

# Proximal and distal joints (bone heads; "{s}" is the side). "top_of_head" is the highest vertex
# above the head bone; "hip_centre" the midpoint of the two hip joints.
JOINTS = {
    "pelvis": ("spine04", "hip_centre"),
    "spine": ("spine04", "neck01"),
    "head": ("neck01", "top_of_head"),
    "upper_arm": ("upperarm01.{s}", "lowerarm01.{s}"),
    "lower_arm": ("lowerarm01.{s}", "wrist.{s}"),
    "hand": ("wrist.{s}", "finger3-1.{s}"),
    "upper_leg": ("upperleg01.{s}", "lowerleg01.{s}"),
    "lower_leg": ("lowerleg01.{s}", "foot.{s}"),
    "foot": ("foot.{s}", "toe2-1.{s}"),
}

# Which segment each Anny bone's flesh belongs to (first matching pattern wins).
_BONE_PATTERNS = (
    (r"^(root|pelvis\.|spine05)", "pelvis"),
    (r"^(spine0[1-4]|clavicle|shoulder|breast)", "spine"),
    (r"^(neck|head|eye|jaw|tongue|special|oris|levator|temporalis|risorius|orbicularis)", "head"),
    (r"^upperarm", "upper_arm"),
    (r"^lowerarm", "lower_arm"),
    (r"^(wrist|finger|metacarpal|thumb)", "hand"),
    (r"^upperleg", "upper_leg"),
    (r"^lowerleg", "lower_leg"),
    (r"^(foot|toe)", "foot"),
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


def bone_segment(bone: str) -> tuple[str, str]:
    """(segment name, side) for an Anny bone name.

    >>> bone_segment("lowerleg02.L")
    ('lower_leg', 'L')
    >>> bone_segment("spine03")
    ('spine', '')
    """
    side = bone[-1] if re.search(r"\.[LR]$", bone) else ""
    for pattern, segment in _BONE_PATTERNS:
        if re.match(pattern, bone):
            return segment, side if segment not in ("pelvis", "spine", "head") else ""
    raise ValueError(f"Anny bone {bone!r} has no segment; add it to stimuli.bodies.segments._BONE_PATTERNS")


def segment_labels() -> list[str]:
    """All segment labels in table order: pelvis, spine, head, then L/R limbs."""
    labels = []
    for name in SEGMENT_ORDER:
        labels += [name] if name in ("pelvis", "spine", "head") else [f"{name}.L", f"{name}.R"]
    return labels


def face_segments(faces: np.ndarray, weights: np.ndarray, indices: np.ndarray, bone_names: list[str]) -> np.ndarray:
    """Segment index (into :func:`segment_labels`) of every triangle: the segment with most skinning weight."""
    labels = segment_labels()
    bone_to_seg = np.array([labels.index(_label(*bone_segment(b))) for b in bone_names])
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


def segment_joint(name: str, heads: np.ndarray, bone_names: list[str], vertices: np.ndarray) -> np.ndarray:
    """Position of a segment end: a bone head, the hip centre, or the top of the head."""
    if name == "hip_centre":
        return 0.5 * (heads[bone_names.index("upperleg01.L")] + heads[bone_names.index("upperleg01.R")])
    if name == "top_of_head":
        head = heads[bone_names.index("head")]
        return np.array([head[0], vertices[:, 1].max(), head[2]])
    return heads[bone_names.index(name)]


def build_segments(weight_kg: float, heads, bone_names, vertices, faces, face_seg, density: float) -> list[Segment]:
    """The segment table of one body (project frame)."""
    labels = segment_labels()
    volumes, centroids = split_volumes(vertices, faces, face_seg, len(labels))
    rows = []
    for i, label in enumerate(labels):
        name, _, side = label.partition(".")
        prox_name, dist_name = (j.format(s=side) for j in JOINTS[name])
        proximal = segment_joint(prox_name, heads, bone_names, vertices)
        distal = segment_joint(dist_name, heads, bone_names, vertices)
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
