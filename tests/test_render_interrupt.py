"""A render that is killed or runs out of disk leaves nothing behind (issue 26, items 4 and 7).

- Workers die with their parent (``stimuli.workers``: a parent-death signal and a watchdog, each
  checked alone), and with them multiprocessing's resource tracker: after ``kill -9`` of a real
  ``shapemotion render``, no process of it is alive 10 s later.
- ``kill -9`` of the whole process group leaves temporary folders; the next render sweeps them.
- A full disk gives exit 2 and a message, never an undecodable clip at its final name, and
  ``render --verify`` decodes every clip it hashes.
"""

from __future__ import annotations

import csv
import errno
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
DEATH_LIMIT_S = 10.0   # the acceptance: no process alive 10 s after the kill


@pytest.fixture
def tiny_protocol(tmp_path, protocol_path):
    """Exp 1 with 2-s clips (one whole walk cycle within validation's tolerance at cycles: 1)."""
    data = yaml.safe_load(protocol_path("exp1_shape_motion").read_text())
    data["clip"].update(duration_s=2.0, cycles=1)
    path = tmp_path / "exp1.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _session_processes(session: int) -> list[str]:
    """Live (not zombie) processes of a session, from /proc: 'pid cmdline' each."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:   # it ended while we looked
            continue
        state, _ppid, _pgrp, sid = stat[stat.rindex(")") + 2:].split()[:4]
        if int(sid) == session and state not in "ZX":
            found.append(f"{entry.name} {cmdline[:120]}")
    return found


def _wait_until_gone(session: int, limit_s: float = DEATH_LIMIT_S) -> tuple[list[str], float]:
    """Processes of ``session`` still alive after ``limit_s`` (and how long it took them to go)."""
    start = time.monotonic()
    while time.monotonic() - start < limit_s:
        alive = _session_processes(session)
        if not alive:
            return [], time.monotonic() - start
        time.sleep(0.1)
    return _session_processes(session), time.monotonic() - start


@pytest.fixture(autouse=True)
def _no_process_outlives_a_test():
    """Whatever a test asserts, the sessions it started are killed at its end (a failing test must not
    leave renders running)."""
    yield
    for process in STARTED:
        for line in _session_processes(process.pid):
            try:
                os.kill(int(line.split()[0]), signal.SIGKILL)
            except ProcessLookupError:
                pass
        if process.poll() is None:
            process.wait()
    STARTED.clear()


STARTED: list[subprocess.Popen] = []


def _popen(command: list[str], **kwargs) -> subprocess.Popen:
    """Start ``command`` in its own session (its processes are found by session id)."""
    process = subprocess.Popen(command, cwd=ROOT, start_new_session=True, text=True, **kwargs)
    STARTED.append(process)
    return process


def _start(script: str, tmp_path: Path) -> subprocess.Popen:
    """Run a Python script in its own session."""
    path = tmp_path / "parent.py"
    path.write_text(textwrap.dedent(script))
    return _popen([sys.executable, str(path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _wait_for(path: Path, process: subprocess.Popen, limit_s: float = 120) -> None:
    deadline = time.monotonic() + limit_s
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.05)


CHILD = """
import os, signal, sys, time
from pathlib import Path
from stimuli.workers import die_with_parent, set_parent_death_signal
marker = Path(sys.argv[2])
if sys.argv[1] == "watchdog":      # the watchdog alone, as where prctl does not exist
    die_with_parent(int(sys.argv[3]), use_prctl=False)
else:                              # the kernel's parent-death signal alone
    def leave(signum, frame):
        raise SystemExit(0)
    signal.signal(signal.SIGTERM, leave)
    assert set_parent_death_signal(signal.SIGTERM)
Path(str(marker) + ".ready").touch()
try:
    time.sleep(120)
finally:                           # the clean-up a dying worker must still run
    marker.write_text("cleaned up")
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl and /proc are Linux")
@pytest.mark.parametrize("mechanism", ["watchdog", "prctl"])
def test_a_child_notices_its_parent_killed_and_cleans_up(mechanism, tmp_path):
    (tmp_path / "child.py").write_text(CHILD)
    marker = tmp_path / "marker"
    parent = _start(f"""
        import os, subprocess, sys, time
        subprocess.Popen([sys.executable, {str(tmp_path / 'child.py')!r}, {mechanism!r}, {str(marker)!r},
                          str(os.getpid())])
        time.sleep(120)
        """, tmp_path)
    _wait_for(Path(f"{marker}.ready"), parent)
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    alive, took = _wait_until_gone(parent.pid)
    assert alive == [], f"{mechanism}: still alive {DEATH_LIMIT_S} s after the parent was killed: {alive}"
    assert marker.read_text() == "cleaned up"
    print(f"{mechanism}: the child left {took:.2f} s after its parent was killed")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl and /proc are Linux")
def test_pool_workers_and_resource_tracker_die_with_the_parent(tmp_path):
    """Two workers busy, more tasks queued: after kill -9 of the parent the busy tasks unwind (their
    ``finally`` runs), no queued task starts, and the workers and the resource tracker are gone."""
    started = tmp_path / "started"
    started.mkdir()
    (tmp_path / "slow_task.py").write_text(textwrap.dedent("""
        import time
        from pathlib import Path

        def task(folder, n):
            Path(folder, f"{n}.started").touch()
            try:
                time.sleep(120)
            finally:
                Path(folder, f"{n}.cleaned").touch()
        """))
    parent = _start(f"""
        import sys, time
        sys.path.insert(0, {str(tmp_path)!r})   # spawned workers get this path too
        from slow_task import task
        from stimuli.workers import process_pool
        if __name__ == "__main__":   # spawned workers import this script too
            with process_pool(2) as pool:
                futures = [pool.submit(task, {str(started)!r}, n) for n in range(6)]
                time.sleep(120)
        """, tmp_path)
    deadline = time.monotonic() + 120
    while len(list(started.glob("*.started"))) < 2:
        assert parent.poll() is None, parent.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    before = _session_processes(parent.pid)
    assert any("resource_tracker" in line for line in before), before
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    alive, _ = _wait_until_gone(parent.pid)
    assert alive == []
    assert sorted(p.stem for p in started.glob("*.started")) == sorted(p.stem for p in started.glob("*.cleaned"))
    assert len(list(started.glob("*.started"))) == 2   # the queued tasks never started


def _render_command(protocol: Path, out: Path, limit: int) -> list[str]:
    return [sys.executable, "-m", "stimuli.cli", "render", str(protocol), "--out", str(out), "--limit", str(limit),
            "--resolution", "160x90", "--fps", "10", "--workers", "2", "--poses", "procedural", "--no-progress",
            "--no-survey"]


def _start_render_and_wait_for_workers(protocol: Path, out: Path, limit: int) -> subprocess.Popen:
    """Start a render in its own session; return once a worker is encoding a clip."""
    process = _popen(_render_command(protocol, out, limit), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 180
    while not list(out.glob("clips/.*.tmp")):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the render never started a clip"
        time.sleep(0.05)
    return process


def _leftovers(out: Path) -> list[str]:
    return sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if ".tmp" in p.name)


def _manifest_ids(out: Path) -> list[str]:
    if not (out / "manifest.csv").exists():
        return []
    with open(out / "manifest.csv", newline="") as handle:
        return [row["stimulus_id"] for row in csv.DictReader(handle)]


@pytest.mark.slow   # two real renders with two spawned workers each: ~40–70 s on two shared cores
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux")
def test_killed_render_leaves_no_process_and_the_rerun_no_partial_file(tiny_protocol, tmp_path, run_cli):
    # kill -9 of the main process alone: workers, ffmpeg and the resource tracker follow it.
    out = tmp_path / "alone"
    render = _start_render_and_wait_for_workers(tiny_protocol, out, limit=6)
    workers = [line for line in _session_processes(render.pid) if "spawn_main" in line]
    # Set-up check (there are workers to orphan), not the property tested: on a loaded machine a
    # fresh-clone run once saw a third spawned process of the session at this moment.
    assert len(workers) >= 2, _session_processes(render.pid)
    os.kill(render.pid, signal.SIGKILL)
    render.wait()
    alive, took = _wait_until_gone(render.pid)
    assert alive == [], f"alive {DEATH_LIMIT_S} s after kill -9 of the render: {alive}"
    assert _leftovers(out) == []   # the workers removed their clips' temporary folders
    print(f"kill -9 of the main process: all its processes gone {took:.2f} s later")

    # kill -9 of the whole group: nobody can clean up, so the next render must.
    for attempt in range(3):   # a clip can finish between seeing its folder and the kill: then again
        out = tmp_path / f"group{attempt}"
        render = _start_render_and_wait_for_workers(tiny_protocol, out, limit=3)
        os.killpg(render.pid, signal.SIGKILL)
        render.wait()
        alive, _ = _wait_until_gone(render.pid)
        assert alive == []
        left = _leftovers(out)
        if left:
            break
    assert left and all(name.startswith("clips/.") for name in left), left
    (out / "clips" / "notes.tmp.txt").write_text("a file of the user's, not a temporary of the render")
    code, _, err = run_cli(*_render_command(tiny_protocol, out, limit=3)[3:])
    assert code == 0, err
    assert _leftovers(out) == ["clips/notes.tmp.txt"]
    assert sorted(p.stem for p in (out / "clips").glob("*.mp4")) == sorted(_manifest_ids(out))
    assert len(_manifest_ids(out)) == 3
    code, stdout, err = run_cli("render", "--out", out, "--verify")
    assert code == 0 and "every clip verifies" in stdout, err


def test_a_second_render_into_the_same_folder_is_refused(tiny_protocol, tmp_path):
    from stimuli.errors import StimuliError
    from stimuli.render.pipeline import output_lock, render_protocol

    out = tmp_path / "out"
    out.mkdir()
    with output_lock(out):
        with pytest.raises(StimuliError, match="another 'shapemotion render' is writing into this folder"):
            render_protocol(tiny_protocol, out, limit=1, resolution="160x90", fps=10, workers=1, progress=False,
                            source="procedural", sheet=False)
    assert list(out.iterdir()) == []


# ---- a full disk ------------------------------------------------------------------------------

def _real_write_frames():
    import imageio_ffmpeg

    return imageio_ffmpeg.write_frames


def _failing_writer(real, fail_on_call: int, make_failure):
    """A stand-in for imageio_ffmpeg.write_frames whose ``fail_on_call``-th clip fails as given."""
    calls = []

    def write_frames(path, *args, **kwargs):
        calls.append(path)
        if len(calls) != fail_on_call:
            return real(path, *args, **kwargs)
        return make_failure(path)

    return write_frames


def _no_space_generator(path):
    """ffmpeg's pipe on a full disk: a few frames go in, then the write fails with ENOSPC."""
    Path(path).write_bytes(b"\0" * 100)   # what ffmpeg had written when the disk filled
    frames = 0
    while True:
        yield
        frames += 1
        if frames > 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _undecodable_generator(path):
    """ffmpeg that takes every frame and exits without its index, as on a full disk: imageio does not
    look at its exit status."""
    Path(path).write_bytes(b"\0\0\0\x18ftypisom" + b"\0" * 2000)
    while True:
        yield


def _one_line(message: str) -> str:
    """The CLI wraps its error paragraph at 100 columns."""
    return " ".join(message.split())


def _render_args(protocol, out, limit):
    return ["render", protocol, "--out", out, "--limit", str(limit), "--resolution", "160x90", "--fps", "10",
            "--workers", "1", "--poses", "procedural", "--no-progress", "--no-survey"]


def test_no_space_while_encoding_is_exit_2_and_leaves_nothing_half_written(tiny_protocol, tmp_path, run_cli,
                                                                           monkeypatch):
    import imageio_ffmpeg

    monkeypatch.setattr(imageio_ffmpeg, "write_frames", _failing_writer(_real_write_frames(), 2, _no_space_generator))
    out = tmp_path / "out"
    code, stdout, err = run_cli(*_render_args(tiny_protocol, out, 3))
    assert code == 2, err
    assert "no space left on the device" in _one_line(err) and "Traceback" not in err
    assert "the 1 clip(s) finished in this run are kept and listed in manifest.csv" in _one_line(err)
    assert _leftovers(out) == []
    assert [p.stem for p in (out / "clips").glob("*.mp4")] == _manifest_ids(out) == ["F-walk-Hi1-Hi1"]
    code, stdout, _ = run_cli("render", "--out", out, "--verify")
    assert code == 0


@pytest.mark.parametrize("disk_full", [False, True])
def test_a_clip_that_does_not_decode_never_gets_its_name(disk_full, tiny_protocol, tmp_path, run_cli, monkeypatch):
    import imageio_ffmpeg

    from stimuli.render import video

    monkeypatch.setattr(imageio_ffmpeg, "write_frames",
                        _failing_writer(_real_write_frames(), 1, _undecodable_generator))
    monkeypatch.setattr(video, "disk_nearly_full", lambda folder: disk_full)
    out = tmp_path / "out"
    code, _, err = run_cli(*_render_args(tiny_protocol, out, 2))
    assert code == 2 and "Traceback" not in err
    message = _one_line(err)
    if disk_full:   # ffmpeg's failure on a full disk is put down to the disk: the render stops
        assert "no space left on the device" in message and "0 clip(s) finished in this run are kept" in message
        assert list((out / "clips").glob("*.mp4")) == [] and _manifest_ids(out) == []
    else:           # otherwise it is that clip's failure, named; the render goes on with the rest
        assert "1 stimulus clip(s) could not be rendered" in message and "1 rendered" in message
        assert "clips/<clip>.mp4: ffmpeg wrote a clip that does not decode: " in message   # then ffmpeg's words
        assert [p.stem for p in (out / "clips").glob("*.mp4")] == _manifest_ids(out) == ["F-walk-Hi1-Hi2"]
    assert _leftovers(out) == []


def test_verify_decodes_what_it_hashes(tiny_protocol, tmp_path, run_cli):
    """A clip recorded in the manifest with the hash of a cut-off file (as renders before the decode
    check could record one on a full disk) fails --verify."""
    from stimuli.render.video import sha256_file

    out = tmp_path / "out"
    code, _, err = run_cli(*_render_args(tiny_protocol, out, 2))
    assert code == 0, err
    clip = out / "clips" / "F-walk-Hi1-Hi2.mp4"
    clip.write_bytes(clip.read_bytes()[-3000:])   # the tail only: no header, no index
    rows = list(csv.DictReader(open(out / "manifest.csv", newline="")))
    for row in rows:
        if row["stimulus_id"] == "F-walk-Hi1-Hi2":
            row["sha256"] = sha256_file(clip)
    with open(out / "manifest.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    code, stdout, err = run_cli("render", "--out", out, "--verify")
    assert code == 2
    # ffmpeg's own words depend on what the cut-off bytes hold ("moov atom not found", "Invalid data found
    # when processing input"): the line names the clip and says it does not decode, whatever ffmpeg said
    assert "F-walk-Hi1-Hi2: clips/F-walk-Hi1-Hi2.mp4 does not decode: " in stdout
    assert "F-walk-Hi1-Hi1" not in stdout
    assert "1 clip(s) do not verify" in err


def _mount_tmpfs(folder: Path, size: str) -> None:
    folder.mkdir()
    if not sys.platform.startswith("linux") or shutil.which("mount") is None:
        pytest.skip("needs Linux mount to make a small full disk")
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                            capture_output=True, text=True)
    if result.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here (needs root or CAP_SYS_ADMIN): {result.stderr.strip()}")


def test_a_render_that_fills_a_small_tmpfs_exits_2_and_leaves_only_clips_that_decode(tiny_protocol, tmp_path,
                                                                                     run_cli):
    """The issue's acceptance: ENOSPC on a small tmpfs gives exit 2 and no undecodable clip.
    A 160×90 2-s clip takes ~12 KB, its poster ~3 KB and the manifest ~0.3 KB a row: 64 KB hold a few."""
    from stimuli.render.video import decode_problem

    disk = tmp_path / "disk"
    _mount_tmpfs(disk, "64k")
    try:
        out = disk / "out"
        code, _, err = run_cli(*_render_args(tiny_protocol, out, 16))
        assert code == 2, err
        assert "no space left on the device" in _one_line(err) and "Traceback" not in err
        clips = sorted((out / "clips").glob("*.mp4"))
        assert clips, "the disk filled before the first clip: make the tmpfs larger"
        assert [c.name for c in clips if decode_problem(c, 20)] == []
        assert _leftovers(out) == []
        if _manifest_ids(out):
            code, stdout, err = run_cli("render", "--out", out, "--verify")
            assert code == 0, stdout + err
    finally:
        subprocess.run(["umount", str(disk)], check=False)


@pytest.mark.parametrize("module", ["stimuli.workers", "stimuli.render.pipeline", "stimuli.render.video"])
def test_docstring_examples(module):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(module))
    assert result.attempted > 0 and result.failed == 0
