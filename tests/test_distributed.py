"""The execution layer (issue 24): scheduler specs and their errors, the unchanged default path, and
render, physics protocol and power on a real Dask scheduler with two worker processes on 127.0.0.1
(one of them killed mid-task) giving the files of a local run."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from shapemotion.execution import ENV_VAR, Scheduler, SchedulerError, chosen_scheduler, parse_scheduler

ROOT = Path(__file__).resolve().parents[1]
START_S = 90   # bounded waits for processes on a loaded 2-core machine


# -- scheduler specs ------------------------------------------------------------------------------

@pytest.mark.parametrize("text, expected", [
    ("local:1", Scheduler(local_workers=1)),
    (" local:16 ", Scheduler(local_workers=16)),
    ("tcp://127.0.0.1:8786", Scheduler(address="tcp://127.0.0.1:8786")),
    ("tcp://head-node.cluster:9000", Scheduler(address="tcp://head-node.cluster:9000")),
    ("tcp://[::1]:8786", Scheduler(address="tcp://[::1]:8786")),
])
def test_scheduler_specs(text, expected):
    assert parse_scheduler(text) == expected


@pytest.mark.parametrize("text, message", [
    ("local:0", "--scheduler local:0: N must be a whole number from 1 to 256"),
    ("local:two", "--scheduler local:two: N must be a whole number"),
    ("local:", "--scheduler 'local:': expected tcp://HOST:PORT"),
    ("tcp://host:99999", "--scheduler tcp://host:99999: port 99999 is not between 1 and 65535"),
    ("tcp://host", "--scheduler 'tcp://host': expected tcp://HOST:PORT"),
    ("127.0.0.1:8786", "expected tcp://HOST:PORT (a running 'dask scheduler') or local:N"),
    ("http://host:8787", "expected tcp://HOST:PORT"),
])
def test_malformed_specs_say_what_was_expected(text, message):
    with pytest.raises(SchedulerError) as error:
        parse_scheduler(text)
    assert message in str(error.value)


def test_environment_variable_is_the_default_and_the_option_wins(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert chosen_scheduler(None) is None
    monkeypatch.setenv(ENV_VAR, "  ")
    assert chosen_scheduler(None) is None   # an empty variable is not a scheduler
    monkeypatch.setenv(ENV_VAR, "local:3")
    assert chosen_scheduler(None) == Scheduler(local_workers=3)
    assert chosen_scheduler("tcp://h:1") == Scheduler(address="tcp://h:1")
    monkeypatch.setenv(ENV_VAR, "local:x")
    with pytest.raises(SchedulerError, match=f"^{ENV_VAR}=local:x: N must"):
        chosen_scheduler(None)


def test_the_module_loads_no_dask_and_no_stimuli():
    code = ("import sys, shapemotion.execution; "
            "print(sorted(m for m in ('dask', 'distributed', 'stimuli') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("command", [
    ["render", "protocols/exp1_shape_motion.yaml", "--out", "{tmp}/r"],
    ["physics", "protocol", "protocols/exp2_com_vs_average.yaml", "--out", "{tmp}/p"],
    ["bodies", "protocols/exp1_shape_motion.yaml", "--out", "{tmp}/b"],
])
def test_bad_scheduler_is_exit_2_before_any_output(command, tmp_path, run_cli, monkeypatch):
    import shapemotion.execution as execution

    monkeypatch.setattr(execution, "CONNECT_TIMEOUT_S", 1)
    args = [str(ROOT / a) if a.startswith("protocols/") else a.format(tmp=tmp_path) for a in command]
    code, _, err = run_cli(*args, "--scheduler", "local:-1")
    assert code == 2 and "--scheduler local:-1: N must be a whole number from 1 to 256" in err
    address = f"tcp://127.0.0.1:{_free_port()}"   # nothing listens there
    code, _, err = run_cli(*args, "--scheduler", address)
    assert code == 2 and f"--scheduler {address}: no Dask scheduler answered within 1 s" in " ".join(err.split())
    assert list(tmp_path.iterdir()) == []


def test_power_bad_scheduler_is_exit_2(power_design, run_cli, monkeypatch):
    monkeypatch.setenv(ENV_VAR, "tcp://nowhere")
    code, _, err = run_cli("power", power_design, "--participants", "8", "--sims", "20")
    assert code == 2 and f"{ENV_VAR}='tcp://nowhere': expected tcp://HOST:PORT" in err


def test_without_scheduler_nothing_goes_to_dask(power_design, short_protocol, tmp_path, run_cli, monkeypatch):
    """No option, no variable: the local paths run, the distributed ones are never reached."""
    import analysis.power
    import stimuli.commands.bodies_cmd
    import stimuli.physics.protocol_step
    import stimuli.render.pipeline

    monkeypatch.delenv(ENV_VAR, raising=False)

    def refuse(*args, **kwargs):
        raise AssertionError("the distributed path was taken without --scheduler")

    monkeypatch.setattr(stimuli.render.pipeline, "_run_on", refuse)
    monkeypatch.setattr(analysis.power, "_distributed_results", refuse)
    monkeypatch.setattr(stimuli.commands.bodies_cmd, "_fit_on", refuse)
    monkeypatch.setattr(stimuli.physics.protocol_step, "_FilesByValue", refuse)
    code, out, _ = run_cli("power", power_design, "--participants", "8", "--sims", "20", "--json")
    assert code == 0 and json.loads(out)["rows"]
    code, out, err = run_cli("render", short_protocol, "--out", tmp_path / "r", "--limit", "1", "--resolution",
                             "160x90", "--fps", "10", "--poses", "procedural", "--workers", "1", "--no-progress",
                             "--no-survey")
    assert code == 0, err
    assert "1 rendered" in out and "dask" not in out + err
    code, out, err = run_cli("bodies", ROOT / "protocols" / "exp1_shape_motion.yaml", "--out", tmp_path / "b",
                             "--no-sheet")
    assert code == 0 and "wrote 12 bodies" in out, err
    with stimuli.physics.protocol_step._pool(1, None, print) as pool:   # the physics step's pool: the local one
        assert pool.submit(abs, -3).result() == 3


# -- a real cluster: `dask scheduler` and two `dask worker` processes -------------------------------

@pytest.mark.slow
def test_render_on_a_cluster_equals_local_and_survives_a_killed_worker(short_protocol, tmp_path, run_cli):
    common = ["--only", "F-walk-Hi1", "--resolution", "160x90", "--fps", "10", "--no-progress", "--no-survey"]
    code, _, err = run_cli("render", short_protocol, "--out", tmp_path / "local", "--workers", "1", *common)
    assert code == 0, err
    with _cluster(tmp_path) as (address, workers):
        out = tmp_path / "dask"
        render = subprocess.Popen([sys.executable, "-m", "stimuli.cli", "render", str(short_protocol), "--out",
                                   str(out), "--scheduler", address, *common], stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
        try:
            killed = _kill_once_a_task_runs(workers[0], "shapemotion-render-", render)
            output, _ = render.communicate(timeout=240)
        finally:
            render.kill()
    assert render.returncode == 0, output
    assert killed and f"dask: scheduler {address}, 2 worker(s)" in output
    assert (out / "manifest.csv").read_bytes() == (tmp_path / "local" / "manifest.csv").read_bytes()
    for clip in (tmp_path / "local" / "clips").iterdir():
        assert (out / "clips" / clip.name).read_bytes() == clip.read_bytes()
    assert [p for p in out.rglob("*") if ".tmp" in p.name] == []
    code, verified, _ = run_cli("render", "--verify", "--out", out)
    assert code == 0 and "every clip verifies" in verified


@pytest.mark.slow
def test_physics_protocol_on_a_cluster_equals_local_and_survives_a_killed_worker(tmp_path, monkeypatch):
    from stimuli.bodies.backend import anny_cache_dir, project_cache_root

    protocol = _tiny_exp2(tmp_path)
    outs = {}
    with _cluster(tmp_path) as (address, workers):
        for name in ("local", "dask"):   # each its own physics cache (the bodies' is shared), so both simulate
            cache = tmp_path / f"cache_{name}"
            (cache / "physics").mkdir(parents=True)
            (cache / "bodies").symlink_to(project_cache_root() / "bodies", target_is_directory=True)
            command = [sys.executable, "-m", "stimuli.cli", "physics", "protocol", str(protocol), "--out",
                       str(tmp_path / name)] + (["--scheduler", address] if name == "dask" else ["--workers", "1"])
            # Anny's model data (about 0.8 GB) and Warp's kernels stay where they are: rebuilt under each
            # test cache they cost two minutes and filled a CI disk.
            env = dict(os.environ, SHAPEMOTION_CACHE=str(cache), ANNY_CACHE_DIR=str(anny_cache_dir()),
                       WARP_CACHE_PATH=str(project_cache_root() / "warp"))
            run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
            try:
                killed = name == "local" or _kill_once_a_task_runs(workers[0], "shapemotion-physics-", run)
                outs[name], _ = run.communicate(timeout=240)
            finally:
                run.kill()
            assert run.returncode == 0 and killed, outs[name]
    local, dask = tmp_path / "local", tmp_path / "dask"
    assert "physics: 4 COM motion(s) to simulate, 0 cached" in outs["dask"]
    files = sorted(p.relative_to(local) for p in local.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(dask) for p in dask.rglob("*") if p.is_file())
    for name in files:
        if name.parts[0] == "reports":   # equal but for the wall-clock time of each simulation
            assert _timeless(local / name) == _timeless(dask / name), name
        else:
            assert (local / name).read_bytes() == (dask / name).read_bytes(), name


@pytest.mark.slow
def test_power_and_bodies_on_a_cluster_give_the_local_results(power_design, run_cli, tmp_path):
    args = ["power", power_design, "--participants", "8", "12", "16", "--sims", "300", "--seed", "7", "--json"]
    bodies = ["bodies", ROOT / "protocols" / "exp1_shape_motion.yaml", "--no-sheet", "--out"]
    code, local, err = run_cli(*args)
    assert code == 0, err
    assert run_cli(*bodies, tmp_path / "bodies_local")[0] == 0
    with _cluster(tmp_path) as (address, _):
        code, dask, err = run_cli(*args, "--scheduler", address)
        assert code == 0, err
        code, out, err_bodies = run_cli(*bodies, tmp_path / "bodies_dask", "--scheduler", address)
        assert code == 0, err_bodies
    assert json.loads(dask) == json.loads(local)
    assert f"dask: scheduler {address}, 2 worker(s)" in err and "wrote 12 bodies" in out
    files = sorted(p.relative_to(tmp_path / "bodies_local") for p in (tmp_path / "bodies_local").rglob("*"))
    assert files == sorted(p.relative_to(tmp_path / "bodies_dask") for p in (tmp_path / "bodies_dask").rglob("*"))
    for name in files:
        local_file, dask_file = tmp_path / "bodies_local" / name, tmp_path / "bodies_dask" / name
        assert local_file.is_dir() or local_file.read_bytes() == dask_file.read_bytes(), name


@pytest.mark.slow
def test_a_scheduler_without_workers_is_exit_2(tmp_path, run_cli, monkeypatch):
    import shapemotion.execution as execution

    monkeypatch.setattr(execution, "CONNECT_TIMEOUT_S", 2)
    port = _free_port()
    scheduler = subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
                                  str(port), "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_for_port(port)
        code, _, err = run_cli("bodies", ROOT / "protocols" / "exp1_shape_motion.yaml", "--out", tmp_path / "b",
                               "--scheduler", f"tcp://127.0.0.1:{port}")
    finally:
        scheduler.kill()
        scheduler.wait(timeout=30)
    assert code == 2 and f"tcp://127.0.0.1:{port}: the scheduler has no workers after 2 s" in " ".join(err.split())
    assert not (tmp_path / "b").exists()


# -- helpers --------------------------------------------------------------------------------------

@pytest.fixture
def short_protocol(tmp_path):
    """Exp. 1 with 1.1 s clips (one walk cycle), as tests/test_render_pipeline.py shortens it."""
    data = yaml.safe_load((ROOT / "protocols" / "exp1_shape_motion.yaml").read_text())
    data["clip"].update(duration_s=1.1, cycles=1)
    path = tmp_path / "exp1_short.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture
def power_design(tmp_path):
    from stimuli.cli import main

    out = tmp_path / "design"
    assert main(["design", str(ROOT / "protocols" / "exp1_shape_motion.yaml"), "--out", str(out)]) == 0
    return out


def _tiny_exp2(tmp_path) -> Path:
    """Exp. 2 cut to two female actors, 1.1 s clips and no SEX factor: four COM motions."""
    data = yaml.safe_load((ROOT / "protocols" / "exp2_com_vs_average.yaml").read_text())
    data["actors"] = [a for a in data["actors"] if a["id"] in ("F_Hi1", "F_Lo1")]
    data["factors"] = [f for f in data["factors"] if f["name"] != "SEX"]
    body = next(f for f in data["factors"] if f["name"] == "BODY")
    body.update(levels=["Hi1", "Lo1"], abbreviations={"Hi1": "H1", "Lo1": "L1"})
    data.update(name="tiny_exp2", blocks={"by": ["GAIT"], "nested": False, "order": "counterbalanced"},
                familiarization={"enabled": False})
    data.pop("practice")
    data["clip"].update(duration_s=1.1, cycles=1)
    path = tmp_path / "tiny_exp2.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _timeless(report: Path) -> dict:
    return {k: v for k, v in json.loads(report.read_text()).items() if not k.startswith("wall_")}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def _cluster(tmp_path):
    """A scheduler and two single-thread workers (no nanny, so a SIGKILL ends the worker for good),
    each worker with its own temporary folder; yields (address, [(process, tmpdir), ...])."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "dask"]
    processes = [subprocess.Popen(dask + ["scheduler", "--host", "127.0.0.1", "--port", str(port),
                                          "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    workers = []
    try:
        _wait_for_port(port)
        for i in range(2):
            tmp = tmp_path / f"worker{i}"
            tmp.mkdir()
            worker = subprocess.Popen(dask + ["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                              "--name", f"w{i}", "--local-directory", str(tmp)],
                                      env=dict(os.environ, TMPDIR=str(tmp)), stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL)
            processes.append(worker)
            workers.append((worker, tmp))
        from distributed import Client

        with Client(address, timeout=START_S) as client:
            client.wait_for_workers(2, timeout=START_S)
        yield address, workers
    finally:
        for process in processes:
            process.kill()
            process.wait(timeout=30)


def _wait_for_port(port: int) -> None:
    deadline = time.time() + START_S
    while time.time() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError(f"no dask scheduler on port {port} after {START_S} s")


def _kill_once_a_task_runs(worker, prefix: str, client_process) -> bool:
    """SIGKILL ``worker`` as soon as a task has made its temporary folder there; False if none did
    before the client finished."""
    process, tmp = worker
    deadline = time.time() + START_S * 2
    while time.time() < deadline and client_process.poll() is None:
        if any(p.name.startswith(prefix) for p in tmp.iterdir()):
            process.send_signal(signal.SIGKILL)
            process.wait(timeout=30)
            return True
        time.sleep(0.05)
    return False


def test_execution_examples_run():
    """The docstring examples of shapemotion.execution (scheduler specs, the unused --workers warning)."""
    import doctest

    import shapemotion.execution as execution

    result = doctest.testmod(execution)
    assert result.attempted >= 5 and result.failed == 0


def test_workers_with_a_scheduler_is_said_to_be_unused(tmp_path, monkeypatch, capsys):
    """``render --workers 2 --scheduler local:1`` warns that --workers is not used (the cluster runs the clips),
    before anything is rendered; without --scheduler nothing is said."""
    from shapemotion.execution import chosen_scheduler
    from stimuli.cli import main

    def stop_before_rendering(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("stimuli.render.pipeline.render_protocol", stop_before_rendering)
    # the spec only, no cluster started: the warning is said before any work
    monkeypatch.setattr("shapemotion.execution.scheduler_option", lambda option, error: chosen_scheduler(option))
    protocol = Path(__file__).resolve().parents[1] / "protocols" / "exp1_shape_motion.yaml"
    for extra, said in ((["--scheduler", "local:1"], True), ([], False)):
        code = main(["render", str(protocol), "--out", str(tmp_path / "out"), "--workers", "2", *extra])
        err = capsys.readouterr().err
        assert code == 130 and ("--workers 2 is not used with --scheduler" in err) == said, err
