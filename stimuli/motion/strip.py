"""Frame strips: several poses across one gait cycle, side view, for checking motions by eye.

Draws the 15 point-light markers joined as a stick figure (matplotlib, no OpenGL needed) for
``n`` evenly spaced frames of the first cycle, ground line at y = 0, feet in contact marked.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stimuli.fileio import save_figure
from stimuli.motion.markers import MARKERS, marker_trajectories

BONES = [("hips", "l_upper_leg"), ("hips", "r_upper_leg"), ("l_upper_leg", "l_knee"), ("r_upper_leg", "r_knee"),
         ("l_knee", "l_heel"), ("r_knee", "r_heel"), ("hips", "torso"), ("torso", "head"),
         ("torso", "l_shoulder"), ("torso", "r_shoulder"), ("l_shoulder", "l_elbow"), ("r_shoulder", "r_elbow"),
         ("l_elbow", "l_wrist"), ("r_elbow", "r_wrist")]


def frame_strip(motions: dict[str, object], path: str | Path, n: int = 8, bodies: dict | None = None) -> Path:
    """One row per motion (label → Motion), ``n`` poses of its first cycle, side view (z → right);
    ``bodies`` (label → Body) for motions on a body's rig: its markers as a clip draws them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(motions)
    fig, axes = plt.subplots(rows, n, figsize=(1.4 * n, 2.4 * rows), squeeze=False)
    idx = {m: i for i, m in enumerate(MARKERS)}
    for r, (label, motion) in enumerate(motions.items()):
        tr = marker_trajectories(motion, (bodies or {}).get(label))
        cycles = int(motion.metadata.get("cycles", 1)) or 1
        frames = np.linspace(0, motion.n_frames / cycles, n, endpoint=False).astype(int)
        for c, f in enumerate(frames):
            ax = axes[r, c]
            p = tr[f]
            for a, b in BONES:
                color = "tab:blue" if a.startswith("l_") or b.startswith("l_") else \
                    "tab:red" if a.startswith("r_") or b.startswith("r_") else "k"
                ax.plot([p[idx[a], 2], p[idx[b], 2]], [p[idx[a], 1], p[idx[b], 1]], color=color, lw=1.5)
            ax.scatter(p[:, 2], p[:, 1], s=6, c="k", zorder=3)
            for s, col in (("l", "tab:blue"), ("r", "tab:red")):
                if p[idx[f"{s}_heel"], 1] < 0.05:
                    ax.plot(p[idx[f"{s}_heel"], 2], 0.0, marker="^", color=col, ms=5)
            ax.axhline(0.0, color="0.5", lw=0.8)
            ax.set_xlim(p[idx["hips"], 2] - 0.8, p[idx["hips"], 2] + 0.8)
            ax.set_ylim(-0.05, 2.0)
            ax.set_aspect("equal")
            ax.axis("off")
            ax.set_title(f"{label} {100 * (f % max(motion.n_frames // cycles, 1)) / max(motion.n_frames // cycles, 1):.0f}%",
                         fontsize=6)
    fig.tight_layout()
    path = save_figure(fig, path)
    plt.close(fig)
    return path


def protocol_strips(protocol_path: str | Path, out_dir: str | Path, frames: int = 8, on_bodies: bool = True) -> list[Path]:
    """A strip per actor and gait of a protocol (generated motion, retargeted onto the actor's
    fitted Anny body when ``on_bodies``), plus one overview per gait with every actor."""
    from stimuli.motion.style import actor_gait
    from stimuli.protocol import load_protocol

    proto = load_protocol(protocol_path)
    out_dir = Path(out_dir)
    written = []
    for gait, spec in proto.gaits.items():
        rows, bodies = {}, {}
        for a in proto.actors:
            m = actor_gait(a, gait, spec.cadence_spm, spec.speed_mps, proto.seed, fps=30.0, cycles=2)
            label = f"{a.id} {gait}"
            if on_bodies:
                from stimuli.bodies import body_for_actor
                from stimuli.motion.retarget import retarget
                bodies[label] = body_for_actor(a)
                m = retarget(m, bodies[label])
            rows[label] = m
            written.append(frame_strip({label: m}, out_dir / f"strip_{a.id}_{gait}.png", frames, bodies))
        written.append(frame_strip(rows, out_dir / f"strips_{gait}.png", frames, bodies))
    return written
