"""Render speed: frames per second for one and two bodies at 640×360 and 1280×720, and the time
for the whole Experiment-1 set (64 test + 16 practice clips, 4 s, 30 fps, 1280×720, 2 workers).

    .venv/bin/python benchmarks/render_bench.py            # fps table + the Exp-1 set
    .venv/bin/python benchmarks/render_bench.py --no-set   # fps table only

Frames per second include everything per frame: skinning, normals, the in-place vertex upload,
rendering (4× MSAA), read-back and H.264 encoding. Poses are the renderer's procedural stepping
pose on real fitted Anny bodies (the cost of a frame does not depend on which motion it shows);
``--poses protocol`` renders the Exp-1 set from the protocol's real motions once they exist.
Prints the OpenGL device (llvmpipe = software rendering on the CPU).
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def children_cpu() -> float:
    """CPU seconds of finished child processes (ffmpeg, pool workers and their ffmpegs)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def clip_fps(n_bodies: int, width: int, height: int, seconds: float = 2.0, fps: int = 30):
    """(wall-clock fps, CPU ms per frame here, CPU ms per frame in ffmpeg) of one clip, encoded to MP4."""
    from stimuli.bodies import fit_body
    from stimuli.render.clip import Figure, Look, render_frames
    from stimuli.render.procedural import stepping_pose
    from stimuli.render.video import write_video

    body = fit_body("M", 1.81, 22.7)
    layout = "treadmill" if n_bodies == 1 else "side_by_side"
    look = Look(layout, width, height, fps, seconds, 35.0 if n_bodies == 1 else 20.0, 10.0,
                4.0 if n_bodies == 1 else 5.0, 40.0 if n_bodies == 1 else 45.0)
    rot, root = stepping_pose(body, look.n_frames)
    figures = [Figure(body, rot, root, 1.2) for _ in range(n_bodies)]
    with tempfile.TemporaryDirectory() as tmp:
        write_video(render_frames(look, figures), Path(tmp) / "warm.mp4", fps, width, height, look.n_frames)
        wall, cpu, enc = time.perf_counter(), time.process_time(), children_cpu()
        write_video(render_frames(look, figures), Path(tmp) / "clip.mp4", fps, width, height, look.n_frames)
        wall, cpu, enc = time.perf_counter() - wall, time.process_time() - cpu, children_cpu() - enc
    return look.n_frames / wall, 1000 * cpu / look.n_frames, 1000 * enc / look.n_frames


def exp1_set(poses: str, workers: int) -> tuple[float, int, float]:
    """Wall seconds for the whole Exp-1 set at the protocol's settings, clips, CPU seconds (all processes)."""
    from stimuli.render.pipeline import render_protocol

    with tempfile.TemporaryDirectory() as tmp:
        start, cpu = time.perf_counter(), time.process_time() + children_cpu()
        report = render_protocol(ROOT / "protocols" / "exp1_shape_motion.yaml", tmp, workers=workers,
                                 source=poses, progress=True, sheet=False)
        cpu = time.process_time() + children_cpu() - cpu
        return time.perf_counter() - start, len(report.rendered), cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-set", action="store_true", help="skip the whole Exp-1 set")
    parser.add_argument("--poses", choices=["procedural", "protocol"], default="procedural")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    from stimuli.render.gl import device_name, renderer

    renderer(64, 64)
    print(f"OpenGL device: {device_name()}   PYOPENGL_PLATFORM={os.environ.get('PYOPENGL_PLATFORM')}   "
          f"CPU cores: {os.cpu_count()}   load average: {os.getloadavg()[0]:.1f}")
    print(f"{'bodies':>6} {'resolution':>11} {'fps (wall)':>11} {'CPU ms/frame':>13} {'+ ffmpeg ms':>12}")
    for n in (1, 2):
        for w, h in ((640, 360), (1280, 720)):
            fps, cpu_ms, enc_ms = clip_fps(n, w, h)
            print(f"{n:>6} {f'{w}x{h}':>11} {fps:>11.1f} {cpu_ms:>13.1f} {enc_ms:>12.1f}")
    if not args.no_set:
        seconds, clips, cpu = exp1_set(args.poses, args.workers)
        cores = min(args.workers, os.cpu_count() or 1)
        print(f"Exp-1 set: {clips} clips (4 s, 30 fps, 1280x720) in {seconds:.0f} s ({seconds / 60:.1f} min) "
              f"with {args.workers} workers; {cpu:.0f} CPU s in all processes = {cpu / cores / 60:.1f} min "
              f"on {cores} otherwise idle cores; load average now {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
