"""Bodies speed and accuracy: Anny load, fit per body (cold and cached), a cached CLI re-run, skinning per
frame (batched), forward kinematics, contact-sheet rendering; with the height/BMI error of every Table 2
actor. Prints figures; asserts nothing.

    .venv/bin/python benchmarks/bodies_bench.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from stimuli.bodies import backend  # noqa: E402

TABLE2 = [("F_Hi1", "F", 1.60, 28.1), ("F_Hi2", "F", 1.64, 25.3), ("F_Lo1", "F", 1.60, 24.8),
          ("F_Lo2", "F", 1.60, 19.5), ("M_Hi1", "M", 1.79, 32.1), ("M_Hi2", "M", 1.83, 35.8),
          ("M_Lo1", "M", 1.81, 22.7), ("M_Lo2", "M", 1.82, 21.7)]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="fewer frames, no CLI re-run")
    args = parser.parse_args()
    # Keep Anny's model cache where it is; put the body cache in a fresh folder so fits are cold.
    os.environ.setdefault("ANNY_CACHE_DIR", str(backend.anny_cache_dir()))
    tmp = Path(tempfile.mkdtemp(prefix="bodies_bench_"))
    os.environ["SHAPEMOTION_CACHE"] = str(tmp)
    cache_existed = any(Path(os.environ["ANNY_CACHE_DIR"]).glob("v*/*.safetensors"))

    start = time.perf_counter()
    backend.model()
    total = time.perf_counter() - start
    print(f"Anny {backend.anny_version()}: import torch+anny {backend.LOAD_SECONDS['import']:.2f} s, model "
          f"{backend.LOAD_SECONDS['model']:.2f} s ({'cache existed' if cache_existed else 'built the cache'}), "
          f"total {total:.2f} s")

    from stimuli.bodies import fit_body

    start = time.perf_counter()
    from stimuli.bodies.fit import Targets, _start_grid

    _start_grid("F", 30.0), _start_grid("M", 30.0)
    print(f"start grids (once per process, 2 sexes × 18 bodies): {time.perf_counter() - start:.2f} s")
    print(f"{'actor':<7}{'target H':>9}{'H':>8}{'dH cm':>8}{'target BMI':>11}{'BMI':>7}{'dBMI':>7}"
          f"{'cold s':>8}{'cached s':>9}")
    cold, cached = [], []
    for body_id, sex, height, bmi in TABLE2:
        start = time.perf_counter()
        body = fit_body(sex, height, bmi, body_id=body_id)
        cold.append(time.perf_counter() - start)
        start = time.perf_counter()
        fit_body(sex, height, bmi, body_id=body_id)
        cached.append(time.perf_counter() - start)
        a = body.anthropometry
        print(f"{body_id:<7}{height:>9.3f}{a.height_m:>8.4f}{(a.height_m - height) * 100:>8.3f}{bmi:>11.1f}"
              f"{a.bmi:>7.3f}{a.bmi - bmi:>7.3f}{cold[-1]:>8.3f}{cached[-1]:>9.4f}")
    print(f"fit per body: cold median {np.median(cold):.3f} s (max {max(cold):.3f}), "
          f"cached median {np.median(cached) * 1000:.1f} ms")

    frames = 30 if args.quick else 120
    rng = np.random.default_rng(0)
    rot, root = body.rest_pose()
    quats = np.tile(rot, (frames, 1, 1))
    quats[:, :, 1:] = rng.normal(scale=0.1, size=(frames, body.rig.n_bones, 3))
    roots = np.tile(root, (frames, 1))
    body.skin(quats[:2], roots[:2])  # warm-up (kernel load)
    start = time.perf_counter()
    body.joint_positions(quats, roots)
    fk = time.perf_counter() - start
    out = np.empty((frames, body.n_vertices, 3), dtype=np.float32)
    start = time.perf_counter()
    body.skin(quats, roots, out=out)
    skin = time.perf_counter() - start
    print(f"skinning {frames} frames × {body.n_vertices} vertices: {skin * 1000 / frames:.2f} ms/frame "
          f"({frames / skin:.0f} frames/s); forward kinematics alone {fk * 1000 / frames:.3f} ms/frame")

    from stimuli.bodies.contact_sheet import contact_sheet
    from stimuli.bodies.api import fit_body as fit

    bodies = [fit(s, h, b, body_id=i) for i, s, h, b in TABLE2]
    start = time.perf_counter()
    contact_sheet(bodies, tmp / "sheet.png")
    print(f"contact sheet of 8 bodies (16 renders, EGL): {time.perf_counter() - start:.2f} s")

    if not args.quick:
        exe = ROOT / ".venv" / "bin" / "shapemotion"
        for label in ("first run (bodies cache empty)", "second run (cached)"):
            cli_cache = tmp / "cli_cache"
            start = time.perf_counter()
            subprocess.run([str(exe), "bodies", str(ROOT / "protocols" / "exp1_shape_motion.yaml"), "--out",
                            str(tmp / "cli"), "--no-sheet"], check=True, capture_output=True,
                           env={**os.environ, "SHAPEMOTION_CACHE": str(cli_cache)})
            print(f"shapemotion bodies exp1 (12 bodies, no sheet), {label}: {time.perf_counter() - start:.2f} s")
    _ = Targets


if __name__ == "__main__":
    main()
