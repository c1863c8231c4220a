"""One call for all motion metrics of a clip, on the skeleton or on a body's skinned mesh.

``motion_quality(motion)`` uses the skeleton's sole points and joints; ``motion_quality(motion,
body)`` skins the motion on the body (``Body.skin``; the motion must be on the body's rig) and
measures Penetrate on the lowest vertex, Float, the PhysDiff/PHC skate and the base of support on
every vertex of each foot's sole region; the HUMOS skate on the rig's foot joints (HUMOS uses the
SMPL foot joints), the zero-moment point from Winter's segment masses on the rig's joints
(definitions: :mod:`stimuli.motion.metrics`).
"""

from __future__ import annotations

import numpy as np

from stimuli.motion.metrics import gait_metrics, plausibility_from_joints, plausibility_from_mesh

FOOT_REGION_M = 0.06  # rest-mesh vertices this low belong to a foot's sole region


def foot_vertex_indices(body) -> dict[str, np.ndarray]:
    """Per side, indices of every rest vertex of the sole region (below 6 cm): the whole sole, not
    a subsample (a sampled sole made the base of support ragged)."""
    v = np.asarray(body.vertices, float)
    return {s: np.flatnonzero((v[:, 1] < FOOT_REGION_M) & (v[:, 0] * sign > 0.0))
            for s, sign in (("l", 1.0), ("r", -1.0))}


def motion_quality(motion, body=None) -> dict:
    """Gait figures and plausibility metrics; mesh-based when ``body`` is given."""
    if body is None:
        return {**gait_metrics(motion), **plausibility_from_joints(motion), "measured_on": "skeleton"}
    from stimuli.motion.retarget import mesh_sole_points

    verts = np.asarray(body.skin(motion.rotations, motion.root_translation), float)
    plaus = plausibility_from_mesh(verts, foot_vertex_indices(body), motion)
    return {**gait_metrics(motion, mesh_sole_points(body)), **plaus, "measured_on": "mesh"}
