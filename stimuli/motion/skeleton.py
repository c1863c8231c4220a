"""Joint roles and skeleton namings: which joint of a file is the pelvis, the left knee, …

Every importer maps its joints onto the same *roles* so that events, metrics and retargeting work on
any skeleton. Known namings are detected automatically (the naming that matches most roles wins);
anything else takes a user mapping file (YAML or JSON, ``{role: joint_name}``).

Examples
--------
>>> detect_roles(["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot",
...               "Spine", "Head"])["naming"]
'cmu'
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from stimuli.errors import StimuliError

SIDES = ("l", "r")
LIMB_ROLES = ("hip", "knee", "ankle", "toe", "clavicle", "shoulder", "elbow", "wrist")
CENTRE_ROLES = ("pelvis", "spine", "chest", "neck", "head")
ROLES = CENTRE_ROLES + tuple(f"{s}_{r}" for s in SIDES for r in LIMB_ROLES)
# Roles without which nothing (events, retargeting) can work.
REQUIRED = ("pelvis", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")


def _sided(table: dict[str, tuple[str, ...]], left: str, right: str) -> dict[str, tuple[str, ...]]:
    """Expand ``{role: names with {S}}`` to both sides using the naming's side words."""
    out: dict[str, tuple[str, ...]] = {}
    for role, names in table.items():
        if "{S}" in "".join(names):
            out[f"l_{role}"] = tuple(n.replace("{S}", left) for n in names)
            out[f"r_{role}"] = tuple(n.replace("{S}", right) for n in names)
        else:
            out[role] = names
    return out


# Candidate joint names per role, first match wins; compared case-insensitively after stripping
# a namespace prefix such as "mixamorig:".
NAMINGS: dict[str, dict[str, tuple[str, ...]]] = {
    "mixamo": _sided({
        "pelvis": ("mixamorig:Hips",), "spine": ("mixamorig:Spine",), "chest": ("mixamorig:Spine2", "mixamorig:Spine1"),
        "neck": ("mixamorig:Neck",), "head": ("mixamorig:Head",),
        "hip": ("mixamorig:{S}UpLeg",), "knee": ("mixamorig:{S}Leg",), "ankle": ("mixamorig:{S}Foot",),
        "toe": ("mixamorig:{S}ToeBase",), "clavicle": ("mixamorig:{S}Shoulder",), "shoulder": ("mixamorig:{S}Arm",),
        "elbow": ("mixamorig:{S}ForeArm",), "wrist": ("mixamorig:{S}Hand",),
    }, "Left", "Right"),
    # CMU cgspeed/Hahne release (Mixamo without its prefix; on a tie the earlier naming wins).
    "cmu": _sided({
        "pelvis": ("Hips",), "spine": ("Spine", "LowerBack"), "chest": ("Spine1", "Spine2"),
        "neck": ("Neck1", "Neck"), "head": ("Head",),
        "hip": ("{S}UpLeg",), "knee": ("{S}Leg",), "ankle": ("{S}Foot",), "toe": ("{S}ToeBase", "{S}Toe"),
        "clavicle": ("{S}Shoulder",), "shoulder": ("{S}Arm",), "elbow": ("{S}ForeArm",), "wrist": ("{S}Hand",),
    }, "Left", "Right"),
    # Old CMU / Biovision / Poser-style: Hip, LeftHip, LeftKnee, LeftAnkle, Abdomen, Chest, …
    "poser": _sided({
        "pelvis": ("Hips", "Hip", "hip"), "spine": ("Abdomen", "abdomen"), "chest": ("Chest", "chest"),
        "neck": ("Neck", "neck"), "head": ("Head", "head"),
        "hip": ("{S}Hip", "{S}UpLeg"), "knee": ("{S}Knee",), "ankle": ("{S}Ankle",), "toe": ("{S}Toe",),
        "clavicle": ("{S}Collar",), "shoulder": ("{S}Shoulder",), "elbow": ("{S}Elbow",), "wrist": ("{S}Wrist",),
    }, "Left", "Right"),
    # DAZ/Poser figure names: lThigh, lShin, lFoot, lCollar, lShldr, lForeArm, lHand.
    "daz": _sided({
        "pelvis": ("hip", "Hip"), "spine": ("abdomen",), "chest": ("chest",), "neck": ("neck",), "head": ("head",),
        "hip": ("{S}Thigh",), "knee": ("{S}Shin",), "ankle": ("{S}Foot",), "toe": ("{S}Toe",),
        "clavicle": ("{S}Collar",), "shoulder": ("{S}Shldr",), "elbow": ("{S}ForeArm",), "wrist": ("{S}Hand",),
    }, "l", "r"),
    # The generator's own skeleton: joint names are the roles.
    "canonical": {r: (r,) for r in ROLES},
    # SMPL body joints as AMASS files order them.
    "smpl": _sided({
        "pelvis": ("pelvis",), "spine": ("spine2", "spine1"), "chest": ("spine3",), "neck": ("neck",), "head": ("head",),
        "hip": ("{S}_hip",), "knee": ("{S}_knee",), "ankle": ("{S}_ankle",), "toe": ("{S}_foot",),
        "clavicle": ("{S}_collar",), "shoulder": ("{S}_shoulder",), "elbow": ("{S}_elbow",), "wrist": ("{S}_wrist",),
    }, "left", "right"),
    # The Anny rig (anny 0.6, rig "anny").
    "anny": _sided({
        "pelvis": ("root",), "spine": ("spine03",), "chest": ("spine01",), "neck": ("neck01",), "head": ("head",),
        "hip": ("upperleg01.{S}",), "knee": ("lowerleg01.{S}",), "ankle": ("foot.{S}",), "toe": ("toe1-1.{S}",),
        "clavicle": ("clavicle.{S}",), "shoulder": ("upperarm01.{S}",), "elbow": ("lowerarm01.{S}",),
        "wrist": ("wrist.{S}",),
    }, "L", "R"),
}


def _key(name: str, keep_prefix: bool) -> str:
    name = name.strip()
    if not keep_prefix:
        name = re.sub(r"^.*[:|]", "", name)
    return name.lower()


def _match(joint_names: list[str], table: dict[str, tuple[str, ...]]) -> dict[str, str]:
    keep_prefix = any(":" in c for names in table.values() for c in names)
    lookup = {_key(n, keep_prefix): n for n in joint_names}
    roles: dict[str, str] = {}
    for role, candidates in table.items():
        for cand in candidates:
            hit = lookup.get(_key(cand, keep_prefix))
            if hit is not None and hit not in roles.values():
                roles[role] = hit
                break
    return roles


def detect_roles(joint_names: list[str], where: str = "skeleton") -> dict:
    """Map roles to joint names by trying every known naming; the best match wins.

    Returns ``{"naming": name, "roles": {role: joint}}``; raises StimuliError listing the joints
    and the missing roles when no naming finds the required ones (use a mapping file then).
    """
    best_name, best = None, {}
    for naming, table in NAMINGS.items():
        roles = _match(joint_names, table)
        if len(roles) > len(best):
            best_name, best = naming, roles
    missing = [r for r in REQUIRED if r not in best]
    if missing:
        raise StimuliError(
            f"{where}: could not recognise the skeleton naming (best guess {best_name!r} lacks "
            f"{', '.join(missing)}); joints are {', '.join(joint_names)}. Pass a mapping file "
            f"(YAML/JSON {{role: joint}}) with roles from: {', '.join(ROLES)}")
    return {"naming": best_name, "roles": best}


def load_mapping(path: str | Path, joint_names: list[str]) -> dict:
    """Read a user mapping file ``{role: joint_name}`` and check it against the skeleton."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise StimuliError(f"{path}: cannot read mapping file ({exc.strerror})") from None
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import yaml
            data = yaml.safe_load(text)
    except Exception as exc:  # noqa: BLE001 - any parse error is a user error here
        raise StimuliError(f"{path}: not valid YAML/JSON ({exc})") from None
    if not isinstance(data, dict):
        raise StimuliError(f"{path}: expected a mapping {{role: joint_name}}, got {type(data).__name__}")
    for role, joint in data.items():
        if role not in ROLES:
            raise StimuliError(f"{path}: unknown role {role!r}; roles are {', '.join(ROLES)}")
        if joint not in joint_names:
            raise StimuliError(f"{path}: role {role!r} names joint {joint!r}, which is not in the skeleton "
                               f"({', '.join(joint_names)})")
    missing = [r for r in REQUIRED if r not in data]
    if missing:
        raise StimuliError(f"{path}: mapping lacks required role(s) {', '.join(missing)}")
    return {"naming": "user", "roles": {str(k): str(v) for k, v in data.items()}}


def role_indices(motion) -> dict[str, int]:
    """Role → joint index for a Motion (from its metadata, else detected from its joint names)."""
    roles = motion.metadata.get("roles") or detect_roles(motion.joint_names)["roles"]
    return {role: motion.joint_names.index(name) for role, name in roles.items() if name in motion.joint_names}
