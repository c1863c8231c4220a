"""Overhead of ``--scheduler`` (a Dask scheduler and its workers) against the local process pool, and
its scaling from one worker to two, for a render of Exp. 1 clips and for a power sweep.

Each configuration runs the real command (``python -m stimuli.cli ...``) into a fresh folder:

- ``pool``: the default local pool (``--workers N``);
- ``dask N``: ``--scheduler tcp://127.0.0.1:PORT`` with N ``dask worker`` processes (one thread each),
  started beforehand, so their start-up is not counted (it is printed once; ``local:N`` pays it on every
  run);
- ``local:2``: the same, with the command starting its own cluster.

Reported per run: wall seconds and CPU seconds (the command and its children, plus the dask workers'
and scheduler's own CPU time). Wall time on a shared, loaded machine is noisy: compare CPU seconds too.
Numbers only; nothing is asserted.

    python benchmarks/distributed_bench.py [--steps render,power] [--clips F-walk] [--sims 4000]
"""

from __future__ import annotations

import argparse
import os
import resource
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "stimuli.cli"]


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def process_cpu(pids: list[int]) -> float:
    import psutil   # a dependency of distributed

    return sum(sum(psutil.Process(pid).cpu_times()[:2]) for pid in pids)


def timed(command: list[str], cluster_pids: list[int]) -> tuple[float, float]:
    """(wall s, CPU s) of one command, the cluster's processes' CPU included."""
    cpu0, cluster0, start = children_cpu(), process_cpu(cluster_pids), time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    return time.perf_counter() - start, children_cpu() - cpu0 + process_cpu(cluster_pids) - cluster0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def cluster(workers: int):
    """A ``dask scheduler`` and ``workers`` single-thread ``dask worker`` s on 127.0.0.1; yields
    (address, pids, seconds until all workers were connected)."""
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    start = time.perf_counter()
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
                                   str(port), "--no-dashboard"], **quiet)]
    try:
        processes += [subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nthreads", "1",
                                        "--no-nanny", "--no-dashboard"], **quiet) for _ in range(workers)]
        with Client(address, timeout=120) as client:
            client.wait_for_workers(workers, timeout=120)
        yield address, [p.pid for p in processes], time.perf_counter() - start
    finally:
        for p in processes:
            p.kill()
            p.wait()


def short_protocol(folder: Path, duration: float) -> Path:
    import yaml

    data = yaml.safe_load((ROOT / "protocols" / "exp1_shape_motion.yaml").read_text())
    data["clip"].update(duration_s=duration, cycles=1)
    path = folder / "exp1.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def compare(name: str, make_command, folder: Path, local: list[str]) -> None:
    """Run ``make_command(out, options)`` without a scheduler (``local`` options), then on clusters of 1 and
    2 workers and on local:2."""
    rows = []
    runs = [(f"no scheduler {' '.join(local)}", None, local)]
    runs += [(f"dask, {n} worker(s)", n, None) for n in (1, 2)]
    for label, workers, extra in runs:
        out = folder / f"{name}_{len(rows)}"
        if workers is None:
            rows.append((label,) + timed(make_command(out, extra), []))
            continue
        with cluster(workers) as (address, pids, startup):
            print(f"  ({label}: scheduler and workers connected after {startup:.1f} s, not counted below)")
            rows.append((label,) + timed(make_command(out, ["--scheduler", address]), pids))
    out = folder / f"{name}_local2"
    local2 = timed(make_command(out, ["--scheduler", "local:2"]), [])
    rows.append(("local:2 (the command starts its cluster)", *local2))
    base_wall, base_cpu = rows[0][1], rows[0][2]
    print(f"{name}:")
    for label, wall, cpu in rows:
        print(f"  {label:<42} wall {wall:7.1f} s ({100 * (wall / base_wall - 1):+5.1f} %)   "
              f"CPU {cpu:7.1f} s ({100 * (cpu / base_cpu - 1):+5.1f} %)")
    one, two = rows[1][1], rows[2][1]
    print(f"  scaling 1 -> 2 workers: {one / two:.2f}x faster (wall)")


def bench_render(args, tmp: Path) -> None:
    protocol = short_protocol(tmp, args.duration)
    render = [*CLI, "render", str(protocol), "--only", args.clips, "--resolution", args.resolution, "--fps",
              args.fps, "--no-progress", "--no-survey"]
    print(f"render: Exp. 1 clips matching {args.clips!r}, {args.duration} s, {args.resolution} at {args.fps} fps")
    compare("render", lambda out, extra: render + ["--out", str(out)] + extra, tmp, ["--workers", "2"])


def bench_power(args, tmp: Path) -> None:
    subprocess.run([*CLI, "design", str(ROOT / "protocols" / "exp1_shape_motion.yaml"), "--out",
                    str(tmp / "design")], check=True, stdout=subprocess.DEVNULL, cwd=ROOT)
    power = [*CLI, "power", str(tmp / "design"), "--participants", *args.participants.split(), "--sims",
             args.sims, "--seed", "1", "--json"]
    print(f"power: Exp. 1 null model, N = {args.participants}, {args.sims} data sets per N "
          "(without a scheduler the sweep runs serially: power has no process pool)")
    compare("power", lambda out, extra: power + extra, tmp, [])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", default="F-walk", help="--only of the render (default F-walk: 20 clips)")
    parser.add_argument("--duration", type=float, default=1.1, help="clip seconds (default 1.1, one walk cycle)")
    parser.add_argument("--resolution", default="320x180")
    parser.add_argument("--fps", default="15")
    parser.add_argument("--sims", default="4000", help="power: data sets per N")
    parser.add_argument("--participants", default="8 12 16 20 24 28 32 36", help="power: the N swept")
    parser.add_argument("--steps", default="render,power", help="which of render,power to measure")
    args = parser.parse_args(argv)
    print(f"machine: {os.cpu_count()} CPU(s), load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        if "render" in args.steps:
            bench_render(args, Path(tmp))
        if "power" in args.steps:
            bench_power(args, Path(tmp))
    return 0


if __name__ == "__main__":
    sys.exit(main())
