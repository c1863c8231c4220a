"""Bodies: Anny meshes fitted to sex, height and BMI, with rig, skinning, anthropometry and segments.

See docs/readme_bodies.md for the API contract. Everything is in the project frame (metres,
y up, faces +z, feet on y = 0); heavy libraries (torch, anny) load on first use.
"""

from stimuli.bodies.api import BodyFitError, body_for_actor, fit_body, fit_protocol_bodies
from stimuli.bodies.body import Body, FitReport
from stimuli.bodies.contact_sheet import contact_sheet
from stimuli.bodies.export import write_bodies
from stimuli.bodies.measure import Anthropometry
from stimuli.bodies.rig import Rig
from stimuli.bodies.segments import TABLE1, Segment

# Role → Anny bone name for the joints other modules map to (all 104 names: Body.rig.names).
MAIN_BONES = {
    "hips": "root", "spine_low": "spine05", "spine_mid": "spine03", "chest": "spine01", "neck": "neck01",
    "head": "head",
    **{f"{side}_{role}": f"{bone}.{s}" for s, side in (("L", "left"), ("R", "right")) for role, bone in (
        ("clavicle", "clavicle"), ("shoulder", "upperarm01"), ("elbow", "lowerarm01"), ("wrist", "wrist"),
        ("hip", "upperleg01"), ("knee", "lowerleg01"), ("ankle", "foot"), ("toes", "toe2-1"))},
}

__all__ = ["Anthropometry", "Body", "BodyFitError", "FitReport", "MAIN_BONES", "Rig", "Segment", "TABLE1",
           "body_for_actor", "contact_sheet", "fit_body", "fit_protocol_bodies", "write_bodies"]
