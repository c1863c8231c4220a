"""Rendering: bodies × motions × layout → anti-aliased frames (pyrender, offscreen) → H.264 clips.

Public API (see docs/readme_render.md):

- :func:`render_protocol` — every stimulus of a protocol's design into ``clips/``, ``posters/``,
  ``manifest.csv`` and ``contact_sheet.png`` (parallel, resumable).
- :func:`render_frames`, :class:`Figure`, :class:`Look` — one clip's frames from bodies and poses.
- :func:`write_video` — frames → MP4 (yuv420p, +faststart) and a poster PNG, atomically.
- :func:`verify_manifest` — re-hash every clip of a manifest.

Heavy libraries (pyrender, torch) load on first use, not on import.
"""

from stimuli.render.clip import Figure, Look, render_frames
from stimuli.render.manifest import read_manifest, verify_manifest
from stimuli.render.pipeline import RenderReport, render_protocol
from stimuli.render.video import write_video

__all__ = ["Figure", "Look", "RenderReport", "read_manifest", "render_frames", "render_protocol", "verify_manifest",
           "write_video"]
