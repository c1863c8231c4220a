"""The ``Motion`` object and its ``.npz`` file (DESIGN.md contract).

A motion is a skeleton (joint names, parent indices, rest offsets in metres) plus per-frame local
joint rotations (T×J×4, w-first quaternions, identity = rest pose) and a root translation (T×3,
metres, y-up, character faces +z, ground at y = 0). Forward kinematics::

    R_j = R_parent(j) · q_j            p_j = p_parent(j) + R_parent(j) · offset_j

with the root at ``root_translation`` (the root's own offset is ignored).

Examples
--------
>>> import numpy as np
>>> m = Motion(fps=30.0, joint_names=["root", "tip"], parents=np.array([-1, 0]),
...            offsets=np.array([[0, 0, 0], [0, 1.0, 0]]),
...            rotations=np.tile([1.0, 0, 0, 0], (2, 2, 1)), root_translation=np.zeros((2, 3)))
>>> m.positions()[0, 1].tolist()
[0.0, 1.0, 0.0]
"""

from __future__ import annotations

import copy
import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.motion import quat


@dataclass
class Motion:
    """Skeletal motion: see the module docstring for conventions."""

    fps: float
    joint_names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    rotations: np.ndarray
    root_translation: np.ndarray
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.joint_names = [str(n) for n in self.joint_names]
        self.parents = np.asarray(self.parents, dtype=int)
        self.offsets = np.asarray(self.offsets, dtype=float)
        self.rotations = quat.normalize(np.asarray(self.rotations, dtype=float))
        self.root_translation = np.asarray(self.root_translation, dtype=float)
        self.validate()

    # ------------------------------------------------------------------ checks and basic facts
    def validate(self, where: str = "motion") -> None:
        """Raise StimuliError if shapes disagree, the tree is not topologically ordered, or NaN."""
        j = len(self.joint_names)
        t = self.rotations.shape[0] if self.rotations.ndim == 3 else -1
        checks = [
            (self.fps > 0, f"fps must be > 0, got {self.fps}"),
            (self.parents.shape == (j,), f"parents must have {j} entries, got {self.parents.shape}"),
            (self.offsets.shape == (j, 3), f"offsets must be {j}×3, got {self.offsets.shape}"),
            (self.rotations.ndim == 3 and self.rotations.shape[1:] == (j, 4),
             f"rotations must be T×{j}×4, got {self.rotations.shape}"),
            (self.root_translation.shape == (t, 3), f"root_translation must be {t}×3, got {self.root_translation.shape}"),
            (t >= 1, "motion has no frames"),
        ]
        for ok, msg in checks:
            if not ok:
                raise StimuliError(f"{where}: {msg}")
        if self.parents[0] != -1 or np.any(self.parents[1:] >= np.arange(1, j)) or np.any(self.parents[1:] < 0):
            raise StimuliError(f"{where}: parents must list the root first (-1) and every parent before its child")
        for name, arr in (("offsets", self.offsets), ("rotations", self.rotations), ("root_translation", self.root_translation)):
            if not np.all(np.isfinite(arr)):
                bad = np.argwhere(~np.isfinite(arr))[0]
                raise StimuliError(f"{where}: {name} contains NaN/inf (first at index {tuple(bad.tolist())})")

    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def duration_s(self) -> float:
        """Duration of the clip when looped (n_frames / fps)."""
        return self.n_frames / self.fps

    def index(self, name: str) -> int:
        """Index of a joint by name (StimuliError naming the known joints if absent)."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise StimuliError(f"motion: no joint named {name!r}; joints are {', '.join(self.joint_names)}") from None

    def copy(self) -> "Motion":
        return copy.deepcopy(self)

    def replace(self, **changes) -> "Motion":
        """A copy with some fields replaced (metadata merged, not replaced)."""
        out = self.copy()
        meta = changes.pop("metadata", None)
        for k, v in changes.items():
            setattr(out, k, v)
        if meta:
            out.metadata.update(meta)
        out.__post_init__()
        return out

    # ------------------------------------------------------------------ kinematics
    def global_transforms(self, rotations: np.ndarray | None = None, root: np.ndarray | None = None):
        """World rotations (T×J×4) and positions (T×J×3) by forward kinematics."""
        rot = self.rotations if rotations is None else rotations
        root = self.root_translation if root is None else root
        t, j = rot.shape[:2]
        grot = np.empty_like(rot)
        gpos = np.empty((t, j, 3))
        grot[:, 0] = rot[:, 0]
        gpos[:, 0] = root
        # One product per depth of the tree, not per joint: the same arithmetic per element, in
        # about a third of the calls (each call's overhead outweighs its few hundred frames).
        for ks, ps in _depth_levels(self.parents[:j]):
            grot[:, ks] = quat.mul(grot[:, ps], rot[:, ks])
            gpos[:, ks] = gpos[:, ps] + quat.rotate(grot[:, ps], self.offsets[ks])
        return grot, gpos

    def positions(self) -> np.ndarray:
        """World joint positions, T×J×3 (metres)."""
        return self.global_transforms()[1]

    def rest_positions(self) -> np.ndarray:
        """Joint positions of the rest pose with the root at the origin, J×3."""
        pos = np.zeros((self.n_joints, 3))
        for k in range(1, self.n_joints):
            pos[k] = pos[self.parents[k]] + self.offsets[k]
        return pos

    def children(self, j: int) -> list[int]:
        return [int(k) for k in np.flatnonzero(self.parents == j)]

    # ------------------------------------------------------------------ time
    def slice(self, start: int, stop: int | None = None) -> "Motion":
        """Frames ``start:stop`` as a new motion."""
        stop = self.n_frames if stop is None else stop
        if not 0 <= start < stop <= self.n_frames:
            raise StimuliError(f"motion: frame range {start}:{stop} outside 0:{self.n_frames}")
        return self.replace(rotations=self.rotations[start:stop].copy(),
                            root_translation=self.root_translation[start:stop].copy())

    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations and root translation at arbitrary times (s): slerp and linear interpolation."""
        f = np.clip(np.asarray(times, float) * self.fps, 0, self.n_frames - 1)
        i0 = np.floor(f).astype(int)
        i1 = np.minimum(i0 + 1, self.n_frames - 1)
        a = (f - i0)
        rot = quat.slerp(self.rotations[i0], self.rotations[i1], np.repeat(a[:, None], self.n_joints, 1))
        root = self.root_translation[i0] * (1 - a[:, None]) + self.root_translation[i1] * a[:, None]
        return rot, root

    def resample(self, fps: float) -> "Motion":
        """The same motion at another frame rate (same duration of the covered time span)."""
        if fps <= 0:
            raise StimuliError(f"motion: target fps must be > 0, got {fps}")
        span = (self.n_frames - 1) / self.fps
        n = int(round(span * fps)) + 1
        rot, root = self.sample(np.arange(n) / fps)
        return self.replace(fps=float(fps), rotations=rot, root_translation=root)

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        """Write the ``.npz`` contract (atomically: a temporary file of this process, then rename).

        The temporary name is unique: with one fixed name, two processes saving the same file (two
        physics runs sharing the cache) wrote into one temporary file, and a reader could find the
        motion empty while the other process was still writing it.
        """
        from stimuli.fileio import atomic_write_bytes

        path = Path(path)
        atomic_write_bytes(path, self.to_bytes())   # e.g. ``path`` is a folder: no temporary file left
        return path

    def to_bytes(self) -> bytes:
        """The ``.npz`` file's bytes (:meth:`save` writes them): the same for the same motion, as
        zip entries carry no time."""
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer, fps=np.float64(self.fps), joint_names=np.array(self.joint_names, dtype=str),
            parents=self.parents.astype(np.int32), offsets=self.offsets,
            rotations=self.rotations, root_translation=self.root_translation,
            metadata=np.array(json.dumps(self.metadata, sort_keys=True, default=_json_default)))
        return buffer.getvalue()

    @classmethod
    def load(cls, path: str | Path) -> "Motion":
        """Read a ``.npz`` motion (StimuliError naming the file and the missing/bad field).

        Fields beyond the contract are ignored (other tools may add their own).
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                fields = {k: data[k] for k in data.files}
        except FileNotFoundError:
            raise StimuliError(f"{path}: motion file not found") from None
        except IsADirectoryError:
            raise StimuliError(f"{path}: is a folder, not a motion file") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            # numpy reads any file as a pickle when it is neither .npz nor .npy, hence its
            # "pickled (object) data" message for a text file; say what the file is not instead.
            raise StimuliError(f"{path}: not a shapemotion motion (.npz): {_load_problem(exc)}") from None
        needed = ["fps", "joint_names", "parents", "offsets", "rotations", "root_translation"]
        missing = [k for k in needed if k not in fields]
        if missing:
            raise StimuliError(f"{path}: missing field(s) {', '.join(missing)} (a Motion .npz needs {', '.join(needed)})")
        try:
            meta = json.loads(str(fields["metadata"])) if "metadata" in fields else {}
        except json.JSONDecodeError as exc:
            raise StimuliError(f"{path}: not a shapemotion motion (.npz): metadata is not JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise StimuliError(f"{path}: not a shapemotion motion (.npz): metadata must be a JSON object")
        try:
            _check_finite_rotations(fields["rotations"])
            return cls(fps=float(fields["fps"]), joint_names=list(fields["joint_names"]), parents=fields["parents"],
                       offsets=fields["offsets"], rotations=fields["rotations"],
                       root_translation=fields["root_translation"], metadata=meta)
        except StimuliError as exc:
            raise StimuliError(f"{path}: {exc}") from None
        except (TypeError, ValueError) as exc:  # e.g. an array where fps should be a number
            raise StimuliError(f"{path}: not a shapemotion motion (.npz): {exc}") from None

def _load_problem(exc: Exception) -> str:
    """What was wrong with a file numpy could not read, in words."""
    if isinstance(exc, EOFError) or "pickled" in str(exc) or isinstance(exc, zipfile.BadZipFile):
        return "the file is empty, truncated or of another kind"
    return str(exc)


def _check_finite_rotations(rotations) -> None:
    """NaN quaternions would be normalised into NaN poses: name the first bad frame and joint."""
    rot = np.asarray(rotations, dtype=float)
    if rot.ndim == 3 and not np.all(np.isfinite(rot)):
        frame, joint = np.argwhere(~np.isfinite(rot))[0][:2]
        raise StimuliError(f"rotations hold NaN/inf at frame {frame} (joint {joint})")


def _json_default(obj):
    """numpy scalars and arrays in metadata become plain JSON."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _depth_levels(parents: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The non-root joints grouped by depth in the tree, root's children first: (joints, their parents) per depth.

    >>> [(ks.tolist(), ps.tolist()) for ks, ps in _depth_levels(np.array([-1, 0, 1, 0, 3]))]
    [([1, 3], [0, 0]), ([2, 4], [1, 3])]
    """
    depth = np.zeros(len(parents), int)
    for k in range(1, len(parents)):
        depth[k] = depth[parents[k]] + 1
    return [(np.flatnonzero(depth == d), parents[depth == d]) for d in range(1, int(depth.max(initial=0)) + 1)]
