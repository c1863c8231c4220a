"""H.264 MP4 files that play in every browser: yuv420p, +faststart, an exact frame count.

Frames go straight into an ffmpeg process (imageio-ffmpeg) writing a temporary file next to the
target; only a complete file is renamed into place, so Ctrl-C or a crash never leaves half a
clip. The poster (a PNG of the first frame) is written the same way.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.interrupts import check_interrupted
from stimuli.workers import at_forced_exit

CRF = 20                   # visually lossless for these flat-shaded scenes
PRESET = "superfast"       # ~9 ms per 720p frame (veryfast: ~17 ms for files 2.4× smaller, ~0.8 MB per 4 s)
# One x264 thread: its default (1.5 × the machine's cores) made a clip's bytes depend on the machine
# (frame threads change the encoding), and the render workers keep the cores busy anyway (one
# thread costs 3–7 % less CPU per frame; it encodes a 720p frame in ~6 ms, the render takes ~28).
ENCODER_THREADS = 1


class BrokenClip(StimuliError):
    """ffmpeg finished, but the file it wrote does not decode to the frames sent."""


@dataclass(frozen=True)
class VideoInfo:
    path: Path
    n_frames: int
    sha256: str


def sha256_file(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _temp_name(path: Path, suffix: str) -> Path:
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{suffix}")


def check_size(width: int, height: int) -> None:
    """yuv420p needs even sizes; say so instead of letting ffmpeg fail or pad silently."""
    if width % 2 or height % 2 or width < 16 or height < 16:
        raise StimuliError(f"--resolution: H.264 yuv420p needs even width and height of at least 16, got {width}x{height}")


def write_video(frames, path: str | Path, fps: int, width: int, height: int, n_frames: int,
                poster: str | Path | None = None) -> VideoInfo:
    """Encode exactly ``n_frames`` frames from the iterator into ``path`` (atomically)."""
    import imageio_ffmpeg

    check_size(width, height)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # ffmpeg writes inside a private temporary folder: if it is interrupted while starting up, it can
    # still create its output after we cleaned up, but not in a folder that no longer exists.
    tmp_dir = Path(tempfile.mkdtemp(prefix=f".{path.stem}.", suffix=".tmp", dir=path.parent))
    _OPEN_TEMPORARIES.add(tmp_dir)
    tmp = tmp_dir / path.name
    writer = imageio_ffmpeg.write_frames(
        str(tmp), (width, height), fps=fps, codec="libx264", pix_fmt_in="rgb24", pix_fmt_out="yuv420p",
        quality=None, macro_block_size=1, ffmpeg_log_level="error",
        output_params=["-crf", str(CRF), "-preset", PRESET, "-movflags", "+faststart", "-g", str(fps * 2),
                       "-threads", str(ENCODER_THREADS)])
    count = 0
    try:
        writer.send(None)
        for frame in frames:
            check_interrupted()
            if count == 0 and poster is not None:
                write_png(frame, poster)
            writer.send(np.ascontiguousarray(frame))
            count += 1
        writer.close()
        if count != n_frames:
            raise RuntimeError(f"{path.name}: rendered {count} frames, expected {n_frames}")
        # imageio does not look at ffmpeg's exit status: on a full disk ffmpeg stops writing and the
        # file lacks its index ("moov atom not found"). Only a clip that decodes gets its name.
        problem = decode_problem(tmp, n_frames)
        if problem:
            raise BrokenClip(f"{path}: ffmpeg wrote a clip that {problem}")
        os.replace(tmp, path)
        tmp_dir.rmdir()
        _OPEN_TEMPORARIES.discard(tmp_dir)
    except BaseException as exc:
        # Looked at before the clean-up frees the space the clip took.
        full = isinstance(exc, (OSError, BrokenClip)) and not _is_no_space(exc) and disk_nearly_full(tmp_dir)
        # The clip is discarded: imageio kills ffmpeg on a BaseException thrown in (close() would
        # wait for it to start up and finish the file). ffmpeg shares the terminal's process group,
        # so on Ctrl-C it is interrupted too and stopping the writer may raise; the temporary folder
        # must go whatever happens.
        try:
            writer.throw(_DiscardClip())
        except BaseException:
            pass
        finally:
            shutil.rmtree(tmp_dir, ignore_errors=True)
            _OPEN_TEMPORARIES.discard(tmp_dir)
        if full:   # ffmpeg failed or quit (a broken pipe) on a full disk: say so
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path.parent)) from exc
        raise
    return VideoInfo(path, count, sha256_file(path))


class _DiscardClip(BaseException):
    """Thrown into imageio's writer to have it kill ffmpeg instead of waiting for it."""


# Temporary folders of clips being written in this process: removed by the death watch should this
# worker have to be ended before write_video could clean up (stimuli.workers.at_forced_exit).
_OPEN_TEMPORARIES: set[Path] = set()


def _remove_open_temporaries() -> None:
    for folder in list(_OPEN_TEMPORARIES):
        shutil.rmtree(folder, ignore_errors=True)


at_forced_exit(_remove_open_temporaries)


LOW_SPACE_BYTES = 1 << 20  # below this, a clip that ffmpeg could not finish is put down to a full disk


def _is_no_space(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)


def disk_nearly_full(folder: str | Path) -> bool:
    """Whether the disk holding ``folder`` has less than :data:`LOW_SPACE_BYTES` left for this user
    (ffmpeg reports a full disk only on its own stderr, so the free space is what tells it apart)."""
    try:
        return shutil.disk_usage(folder).free < LOW_SPACE_BYTES
    except OSError:
        return False


def decode_problem(path: str | Path, n_frames: int | None = None) -> str:
    """Why the video at ``path`` does not decode completely ('' when it does): every frame of its first
    video stream is decoded by ffmpeg (imageio-ffmpeg's binary) and, with ``n_frames``, counted.

    Decoding a rendered 4-s 720p clip takes about 0.15 s of one core (rendering it, about 4 s); the
    deblocking filter is skipped (a post-filter on decoded pixels: it finds no broken stream, and
    skipping it saves ~12 % of the decode).

    >>> decode_problem(__file__).startswith("does not decode: ")   # this Python file is no video
    True
    """
    import subprocess

    import imageio_ffmpeg

    command = [imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-xerror", "-threads", "1",
               "-skip_loop_filter", "all", "-i", str(path), "-map", "0:v:0", "-f", "framecrc", "-"]
    result = subprocess.run(command, capture_output=True, text=True, errors="replace")
    errors = [line.strip() for line in result.stderr.splitlines() if line.strip()]
    if result.returncode != 0 or errors:
        first = next((line for line in errors if "moov atom" in line), errors[0] if errors else
                     f"ffmpeg exit status {result.returncode}")
        return f"does not decode: {first.split('] ', 1)[-1]}"
    frames = sum(1 for line in result.stdout.splitlines() if line and not line.startswith("#"))
    if n_frames is not None and frames != n_frames:
        return f"decodes to {frames} frame(s), expected {n_frames}"
    return ""


def write_png(frame: np.ndarray, path: str | Path) -> Path:
    """Save one frame as PNG via a temporary name."""
    import imageio.v3 as iio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # Encoded in memory first: imageio writing the file itself, on a full disk, fails a second time
    # when the plugin is collected ("Exception ignored in PluginV3.__del__" with a traceback).
    data = iio.imwrite("<bytes>", frame, extension=".png")
    tmp = _temp_name(path, ".png")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def read_video(path: str | Path) -> tuple[np.ndarray, dict]:
    """All frames (T, H, W, 3) and the stream's metadata (fps, size) — for tests and checks."""
    import imageio.v3 as iio

    frames = iio.imread(path, plugin="pyav") if _has_pyav() else np.stack(list(iio.imiter(path, plugin="FFMPEG")))
    meta = iio.immeta(path, plugin="FFMPEG")
    return frames, meta


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True
