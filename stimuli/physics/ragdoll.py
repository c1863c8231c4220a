"""The ragdoll: rigid segments of a fitted body, joints at its rig joints, as MuJoCo MJCF.

Seventeen rigid bodies: the fifteen of the segment table of ``Body.segments`` (pelvis (free root),
spine, head, and per side upper arm, lower arm, hand, upper leg, lower leg, foot) and per side the
toes (a walk's ragdoll; a jog's feet end at the ball, :data:`TOES_BY_GAIT`: fifteen bodies, 12
joints, 28 DoF). Shapes: capsules for the limbs, trunk and pelvis (radius from the segment's mesh volume), a
sphere for the head, a box for each foot from the heel to the ball and one for its toes from the
ball to the tips (fitted to the mesh vertices below the ankle), which are the only shapes that
touch the ground. Joints (14, 30 DoF): spine, neck, shoulders, hips and ankles are three hinges
each (Euler angles, so MuJoCo's PD position actuators apply), elbows, knees and toes one hinge
each; the hands are welded to the forearms. The paper's ragdoll (Unity) has 10 joints and 22 DoF;
we add the two ankles (3 DoF each) so that the feet can roll over the ground, and the toes, which
bend at the ball as the foot pushes off (with a rigid foot to the tips, the heel could not rise
without digging the tips into the floor; ended at the ball, the foot had nothing to stand on
once the heel was up, and the walks hopped: docs/readme_physics.md, "The ragdoll's toes").

Every body frame is parallel to the world axes in the rest pose and sits at its joint, so a body's
world rotation *is* the rest-relative global rotation of the motion's bone it stands for
(``Body.rig`` pose semantics: rotations relative to the rest pose, expressed in world axes).
Inertial properties come from :mod:`stimuli.physics.inertia` (Table 1), set explicitly.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stimuli.physics import inertia

# label, parent, joint kind, joint anchor (Anny bone head, "{s}" = side), the Anny bone whose
# global rotation the body follows, Euler order of the 3-hinge joints (middle axis = the one that
# moves least in gait, away from gimbal lock).
LAYOUT = (
    ("pelvis", None, "free", "root", "root", None),
    ("spine", "pelvis", "ball", "spine04", "spine03", "XZY"),
    ("head", "spine", "ball", "neck01", "head", "XZY"),
    ("upper_arm.{s}", "spine", "ball", "upperarm01.{s}", "upperarm02.{s}", "XZY"),
    ("lower_arm.{s}", "upper_arm.{s}", "hinge", "lowerarm01.{s}", "lowerarm01.{s}", None),
    ("hand.{s}", "lower_arm.{s}", "weld", "wrist.{s}", None, None),
    ("upper_leg.{s}", "pelvis", "ball", "upperleg01.{s}", "upperleg02.{s}", "XZY"),
    ("lower_leg.{s}", "upper_leg.{s}", "hinge", "lowerleg01.{s}", "lowerleg01.{s}", None),
    ("foot.{s}", "lower_leg.{s}", "ball", "foot.{s}", "foot.{s}", "XZY"),
)
# Foot–floor friction. Not a knob for the walk hop: under MuJoCo's default pyramidal friction cone
# μ also sets the normal contact's compliance (its rows are the cone edges n ± μt), so μ = 2 "cured"
# the hop by sinking the feet 3–5 cm into the floor (and stopped the jogs flying); with the elliptic
# cone, where μ is only friction, μ = 2 leaves the hop as it was (docs/physics_log.md, "Why friction moved the hop").
FOOT_FRICTION = 1.0
# Foot–floor contact (MuJoCo solref: time constant s, damping ratio), set on both geoms so it is
# not mixed with the default. Damped 1.5× critical instead of 1×: critically damped, the stiff PD
# legs bounced off the floor at landing. Time constant 0.03 s instead of MuJoCo's 0.02: a heel pad
# and shoe give about a centimetre; on the rigid 0.02 a jog at 1.5× its reference weight landed
# with 14 N·m/kg knee-moment spikes and 37 % of its steps airborne (now 0.6 and 30 %); the
# bundled CMU walk hops less (15 % airborne on the base body, 18 % before). Penetration: mean
# 5.5–7 mm walking, 95th percentile 8–11 mm; jog landings of the heaviest man 17 mm (0.02:
# 3.6–4.5, 5–7 and 11 mm).
CONTACT_SOLREF = "0.03 1.5"
# Which gaits' ragdolls have toes (``build_ragdoll(toes=)``; ``retarget(toe_segment=)`` overrides).
# Walks: with the foot box ending at the ball, the base character hopped on CMU 07_12 (0.055 of
# the walk with no foot down, against 0 in its reference) and on the Poser walk (0.115); with toes
# 0.014 and 0.037, no walk worse. Jogs keep the box on its ball (stimuli.physics.toes): with toes
# the Exp-2 women's jog averages stayed down into their flight, 0.14-0.18 of the jog in the air
# against their reference's 0.21 (0.23-0.25 without) (docs/physics_log.md, "The ragdoll's toes").
TOES_BY_GAIT = {"walk": True, "jog": False}
ARMATURE = 0.01  # kg·m² added to every hinge: keeps light segments stable at a 1 ms step


@dataclasses.dataclass
class Link:
    """One rigid body of the ragdoll (project frame, rest pose)."""

    label: str
    parent: str | None
    kind: str
    anchor: np.ndarray
    bone: str | None
    euler: str | None
    mass: inertia.SegmentMass
    geom: dict
    inertia: np.ndarray
    inertia_quat: np.ndarray
    hinge_axis: np.ndarray | None = None

    @property
    def dofs(self) -> list[str]:
        """Names of the actuated DoF of this body's joint (``knee.L`` style joint names)."""
        if self.kind == "ball":
            return [f"{self.joint_name}:{a}" for a in self.euler]
        if self.kind == "hinge":
            return [self.joint_name]
        return []

    @property
    def joint_name(self) -> str:
        """Anatomical name of the joint at the body's proximal end."""
        base, _, side = self.label.partition(".")
        name = {"spine": "spine", "head": "neck", "upper_arm": "shoulder", "lower_arm": "elbow",
                "upper_leg": "hip", "lower_leg": "knee", "foot": "ankle", "hand": "wrist", "pelvis": "root",
                "toes": "toe"}[base]
        return f"{name}.{side}" if side else name


@dataclasses.dataclass
class Ragdoll:
    """Links in parent-first order plus the body they came from."""

    links: list[Link]
    weight_kg: float
    height_m: float
    body_id: str

    def link(self, label: str) -> Link:
        return next(k for k in self.links if k.label == label)

    @property
    def has_toes(self) -> bool:
        """Whether the feet have toe segments (:func:`toe_link`)."""
        return any(k.label.startswith("toes.") for k in self.links)

    @property
    def dof_names(self) -> list[str]:
        return [d for k in self.links for d in k.dofs]


def expand_layout():
    """LAYOUT with both sides spelled out (parents before children)."""
    rows = []
    for row in LAYOUT:
        if "{s}" in row[0]:
            for s in "LR":
                rows.append(tuple(x.format(s=s) if isinstance(x, str) else x for x in row))
        else:
            rows.append(row)
    order = {r[0]: i for i, r in enumerate(rows)}
    return sorted(rows, key=lambda r: _depth(r, order, rows))


def _depth(row, order, rows):
    depth, parent = 0, row[1]
    while parent is not None:
        depth += 1
        parent = rows[order[parent]][1]
    return depth, order[row[0]]


def capsule_radius(volume: float, length: float) -> float:
    """Radius r of a capsule of total volume ``volume`` whose cap centres are ``length`` apart."""
    roots = np.roots([4.0 / 3.0 * np.pi, np.pi * length, 0.0, -volume])
    return float(max(r.real for r in roots if abs(r.imag) < 1e-9 and r.real > 0))


def _foot_box(body, ankle: np.ndarray, ball: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half sizes of the box around the mesh vertices below the ankle (sole on y = 0).

    The box ends at the ball of the foot (the toe joint, the foot segment's distal end), where the
    toes' box (:func:`toe_link`) is hinged: one rigid box reaching the toe tips dug ~6 cm into the
    floor whenever the heel rose, and the contact threw the body up (the pelvis bounced ±8 cm).
    """
    v = body.vertices
    forward = np.asarray(ball - ankle, float)
    forward[1] = 0.0
    forward /= np.linalg.norm(forward)
    near = _below_ankle(v, ankle) & ((v - ankle) @ forward <= (ball - ankle) @ forward)
    lo, hi = v[near].min(0), v[near].max(0)
    lo[1] = 0.0
    hi[1] = ankle[1]
    return (lo + hi) / 2, (hi - lo) / 2


def _below_ankle(v: np.ndarray, ankle: np.ndarray) -> np.ndarray:
    """Mesh vertices of one foot: below its ankle, within 12 cm sideways and 35 cm along."""
    return (v[:, 1] < ankle[1]) & (np.abs(v[:, 0] - ankle[0]) < 0.12) & (np.abs(v[:, 2] - ankle[2]) < 0.35)


def _axis_quat(direction: np.ndarray) -> np.ndarray:
    """Quaternion (w-first) turning +z onto ``direction`` (for capsule inertia frames)."""
    z = np.array([0.0, 0.0, 1.0])
    d = direction / np.linalg.norm(direction)
    c = float(np.dot(z, d))
    if c < -0.999999:
        return np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.cross(z, d)
    q = np.array([1.0 + c, *axis])
    return q / np.linalg.norm(q)


def _shape(label: str, seg, body, anchor: np.ndarray, rig) -> tuple[dict, np.ndarray, np.ndarray, float]:
    """Geometry (body-local), principal inertia per kg and its frame for one segment."""
    name = label.split(".")[0]
    if name == "head":
        radius = (3 * seg.volume_m3 / (4 * np.pi)) ** (1 / 3)
        centre = seg.com_geometric - anchor
        return {"type": "sphere", "size": [radius], "pos": centre}, inertia.sphere_inertia(1.0, radius), np.array([1.0, 0, 0, 0]), radius
    if name == "foot":
        centre, half = _foot_box(body, anchor, np.asarray(seg.distal, float))
        return ({"type": "box", "size": half, "pos": centre - anchor}, inertia.box_inertia(1.0, half),
                np.array([1.0, 0, 0, 0]), float(half[0]))
    if name == "pelvis":
        a, b = rig.rest_heads[rig.index("upperleg01.L")], rig.rest_heads[rig.index("upperleg01.R")]
    else:
        a, b = seg.proximal, seg.distal
    length = float(np.linalg.norm(b - a))
    radius = capsule_radius(seg.volume_m3, length)
    geom = {"type": "capsule", "fromto": np.concatenate([a - anchor, b - anchor]), "size": [radius]}
    return geom, inertia.capsule_inertia(1.0, radius, length / 2), _axis_quat(b - a), radius


def build_ragdoll(body, weight_kg: float | None = None, hinge_axes: dict[str, np.ndarray] | None = None,
                  toes: bool = True) -> Ragdoll:
    """The ragdoll of a fitted ``stimuli.bodies.Body`` with Table-1 masses for ``weight_kg``.

    ``weight_kg`` defaults to the body's own mass; ``hinge_axes`` maps ``lower_leg.L`` … to a
    unit axis (world, rest pose) for the elbows and knees (default: the body's +x, its left);
    ``toes``: the feet get toe segments (:func:`toe_link`; :data:`TOES_BY_GAIT`).
    """
    weight = float(body.anthropometry.mass_kg if weight_kg is None else weight_kg)
    height = float(body.anthropometry.height_m)
    inertia.check_weight(weight, height)
    masses = {m.label: m for m in inertia.segment_masses(body.segments, weight)}
    segs = {s.label: s for s in body.segments}
    rig = body.rig
    links = []
    for label, parent, kind, joint_bone, bone, euler in expand_layout():
        anchor = rig.rest_heads[rig.index(joint_bone)].astype(float)
        geom, unit_inertia, iquat, _ = _shape(label, segs[label], body, anchor, rig)
        axis = None
        if kind == "hinge":
            axis = np.asarray((hinge_axes or {}).get(label, [1.0, 0.0, 0.0]), float)
            axis = axis / np.linalg.norm(axis)
        links.append(Link(label, parent, kind, anchor, bone, euler, masses[label], geom,
                          unit_inertia * masses[label].mass_kg, iquat, axis))
    if toes:
        links += [toe_link(body, next(k for k in links if k.label == f"foot.{s}"), s) for s in "LR"]
    return Ragdoll(links, weight, height, body.body_id)


def toe_link(body, foot: Link, side: str) -> Link:
    """The toes of one side: a box around the mesh vertices ahead of the ball (sole on y = 0), hinged
    at the ball about the foot's lateral axis (level, square to the heel–ball line).

    Table 1 gives one mass for the whole foot; it is split between the foot and its toes in
    proportion to their boxes' volumes, keeping the whole foot's centre of mass, so the body's mass
    and centre of mass (and the balance factor b) are as without the split. ``foot`` (the foot's
    link, the toes' parent) is given its share here.
    """
    seg = {s.label: s for s in body.segments}[f"foot.{side}"]
    ankle, ball = np.asarray(seg.proximal, float), np.asarray(seg.distal, float)
    forward = ball - ankle
    forward[1] = 0.0
    forward /= np.linalg.norm(forward)
    v = body.vertices
    ahead = _below_ankle(v, ankle) & ((v - ankle) @ forward > (ball - ankle) @ forward)
    lo, hi = v[ahead].min(0), v[ahead].max(0)
    lo[1] = 0.0
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    whole = foot.mass
    toe_kg = whole.mass_kg * float(np.prod(half) / (np.prod(half) + np.prod(foot.geom["size"])))
    foot_kg = whole.mass_kg - toe_kg
    foot.mass = dataclasses.replace(whole, mass_kg=foot_kg, com=(whole.mass_kg * whole.com - toe_kg * centre) / foot_kg)
    foot.inertia = inertia.box_inertia(foot_kg, foot.geom["size"])
    toes = dataclasses.replace(whole, label=f"toes.{side}", mass_kg=toe_kg, com=centre, com_geometric=centre)
    axis = np.cross([0.0, 1.0, 0.0], forward)
    return Link(f"toes.{side}", f"foot.{side}", "hinge", ball, None, None, toes,
                {"type": "box", "size": half, "pos": centre - ball}, inertia.box_inertia(toe_kg, half),
                np.array([1.0, 0.0, 0.0, 0.0]), axis / np.linalg.norm(axis))


def _fmt(values) -> str:
    return " ".join(f"{float(v):.6g}" for v in np.atleast_1d(values))


def _geom_xml(link: Link) -> str:
    g = link.geom
    where = f'fromto="{_fmt(g["fromto"])}"' if "fromto" in g else f'pos="{_fmt(g["pos"])}"'
    if link.label.startswith(("foot", "toes")):
        # Only the feet collide (with the floor); friction as on a belt or floor.
        contact = f'contype="2" conaffinity="1" friction="{FOOT_FRICTION} 0.02 0.002" solref="{CONTACT_SOLREF}"'
    else:
        contact = 'contype="0" conaffinity="0"'
    return f'<geom name="{link.label}" type="{g["type"]}" size="{_fmt(g["size"])}" {where} {contact} mass="0"/>'


def _joint_xml(link: Link) -> str:
    if link.kind == "free":
        return '<freejoint name="root"/>'
    if link.kind == "hinge":
        return f'<joint name="{link.joint_name}" type="hinge" axis="{_fmt(link.hinge_axis)}" armature="{ARMATURE}"/>'
    if link.kind == "ball":
        axes = {"X": "1 0 0", "Y": "0 1 0", "Z": "0 0 1"}
        return "".join(f'<joint name="{d}" type="hinge" axis="{axes[d[-1]]}" armature="{ARMATURE}"/>'
                       for d in link.dofs)
    return ""


def to_mjcf(ragdoll: Ragdoll, timestep: float, kp: dict[str, float], kd: dict[str, float]) -> str:
    """MJCF text of the ragdoll on a ground plane with one PD position actuator per DoF.

    ``kp``/``kd`` map DoF names to gains (N·m/rad, N·m·s/rad): τ = kp (q̄ − q) − kd q̇.
    """
    children: dict[str | None, list[Link]] = {}
    for link in ragdoll.links:
        children.setdefault(link.parent, []).append(link)

    def body_xml(link: Link, parent_anchor: np.ndarray) -> str:
        pos = link.anchor - parent_anchor
        m = link.mass
        inert = (f'<inertial pos="{_fmt(m.com - link.anchor)}" quat="{_fmt(link.inertia_quat)}" '
                 f'mass="{m.mass_kg:.6g}" diaginertia="{_fmt(link.inertia)}"/>')
        inner = "".join(body_xml(c, link.anchor) for c in children.get(link.label, []))
        return (f'<body name="{link.label}" pos="{_fmt(pos)}">{inert}{_joint_xml(link)}'
                f'{_geom_xml(link)}{inner}</body>')

    root = children[None][0]
    actuators = "".join(
        f'<position name="{d}" joint="{d}" kp="{kp[d]:.6g}" kv="{kd[d]:.6g}"/>' for d in ragdoll.dof_names)
    return f"""<mujoco model="ragdoll_{ragdoll.body_id}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{timestep:.8g}" gravity="0 -9.81 0" integrator="implicitfast"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" zaxis="0 1 0" contype="1" conaffinity="2" friction="{FOOT_FRICTION} 0.02 0.002" solref="{CONTACT_SOLREF}"/>
    {body_xml(root, np.zeros(3))}
  </worldbody>
  <actuator>{actuators}</actuator>
</mujoco>"""


def compile_model(ragdoll: Ragdoll, timestep: float, kp: dict[str, float], kd: dict[str, float]):
    """A compiled ``mujoco.MjModel`` of the ragdoll."""
    import mujoco

    return mujoco.MjModel.from_xml_string(to_mjcf(ragdoll, timestep, kp, kd))
