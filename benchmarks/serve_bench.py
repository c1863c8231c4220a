"""Benchmark of ``shapemotion serve``: 100 simulated participants posting their answers at once.

Starts the real server (uvicorn, one process, SQLite in WAL mode) on 127.0.0.1 with a design of 100
lists × 32 trials (4 bodies × 8 repetitions; the bundled Experiment 2 protocol has 64 test trials a
participant, 32 keeps the run short), then 100 participants each start a session and post every
trial as fast as the server answers (httpx, asyncio; ``--think-s 1`` paces them like people watching
clips). Prints the throughput (stored trials per second) and the latency percentiles of the trial
requests. A lab's busiest minute is a few hundred trials: the server needs a few trials per second.
The server runs with its rate limit (``--rate``, default the server's 5/s per session, burst 100); a
request refused with 429 is sent again after its Retry-After, as the page does, and counted.

    .venv/bin/python benchmarks/serve_bench.py [--participants 100] [--think-s 1] [--rate 0]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PROTOCOL = """
name: serve_bench
seed: 3
participants: {participants}
actors:
  - {{id: F_A, label: A, sex: F, height_m: 1.60, bmi: 20}}
  - {{id: F_B, label: B, sex: F, height_m: 1.60, bmi: 24}}
  - {{id: F_C, label: C, sex: F, height_m: 1.60, bmi: 28}}
  - {{id: F_D, label: D, sex: F, height_m: 1.60, bmi: 32}}
factors:
  - {{name: BODY, role: within, levels: [A, B, C, D], maps_to: body}}
display: {{layout: treadmill}}
clip: {{duration_s: 1, fps: 10, width: 64, height: 64}}
repetitions: 8
response: {{type: likert, question: 'How heavy?', labels: ['1', '2', '3', '4', '5', '6', '7']}}
analysis: {{dependent_measure: mean_rating}}
"""
ADMIN = "benchmark-admin-token"


def make_design(folder: Path, participants: int) -> None:
    import pandas as pd

    from stimuli.design import build_design, write_design
    from stimuli.protocol import parse_protocol

    write_design(build_design(parse_protocol(PROTOCOL.format(participants=participants))), folder)
    for sid in pd.read_csv(folder / "conditions.csv")["stimulus_id"]:
        (folder / "clips").mkdir(exist_ok=True)
        (folder / "clips" / f"{sid}.mp4").write_bytes(b"placeholder: the benchmark posts answers only")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(design: Path, port: int, rate: str | None) -> subprocess.Popen:
    limit = ["--rate", rate] if rate is not None else []
    proc = subprocess.Popen([sys.executable, "-m", "stimuli.cli", "serve", str(design), "--port", str(port),
                             "--admin-token", ADMIN, *limit], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=ROOT)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            httpx.get(f"http://127.0.0.1:{port}/config.js", timeout=1)
            return proc
        except httpx.TransportError:
            time.sleep(0.2)
    proc.kill()
    raise SystemExit("the server did not start within 60 s")


async def post(client: httpx.AsyncClient, path: str, limited: list[int], **kwargs) -> httpx.Response:
    """POST, sent again after the Retry-After of a 429 (as the page does); each 429 counted in ``limited``."""
    while (r := await client.post(path, **kwargs)).status_code == 429:
        limited.append(1)
        await asyncio.sleep(int(r.headers["retry-after"]))
    return r


async def participant(client: httpx.AsyncClient, n: int, latencies: list[float], think_s: float,
                      limited: list[int]) -> int:
    r = await post(client, "/api/sessions", limited, json={"params": {"PROLIFIC_PID": f"bench{n}"}})
    state = r.json()
    headers = {"X-Session-Token": state["token"]}
    pause = random.Random(n)
    for trial in state["trials"]:
        if think_s:   # a participant watching the clip: think_s ± 50 % between answers
            await asyncio.sleep(think_s * pause.uniform(0.5, 1.5))
        t0 = time.perf_counter()
        r = await post(client, f"/api/sessions/{state['session']}/trials", limited, headers=headers,
                       json={"index": trial["index"], "response": (n + trial["index"]) % 7, "rt": 900})
        latencies.append(time.perf_counter() - t0)
        if r.status_code != 200:
            raise SystemExit(f"participant {n}, trial {trial['index']}: {r.status_code} {r.text}")
    r = await post(client, f"/api/sessions/{state['session']}/finish", limited, headers=headers, json={})
    return len(state["trials"])


async def run(url: str, participants: int, think_s: float, limited: list[int]) -> tuple[int, float, list[float]]:
    latencies: list[float] = []
    limits = httpx.Limits(max_connections=participants)
    async with httpx.AsyncClient(base_url=url, limits=limits, timeout=60) as client:
        t0 = time.perf_counter()
        counts = await asyncio.gather(*(participant(client, n, latencies, think_s, limited) for n in range(participants)))
        elapsed = time.perf_counter() - t0
    return sum(counts), elapsed, latencies


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", type=int, default=100)
    parser.add_argument("--think-s", type=float, default=0.0,
                        help="seconds between a participant's answers (0: as fast as the server answers)")
    parser.add_argument("--rate", default=None, help="the server's --rate (default: its own; 0: no limit)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        design = Path(tmp) / "design"
        make_design(design, args.participants)
        port = free_port()
        proc = start_server(design, port, args.rate)
        limited: list[int] = []
        try:
            trials, elapsed, latencies = asyncio.run(run(f"http://127.0.0.1:{port}", args.participants,
                                                         args.think_s, limited))
            stored = httpx.get(f"http://127.0.0.1:{port}/admin/progress",
                               headers={"Authorization": f"Bearer {ADMIN}"}).json()
        finally:
            proc.kill()
            proc.wait(10)
    in_db = sum(p["answers"] for p in stored)
    finished = sum(p["finished"] for p in stored)
    ms = np.array(latencies) * 1000
    pace = f"one answer every {args.think_s:g} s ± 50 % each" if args.think_s else "as fast as answered"
    print(f"serve: {args.participants} participants at once ({pace}), {trials} trials in {elapsed:.2f} s "
          f"on {os.cpu_count()} CPUs")
    print(f"  throughput  {trials / elapsed:.0f} trials/s")
    print(f"  latency     p50 {np.percentile(ms, 50):.1f} ms, p99 {np.percentile(ms, 99):.1f} ms, "
          f"max {ms.max():.1f} ms")
    print(f"  stored      {in_db} answers, {finished} sessions finished")
    print(f"  rate limit  {args.rate or 'server default'}: {len(limited)} requests refused with 429 and sent again"
          f" (the latencies above include the waits)")
    if in_db != trials or finished != args.participants:
        print("error: the database does not hold every posted trial", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
