"""On-disk cache of fitted bodies, keyed by (Anny version, fitter version and code, targets).

A cached body is one ``.npz`` (mesh, rig, JSON metadata with anthropometry, segments and fit
report), so a cached run needs neither torch nor the Anny model. Files are written atomically.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
from pathlib import Path

import numpy as np

from stimuli.bodies import backend
from stimuli.bodies.body import Body, FitReport
from stimuli.bodies.measure import Anthropometry
from stimuli.bodies.rig import Rig
from stimuli.bodies.segments import Segment

FORMAT_VERSION = "1"
_VECTORS = ("proximal", "distal", "com_geometric", "com_table", "com_volume")


def cache_dir() -> Path:
    return backend.project_cache_root() / "bodies"


def cache_key(targets_key: dict, fitter_version: str) -> str:
    """Hex digest of everything that determines a body."""
    payload = {"backend": "anny", "anny": backend.anny_version(), "fitter": fitter_version,
               "code": backend.code_digest(), "format": FORMAT_VERSION, "targets": targets_key}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:24]


def save(body: Body, key: str) -> Path:
    from stimuli.fileio import atomic_write_bytes

    meta = {
        "sex": body.sex, "targets": body.targets, "phenotype": body.phenotype, "names": body.rig.names,
        "anthropometry": body.anthropometry.as_dict(), "fit": dataclasses.asdict(body.fit),
        "segments": [_segment_dict(s) for s in body.segments],
    }
    buffer = io.BytesIO()
    np.savez(buffer, vertices=body.vertices, faces=body.faces.astype(np.int32), parents=body.rig.parents,
             heads=body.rig.rest_heads, tails=body.rig.rest_tails, rotations=body.rig.rest_rotations,
             meta=np.array(json.dumps(meta)))
    path = cache_dir() / f"{key}.npz"
    atomic_write_bytes(path, buffer.getvalue())
    return path


def load(key: str, body_id: str) -> Body | None:
    """The cached body for ``key`` (with ``fit.cached`` True), or None when absent or unreadable."""
    path = cache_dir() / f"{key}.npz"
    if not path.exists():
        return None
    try:
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            rig = Rig(names=meta["names"], parents=data["parents"].astype(np.int64), rest_heads=data["heads"],
                      rest_tails=data["tails"], rest_rotations=data["rotations"])
            vertices, faces = data["vertices"], data["faces"].astype(np.int64)
    except (OSError, ValueError, KeyError):
        return None  # a damaged entry is rebuilt, never trusted
    fit = FitReport(**{**meta["fit"], "cached": True})
    segments = [Segment(**{k: np.asarray(v) if k in _VECTORS else v for k, v in s.items()}) for s in meta["segments"]]
    return Body(body_id=body_id, sex=meta["sex"], targets=meta["targets"], phenotype=meta["phenotype"],
                vertices=vertices, faces=faces, rig=rig, anthropometry=Anthropometry(**meta["anthropometry"]),
                segments=segments, fit=fit)


def _segment_dict(segment: Segment) -> dict:
    out = dataclasses.asdict(segment)
    for key in _VECTORS:
        out[key] = [float(x) for x in out[key]]
    return out
