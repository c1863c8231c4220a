"""The flight a reference motion allows a body that the floor can only push.

A simulated jog's flight share is judged against its reference's own, which the contact model
reads from the feet's positions. The reference's centre of mass says whether a body could move
so: a floor pushes up and never pulls down, so wherever the centre of mass falls faster than
gravity no foot can be carrying it. A real run does that only by the noise of its COM estimate
(in flight, where it changes nothing); an average of different runs can do it for a third of its
loop. The men's capture-average jog is braked at up to 1.9 g while the contact model has a foot
down: a body that follows its centre of mass leaves the floor sooner and faster than its feet
say, and flies longer (a controller that does not follow it, such as the paper's compliant PD,
can read less flight, but it does not move like its reference either).

:func:`pushing_floor_flight` follows a centre-of-mass height track wherever a pushing floor allows
(a foot down, downward acceleration at most g) and lets it fall freely elsewhere until it meets
the track again with a foot down: its share in the air is the flight the reference allows.
:func:`reference_under_gravity` does that for a reference posed on a ragdoll model.
"""

from __future__ import annotations

import numpy as np

G = 9.81
OVERSAMPLE = 8   # samples per reference frame: at 30 fps a 4-ms step, finer than the contact model's edges


def pushing_floor_flight(com: np.ndarray, rate: float, down: np.ndarray, laps: int = 5) -> dict[str, float]:
    """Follow the looped centre-of-mass height ``com`` (m, ``rate`` samples per second) wherever a
    floor that only pushes allows it; ``down``: whether a foot is on the floor at each sample.

    Returns ``flight_fraction`` (share of the loop in the air), ``highest_over_m`` (the most the
    body rises above the track), ``pull_mps_per_s`` (the downward speed beyond gravity the track
    asks for, per second of motion: the floor would have to pull) and
    ``pull_with_foot_down_mps_per_s`` (the part of it while a foot is down). The loop is run
    ``laps`` times and all but the first read: a body that flies over a whole loop does not come
    back to the same state each loop.

    A hop that falls under gravity between pushes is followed exactly; a track that falls at 2 g
    (no body can) is followed by a body that flies longer and higher:

    >>> rate, t = 1000.0, np.arange(500) / 1000.0
    >>> stance, v0 = t < 0.2, 9.81 * 0.3 / 2     # 0.2 s on the floor, 0.3 s of flight
    >>> hop = np.where(stance, -v0 / 0.2 * t * (0.2 - t), v0 * (t - 0.2) - 9.81 / 2 * (t - 0.2) ** 2)
    >>> pushing_floor_flight(hop, rate, stance)
    {'flight_fraction': 0.6, 'highest_over_m': 0.0, 'pull_mps_per_s': 0.0, 'pull_with_foot_down_mps_per_s': 0.0}
    >>> pushing_floor_flight(2 * hop, rate, stance)
    {'flight_fraction': 0.8, 'highest_over_m': 0.5353, 'pull_mps_per_s': 5.866, 'pull_with_foot_down_mps_per_s': 0.0}
    """
    com, down = np.asarray(com, float), np.asarray(down, bool)
    if com.shape != down.shape:
        raise ValueError(f"{len(com)} heights and {len(down)} contact samples")
    n, dt = len(com), 1.0 / rate
    speed = (np.roll(com, -1) - np.roll(com, 1)) * rate / 2
    accel = (np.roll(com, -1) - 2 * com + np.roll(com, 1)) * rate ** 2
    supported = down & (accel >= -G)
    attached, y, v = True, com[0], speed[0]
    air, over = np.zeros((laps, n), bool), np.zeros((laps, n))
    for lap in range(laps):
        for i in range(n):
            if attached and not supported[i]:
                attached, y, v = False, com[i - 1], speed[i - 1]
            if not attached:
                v -= G * dt
                y += v * dt
                attached = bool(down[i] and y <= com[i])    # landed (or fell below the track: taken up)
            if attached:
                y, v = com[i], speed[i]
            air[lap, i], over[lap, i] = not attached, y - com[i]
    air, over = air[1:], over[1:]
    pull = np.clip(-G - accel, 0.0, None) * dt / (n * dt)     # each sample's m/s of pull, per second of loop
    return {"flight_fraction": round(float(air.mean()), 4), "highest_over_m": round(float(max(over.max(), 0.0)), 4),
            "pull_mps_per_s": round(float(pull.sum()), 3),
            "pull_with_foot_down_mps_per_s": round(float(pull[down].sum()), 3)}


def com_heights(ref, model, oversample: int = OVERSAMPLE) -> tuple[np.ndarray, float]:
    """The centre-of-mass height of ``ref`` (a :class:`stimuli.physics.reference.Reference`) posed on
    the compiled ragdoll ``model``, at ``oversample`` × its frame rate over one loop; and that rate."""
    import mujoco

    from stimuli.physics.swing import actuator_qpos

    data, qadr = mujoco.MjData(model), actuator_qpos(model)
    rate, pelvis = ref.fps * oversample, model.body("pelvis").id
    pose = ref.sample(np.arange(ref.n_frames * oversample) / rate)
    com = np.empty(len(pose["q"]))
    for i in range(len(com)):
        data.qpos[:3], data.qpos[3:7], data.qpos[qadr] = pose["root_pos"][i], pose["root_quat"][i], pose["q"][i]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        com[i] = data.subtree_com[pelvis, 1]
    return com, rate


def reference_under_gravity(motion, ref, model) -> dict[str, float]:
    """:func:`pushing_floor_flight` of ``motion``'s reference ``ref`` posed on ``model``, its feet
    down where the shared contact model has them, at the same fine rate over one period (the
    simulation repeats the clip, a loop or not)."""
    from stimuli.motion.contact import foot_contacts
    from stimuli.physics.retarget import on_period

    com, rate = com_heights(ref, model)
    down = foot_contacts(on_period(motion, len(com))).down
    return pushing_floor_flight(com, rate, down["l"] | down["r"])
