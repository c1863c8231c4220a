"""Joint roles and skeleton namings: which joint of a file is the pelvis, the left knee, …

Every importer maps its joints onto the same *roles* so that events, metrics and retargeting work on
any skeleton. Known namings are detected automatically (the naming that matches most roles wins);
other rigs by name patterns and the tree (:func:`pattern_roles`: sides from ``Left``/``L``/``_L``/
``.L``/``lhand``, feet and hands by name, the rest of each limb as their ancestors); anything else
takes a user mapping file (YAML or JSON, ``{role: joint_name}``).

Examples
--------
>>> detect_roles(["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot",
...               "Spine", "Head"])["naming"]
'cmu'
"""

from __future__ import annotations

import functools
import itertools
import json
import re
from pathlib import Path

import numpy as np
import yaml

from analysis.io_yaml import load_bounded, yaml_problem
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


def detect_roles(joint_names: list[str], where: str = "skeleton", parents=None) -> dict:
    """Map roles to joint names: the known namings' tables, then the name patterns of any rig.

    The tables (exact names) come first; with ``parents`` (the parent index of each joint) the
    pattern matcher (:func:`pattern_roles`) also runs and wins where it finds more roles, which
    covers rigs the tables do not list (Character Creator, Bandai, 3ds Max Biped, …). Returns
    ``{"naming": name, "roles": {role: joint}}``; raises StimuliError naming ``where``, the
    missing roles and the joints that no role took when neither finds the required ones.

    >>> names = ["Bip01", "Bip01 Pelvis", "Bip01 L Thigh", "Bip01 L Calf", "Bip01 L Foot",
    ...          "Bip01 R Thigh", "Bip01 R Calf", "Bip01 R Foot"]
    >>> detect_roles(names, parents=[-1, 0, 1, 2, 3, 1, 5, 6])["roles"]["l_knee"]
    'Bip01 L Calf'
    """
    # Pure in the names and the tree, and asked for again on the same skeleton by every step that
    # needs a joint (a protocol's averages asked ~480 times for 16 skeletons): remembered per skeleton.
    found = _detect_roles(tuple(joint_names), where, None if parents is None else tuple(int(p) for p in parents))
    return {"naming": found["naming"], "roles": dict(found["roles"])}


@functools.lru_cache(maxsize=256)
def _detect_roles(joint_names: tuple[str, ...], where: str, parents: tuple[int, ...] | None) -> dict:
    """:func:`detect_roles` of one skeleton (hashable arguments; the caller copies the result)."""
    joint_names = list(joint_names)
    best_name, best = None, {}
    for naming, table in NAMINGS.items():
        roles = _match(joint_names, table)
        if len(roles) > len(best):
            best_name, best = naming, roles
    if parents is not None:
        found = pattern_roles(joint_names, parents)
        if len(found) > len(best) or any(r not in best for r in REQUIRED):
            best_name, best = naming_label(joint_names), found
    missing = [r for r in REQUIRED if r not in best]
    if missing:
        taken = set(best.values())
        unmapped = [n for n in joint_names if n not in taken and not n.endswith("_end")]
        shown = ", ".join(unmapped[:40]) + (f" and {len(unmapped) - 40} more" if len(unmapped) > 40 else "")
        raise StimuliError(
            f"{where}: could not recognise the skeleton naming: no joint found for the role(s) "
            f"{', '.join(missing)}"
            + (f" (found {', '.join(f'{r}={j}' for r, j in best.items())})" if best else "")
            + f"; joints no role took: {shown}. Pass a mapping file (YAML/JSON {{role: joint}}) with roles "
            f"from: {', '.join(ROLES)}")
    return {"naming": best_name, "roles": best}


# ---------------------------------------------------------------- name patterns
# Rig prefixes that carry no anatomy (Character Creator, 3ds Max Biped, MotionBuilder, Mixamo, Blender).
PREFIX_TOKENS = {"cc", "base", "bip", "biped", "character", "mixamorig", "def", "org", "rig", "joint", "jnt", "bone"}
SIDE_TOKENS = {"l": "l", "left": "l", "r": "r", "right": "r"}
# Bones that ride along a limb without being its joint: twist/roll/share bones of CC4 and Biped.
HELPER = re.compile(r"twist|roll|share|helper|nub|corrective|adjust")
ANKLE_WORDS = ("ankle", "foot")
WRIST_WORDS = ("wrist", "hand")
TOE_WORDS = ("toebase", "toe", "toes", "ball")
PELVIS_WORDS = ("pelvis", "hips", "hip")


def _tokens(name: str) -> list[str]:
    """A joint name as lower-case words: camel case, digits and separators split; namespace dropped.

    >>> _tokens("mixamorig:LeftUpLeg"), _tokens("CC_Base_L_Thigh"), _tokens("LHipJoint")
    (['left', 'up', 'leg'], ['cc', 'base', 'l', 'thigh'], ['l', 'hip', 'joint'])
    """
    name = re.sub(r"^.*[:|]", "", name.strip())
    return [t.lower() for t in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", name)]


def _side_and_core(name: str) -> tuple[str | None, str]:
    """The side (``"l"``, ``"r"`` or None) and the anatomical core word of a joint name.

    >>> _side_and_core("Hand_L"), _side_and_core("lhand"), _side_and_core("Bip01 R UpperArm")
    (('l', 'hand'), ('l', 'hand'), ('r', 'upperarm'))
    """
    words = [t for t in _tokens(name) if not t.isdigit()]
    side = next((SIDE_TOKENS[t] for t in words if t in SIDE_TOKENS), None)
    core = "".join(t for t in words if t not in SIDE_TOKENS and t not in PREFIX_TOKENS)
    if side is None and len(core) > 3 and core[0] in "lr" and core[1:] in _BODY_WORDS:
        side, core = core[0], core[1:]  # "lhand", "rfoot": a one-letter side glued to the word
    return side, core


_BODY_WORDS = {"hand", "foot", "wrist", "ankle", "toe", "thigh", "knee", "shin", "calf", "hip", "collar",
               "clavicle", "shoulder", "elbow", "forearm", "arm", "upleg", "leg", "fingers", "thumb", "shldr"}


def ancestors(j: int, parents) -> list[int]:
    out = []
    while parents[j] >= 0:
        j = int(parents[j])
        out.append(j)
    return out


def pattern_roles(joint_names: list[str], parents) -> dict[str, str]:
    """Roles found from name patterns and the tree: any rig that names its sides and its feet and hands.

    The ankle (``*foot``/``*ankle``) and wrist (``*hand``/``*wrist``) of each side are found by name;
    the knee, thigh, elbow, upper arm and clavicle are their ancestors in turn (twist and share bones
    skipped), so "Shoulder" may be a clavicle (CMU, Bandai) or an upper arm (3ds Max, Poser) as the
    tree says. The toe is the ankle's toe-named child, else its first child, else its End Site
    (toe-less rigs). The pelvis is the nearest pelvis/hips-named ancestor of both thighs (else their
    common ancestor), the chest the common ancestor of the clavicles, the neck the head's nearest
    neck-named ancestor.

    >>> names = ["Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Foot_L_end", "UpperLeg_R", "LowerLeg_R",
    ...          "Foot_R", "Foot_R_end"]
    >>> r = pattern_roles(names, [-1, 0, 1, 2, 3, 0, 5, 6, 7])
    >>> r["pelvis"], r["l_hip"], r["r_toe"]
    ('Hips', 'UpperLeg_L', 'Foot_R_end')
    """
    parents = [int(p) for p in parents]
    n = len(joint_names)
    parsed = [_side_and_core(nm) for nm in joint_names]
    helper = [bool(HELPER.search(core)) or nm.endswith("_end") for nm, (_, core) in zip(joint_names, parsed)]
    depth = [len(ancestors(j, parents)) for j in range(n)]
    roles: dict[str, int] = {}

    def named(side, words, pool=range(n)):
        """Shallowest non-helper joint of ``side`` whose core is the first of ``words`` found."""
        for w in words:
            hits = [j for j in pool if parsed[j][0] == side and parsed[j][1] == w and not helper[j]]
            if hits:
                return min(hits, key=lambda j: depth[j])
        return None

    def up(j):
        """Nearest ancestor that is a joint of the limb (not a twist or share bone)."""
        return next((a for a in ancestors(j, parents) if not helper[a]), None)

    for s in SIDES:
        ankle = named(s, ANKLE_WORDS)
        if ankle is not None:
            roles[f"{s}_ankle"] = ankle
            knee = up(ankle)
            hip = up(knee) if knee is not None and parsed[knee][0] == s else None
            if hip is not None and parsed[hip][0] == s:
                roles[f"{s}_knee"], roles[f"{s}_hip"] = knee, hip
            kids = [k for k in range(n) if parents[k] == ankle]
            toe = (named(s, TOE_WORDS, [k for k in range(n) if ankle in ancestors(k, parents)])
                   or next((k for k in kids if not helper[k]), None)
                   or next((k for k in kids if joint_names[k].endswith("_end")), None))
            if toe is not None:
                roles[f"{s}_toe"] = toe
        wrist = named(s, WRIST_WORDS)
        if wrist is not None:
            chain = [wrist]
            while len(chain) < 4 and (a := up(chain[-1])) is not None and parsed[a][0] == s:
                chain.append(a)
            for role, j in zip(("wrist", "elbow", "shoulder", "clavicle"), chain):
                roles[f"{s}_{role}"] = j
    if "l_hip" in roles and "r_hip" in roles:
        right = set(ancestors(roles["r_hip"], parents))
        common = [a for a in ancestors(roles["l_hip"], parents) if a in right]
        named_pelvis = (a for w in PELVIS_WORDS for a in common if parsed[a] == (None, w))
        pelvis = next(named_pelvis, common[0] if common else None)
        if pelvis is not None:
            roles["pelvis"] = pelvis
    if "pelvis" not in roles and (pelvis := named(None, PELVIS_WORDS)) is not None:
        roles["pelvis"] = pelvis   # by name alone: says more where the legs are not found
    head = named(None, ("head",))
    if head is not None:
        roles["head"] = head
        neck = next((a for a in ancestors(head, parents) if "neck" in parsed[a][1]), None)
        if neck is not None:
            roles["neck"] = neck
    arms = [roles.get(f"{s}_clavicle", roles.get(f"{s}_shoulder")) for s in SIDES]
    if None not in arms:
        right = set(ancestors(arms[1], parents))
        chest = next((a for a in ancestors(arms[0], parents) if a in right), None)
        if chest is not None:
            roles["chest"] = chest
            # the spine joints lie between the chest and the pelvis or, where the pelvis hangs beside
            # the spine (CC4: Hip > Pelvis and Hip > Waist > Spine01), the pelvis's ancestor they share
            below = {roles["pelvis"], *ancestors(roles["pelvis"], parents)} if "pelvis" in roles else set()
            path = list(itertools.takewhile(lambda a: a not in below, ancestors(chest, parents)))
            spine = [a for a in reversed(path) if not helper[a]]
            pick = next((a for a in spine if parsed[a][1] == "spine" and not re.search(r"\d", joint_names[a])),
                        spine[len(spine) // 2] if spine else None)
            if pick is not None:
                roles["spine"] = pick
    return {role: joint_names[j] for role, j in roles.items()}


def naming_label(joint_names: list[str]) -> str:
    """A name for the rig convention, for the metadata and messages (``"pattern"`` if none fits).

    >>> naming_label(["CC_Base_Hip", "CC_Base_L_Thigh"]), naming_label(["Hips", "UpperLeg_L"])
    ('cc4', 'bandai')
    """
    text = " ".join(joint_names)
    for label, pattern in (("mixamo", r"mixamorig\d*:"), ("cc4", r"\bCC_Base_"), ("biped", r"\bBip0*1\b"),
                           ("bandai", r"\b(UpperLeg|LowerLeg)_[LR]\b"), ("cmu-3dsmax", r"\bLeftHip\b.*\bLeftKnee\b"),
                           ("daz", r"\blThigh|\blShldr"), ("cmu", r"\bLeftUpLeg\b")):
        if re.search(pattern, text):
            return label
    return "pattern"


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
            data, _ = load_bounded(text)   # limits on size, nodes and aliases; a key given twice is refused
    except json.JSONDecodeError as exc:
        raise StimuliError(f"{path}: not valid JSON ({exc})") from None
    except yaml.YAMLError as exc:
        raise StimuliError(f"{path}:{yaml_problem(exc, text)}") from None
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
    roles = motion.metadata.get("roles") or detect_roles(motion.joint_names, parents=motion.parents)["roles"]
    return {role: motion.joint_names.index(name) for role, name in roles.items() if name in motion.joint_names}


def leg_length(motion: Motion) -> float:
    """Thigh + shank + ankle height of a skeleton, in its own units, whatever its rest pose.

    Segment lengths come from the offsets (a rest pose with splayed legs, or CC4's bones all along
    +y, changes nothing); the ankle height is the lowest the ankle comes above the floor the feet
    stand on over the clip (a flat foot), the floor being the lowest foot joint, End Sites included.

    >>> import numpy as np
    >>> from stimuli.motion.motion import Motion
    >>> legs = Motion(fps=30.0, joint_names=["pelvis", "l_hip", "l_knee", "l_ankle", "l_toe", "r_hip", "r_knee",
    ...               "r_ankle", "r_toe"], parents=[-1, 0, 1, 2, 3, 0, 5, 6, 7],
    ...               offsets=[[0, 0, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.42, 0], [0, -0.08, 0.1],
    ...                        [-0.1, 0, 0], [0, -0.45, 0], [0, -0.42, 0], [0, -0.08, 0.1]],
    ...               rotations=np.tile([1.0, 0, 0, 0], (1, 9, 1)), root_translation=[[0, 0.95, 0]])
    >>> round(leg_length(legs), 3)
    0.95
    """
    roles = role_indices(motion)
    rest = motion.rest_positions()
    pos = motion.positions()
    lengths, heights, floors = [], [], []
    for s in ("l", "r"):
        hip, knee, ankle = (roles[f"{s}_{r}"] for r in ("hip", "knee", "ankle"))
        lengths.append(np.linalg.norm(rest[knee] - rest[hip]) + np.linalg.norm(rest[ankle] - rest[knee]))
        foot = [ankle] + [k for k in range(motion.n_joints) if ankle in ancestors(k, motion.parents)]
        floors.append(pos[:, foot, 1].min(axis=1))
        heights.append(pos[:, ankle, 1])
    floor = np.minimum(*floors)
    ankle_height = np.mean([np.percentile(h - floor, 2) for h in heights])
    return float(np.mean(lengths) + max(ankle_height, 0.0))
