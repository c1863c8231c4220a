"""One call for all motion metrics of a clip, on the skeleton or on a body's skinned mesh.

``motion_quality(motion)`` uses the skeleton's sole points; ``motion_quality(motion, body)``
skins the motion on the body (``Body.skin``) and measures Penetrate/Float/Skate on the mesh
(lowest vertex; the vertices of each foot's sole region for Float), Skate on the feet's
heel/ball/toe-tip points (HUMOS uses the foot joints),
with the centre of mass from Winter's segment masses on the rig's joints.
"""

from __future__ import annotations

import numpy as np

from stimuli.motion.footfix import sole_positions
from stimuli.motion.metrics import gait_metrics, plausibility_from_joints, plausibility_from_mesh, segment_com

FOOT_REGION_M = 0.06  # rest-mesh vertices this low belong to a foot's sole region
MAX_FOOT_VERTICES = 150


def foot_vertex_indices(body, max_per_foot: int = MAX_FOOT_VERTICES) -> dict[str, np.ndarray]:
    """Per side, indices of rest vertices of the sole region (evenly subsampled)."""
    v = np.asarray(body.vertices, float)
    out = {}
    for s, sign in (("l", 1.0), ("r", -1.0)):
        idx = np.flatnonzero((v[:, 1] < FOOT_REGION_M) & (v[:, 0] * sign > 0.0))
        step = max(1, len(idx) // max_per_foot)
        out[s] = idx[::step]
    return out


def motion_quality(motion, body=None) -> dict:
    """Gait figures and plausibility metrics; mesh-based when ``body`` is given."""
    if body is None:
        return {**gait_metrics(motion), **plausibility_from_joints(motion), "measured_on": "skeleton"}
    from stimuli.motion.retarget import mesh_sole_points

    pts = mesh_sole_points(body)
    verts = np.asarray(body.skin(motion.rotations, motion.root_translation), float)
    belt = float(motion.metadata.get("belt_speed_mps", 0.0)) if motion.metadata.get("treadmill") else 0.0
    grot, gpos = motion.global_transforms()
    # Skating is judged on the feet's heel/ball/toe-tip points (HUMOS: the foot joints).
    anatomical = {s: sole_positions(grot, gpos, pts[s]) for s in ("l", "r")}
    plaus = plausibility_from_mesh(verts, foot_vertex_indices(body), segment_com(motion, gpos), motion.fps, belt,
                                   periodic=bool(motion.metadata.get("looped")), skate_points=anatomical)
    return {**gait_metrics(motion, pts), **plaus, "measured_on": "mesh"}
