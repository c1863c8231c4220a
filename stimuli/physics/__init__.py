"""The COM method: physics-based retargeting with Table-1 segment masses in MuJoCo.

See docs/readme_physics.md. ``retarget(motion, body, weight_kg, reference_body)`` runs the
paper's balance-point controller (PD joint torques + PD root force) on a ragdoll of the fitted
body and returns the COM motion (same ``.npz`` contract) and a report.
"""

from stimuli.physics.controller import Gains
from stimuli.physics.inertia import balance_factor, segment_masses, whole_body_com
from stimuli.physics.retarget import RagdollFellError, RetargetResult, retarget

__all__ = ["Gains", "RagdollFellError", "RetargetResult", "balance_factor", "retarget", "segment_masses",
           "whole_body_com"]
