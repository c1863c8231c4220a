"""The render pipeline on the bundled protocols (shortened to 1.1 s clips, 160×90 … 320×180):
manifest columns and hashes, resuming, side-by-side placement, errors, the CLI."""

from __future__ import annotations

import csv
import ctypes
import os
import signal
import subprocess
import sys
import time

from pathlib import Path

import numpy as np
import pytest
import yaml

DESIGN_COLUMNS = ["stimulus_id", "file", "sha256", "width", "height", "fps", "n_frames", "duration_s", "layout"]


@pytest.fixture
def short_protocol(tmp_path, protocol_path):
    """A bundled protocol with short clips (same design), written to tmp_path: 1.1 s holds one whole
    walk cycle at 112 steps/min (1.07 s), the shortest clip validation accepts (with ``cycles: 1``)."""

    def make(name, duration=1.1):
        data = yaml.safe_load(protocol_path(name).read_text())
        data["clip"].update(duration_s=duration, cycles=1)
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data))
        return path

    return make


def _manifest(out):
    with open(out / "manifest.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def _render(path, out, **kwargs):
    from stimuli.render.pipeline import render_protocol

    options = dict(resolution="160x90", fps=10, workers=1, progress=False, source="procedural") | kwargs
    return render_protocol(path, out, **options)


def test_manifest_has_design_columns_and_verifiable_hashes(short_protocol, tmp_path, run_cli):
    from stimuli.render.manifest import verify_manifest
    from stimuli.render.video import read_video

    out = tmp_path / "exp1"
    report = _render(short_protocol("exp1_shape_motion"), out, limit=2)
    rows = _manifest(out)
    assert [r["stimulus_id"] for r in rows] == report.rendered == ["F-walk-Hi1-Hi1", "F-walk-Hi1-Hi2"]
    header = list(rows[0])
    assert header[:9] == DESIGN_COLUMNS
    assert header[9:13] == ["SEX", "GAIT", "BODY", "MOTION"] and "practice" in header
    for row in rows:
        frames, meta = read_video(out / row["file"])
        assert frames.shape == (11, 90, 160, 3) and int(row["n_frames"]) == 11 and meta["fps"] == 10
        assert (out / row["poster"]).exists()
        assert row["cadence_spm"] == ""  # procedural stepping poses do not follow the gait's cadence
    # added after the columns older manifests have: cadence, then the motion's source (empty for stepping poses)
    assert header[-6:] == ["cadence_spm", "motion_source", "motion_file", "motion_sha256", "motion_range_s",
                           "motion_params"]
    assert all(row["motion_source"] == "" for row in rows)
    assert verify_manifest(out) == []
    assert run_cli("render", "--out", out, "--verify")[0] == 0
    assert (out / "contact_sheet.png").exists()
    with open(out / rows[0]["file"], "r+b") as handle:   # corrupt one clip
        handle.seek(-10, os.SEEK_END)
        handle.write(b"0123456789")
    assert len(verify_manifest(out)) == 1
    code, _, err = run_cli("render", "--out", out, "--verify")
    assert code == 2 and "do not verify" in err


def test_second_run_renders_only_what_is_new_or_changed(short_protocol, tmp_path):
    out = tmp_path / "exp1"
    path = short_protocol("exp1_shape_motion")
    first = _render(path, out, limit=2)
    stamp = {p.name: p.stat().st_mtime_ns for p in (out / "clips").iterdir()}
    second = _render(path, out, limit=3)
    assert second.skipped == first.rendered and second.rendered == ["F-walk-Hi1-Lo1"]
    assert all((out / "clips" / n).stat().st_mtime_ns == t for n, t in stamp.items())
    third = _render(path, out, limit=3, resolution="192x108")   # other settings: all again
    assert len(third.rendered) == 3 and len(_manifest(out)) == 3
    assert _manifest(out)[0]["width"] == "192"


def test_side_by_side_left_and_right_match_the_manifest(short_protocol, tmp_path):
    out = tmp_path / "exp2"
    report = _render(short_protocol("exp2_com_vs_average"), out, only="walk-F-Hi1-", resolution="320x180")
    rows = {r["stimulus_id"]: r for r in _manifest(out)}
    assert sorted(rows) == ["walk-F-Hi1-COM_NoCOM", "walk-F-Hi1-NoCOM_COM"] == sorted(report.rendered)
    from stimuli.render.video import read_video

    for row in rows.values():
        frames, _ = read_video(out / row["file"])
        frames = frames.astype(int)
        halves = {"left": frames[:, :, :160], "right": frames[:, :, 160:]}
        body = {k: (np.abs(h[0] - 158).max(axis=-1) < 40).sum() for k, h in halves.items()}
        assert min(body.values()) > 300, "a body in each half"
        motion = {k: np.abs(np.diff(h, axis=0)).mean() for k, h in halves.items()}
        # procedural poses: the first METHOD level (NoCOM) steps, the second one half as much
        busier = max(motion, key=motion.get)
        assert row[busier] == "NoCOM" and row["left"] != row["right"]


def test_missing_motion_sources_are_named_not_faked(short_protocol, tmp_path, run_cli):
    code, out, err = run_cli("render", short_protocol("exp2_com_vs_average"), "--out", tmp_path / "x",
                             "--limit", "3", "--resolution", "160x90", "--no-progress")
    assert code == 2
    message = " ".join(err.split())
    assert "3 stimulus clip(s) could not be rendered, for 1 reason(s)" in message and "physics protocol" in message
    assert message.count("--motions DIR") == 1  # NoCOM-left and COM-left clips share one reason
    assert not list((tmp_path / "x").glob("clips/*.mp4"))


def test_failures_are_grouped_by_reason_each_reason_once():
    """Twelve clips failing for two reasons (their messages name each clip): each reason once, with its
    count and a few of its clips, nothing left out."""
    from types import SimpleNamespace

    from stimuli.render.pipeline import RenderReport, _failure_message

    ids = [f"{view}-{body}-{pair}" for view in "ab" for body in ("Thin", "Mid", "Heavy") for pair in ("walk_jog", "jog_walk")]
    failed = {sid: f"afc: stimulus {sid} needs a motion; the renderer maps only method, strength and source levels"
              for sid in ids[:8]}
    failed |= {sid: f"afc: body of {sid} does not fit" for sid in ids[8:]}
    message = _failure_message(SimpleNamespace(name="afc"), RenderReport(Path("out"), failed=failed))
    assert "12 stimulus clip(s) could not be rendered, for 2 reason(s)" in message
    assert message.count("the renderer maps only") == 1 and message.count("does not fit") == 1
    # ids sorted: workers finish in any order, the message of one failure must not change between runs
    assert "8 clip(s) (a-Heavy-jog_walk, a-Heavy-walk_jog, a-Mid-jog_walk, … 5 more): stimulus <clip> needs" in message
    assert "4 clip(s) (b-Heavy-jog_walk, b-Heavy-walk_jog, b-Mid-jog_walk, … 1 more): body of <clip>" in message


def test_many_reasons_are_counted_not_dropped():
    from types import SimpleNamespace

    from stimuli.render.pipeline import MAX_REASONS, RenderReport, _failure_message

    failed = {f"s{i}": f"capture {i}.bvh not found" for i in range(MAX_REASONS + 3)}
    message = _failure_message(SimpleNamespace(name="p"), RenderReport(Path("out"), failed=failed))
    assert message.count("1 clip(s) (") == MAX_REASONS and "3 other reason(s) for 3 clip(s)" in message


def test_render_warns_when_the_clip_changes_a_gaits_cadence(short_protocol, tmp_path, run_cli):
    """A 2 s clip plays a 150 steps/min jog as 2 cycles at 120 steps/min: said before rendering."""
    path = short_protocol("exp1_shape_motion", duration=2.0)
    code, stdout, _ = run_cli("render", path, "--out", tmp_path / "r", "--limit", "1", "--resolution", "160x90",
                              "--fps", "10", "--poses", "procedural", "--no-progress", "--no-survey")
    assert code == 0
    assert "warning: gaits.jog: 138 steps/min does not fill the 2 s clip" in stdout
    assert "2 cycle(s) at 120.0 steps/min (-13.0 %)" in stdout

def test_render_without_a_protocol_is_a_user_error(tmp_path, run_cli):
    code, _, err = run_cli("render", "--out", tmp_path)
    assert code == 2 and "PROTOCOL" in err


@pytest.mark.parametrize("args, message", [
    (["--resolution", "641x360"], "--resolution"),
    (["--only", "no-such-stimulus"], "--only"),
    (["--limit", "-1"], "--limit"),
])
def test_bad_options_exit_2(args, message, short_protocol, tmp_path, run_cli):
    code, _, err = run_cli("render", short_protocol("exp1_shape_motion"), "--out", tmp_path / "y", *args)
    assert code == 2 and message in err


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_leaves_no_half_files_and_the_rerun_resumes(short_protocol, tmp_path, workers):
    path = short_protocol("exp1_shape_motion", duration=2.0)
    out = tmp_path / "exp1"
    total = 16  # enough clips that the render is still running when the interrupt comes, on any load
    command = [sys.executable, "-m", "stimuli.cli", "render", str(path), "--out", str(out), "--limit", str(total),
               "--resolution", "320x180", "--fps", "15", "--workers", str(workers), "--poses", "procedural",
               "--no-progress"]
    # Its own process group, so that the interrupt reaches the workers and ffmpeg too, as Ctrl-C does.
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.time() + 240
    while time.time() < deadline and process.poll() is None:
        if (out / "manifest.csv").exists() and len(_manifest(out)) >= 2:
            break
        time.sleep(0.2)
    time.sleep(0.3)    # let it get into the middle of the next clip
    os.killpg(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err.decode(errors="replace")[-3000:]
    finished = [r["stimulus_id"] for r in _manifest(out)]
    assert 2 <= len(finished) < total
    leftovers = [p.name for p in out.rglob("*") if ".tmp" in p.name]
    assert leftovers == []
    assert sorted(p.stem for p in (out / "clips").glob("*.mp4")) == sorted(finished)
    from stimuli.render.pipeline import render_protocol

    report = render_protocol(path, out, limit=total, resolution="320x180", fps=15, workers=2, progress=False,
                             source="procedural", sheet=False)
    assert report.skipped == finished and len(report.rendered) == total - len(finished)


@pytest.mark.parametrize("failure", [
    # ctypes turns an interrupt raised while it converts a PyOpenGL argument into this error (seen
    # in CI: exit 1 with a traceback from pyrender's glGetIntegerv instead of 130)
    ctypes.ArgumentError("argument 2: KeyboardInterrupt: "),
    OSError(32, "Broken pipe"),                                      # an ffmpeg that died of it
    "broken clip",                                                   # the decode check's ffmpeg died of it
])
def test_a_failure_after_ctrl_c_is_still_the_interrupt(short_protocol, tmp_path, run_cli, monkeypatch, failure):
    """Ctrl-C reaches ffmpeg too, and an interrupt can come back as another exception (ctypes) or be
    lost where Python only prints "Exception ignored": whatever fails after it, the render reports the
    interrupt (exit 130), keeps the clip it finished and leaves no half files."""
    from stimuli.render import pipeline
    from stimuli.render.video import BrokenClip

    if failure == "broken clip":
        failure = BrokenClip("clip.mp4: ffmpeg wrote a clip that does not decode: Invalid data")
    real_render_job = pipeline.render_job
    calls = []

    def render_job(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            return real_render_job(*args, **kwargs)
        try:                       # the interrupt lands where it cannot propagate
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            pass
        raise failure

    monkeypatch.setattr(pipeline, "render_job", render_job)
    out = tmp_path / "r"
    # The failing clip is the last: nothing else notices the lost interrupt.
    code, _, err = run_cli("render", short_protocol("exp1_shape_motion"), "--out", out, "--limit", "2",
                           "--resolution", "160x90", "--fps", "10", "--workers", "1", "--poses", "procedural",
                           "--no-progress", "--no-survey")
    assert (code, err) == (130, "shapemotion: interrupted\n")
    assert len(calls) == 2 and len(_manifest(out)) == 1
    assert sorted(p.name for p in (out / "clips").iterdir()) == [_manifest(out)[0]["file"].split("/")[-1]]
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.slow
def test_exp1_end_to_end_with_real_motions(short_protocol, tmp_path):
    """Exp 1 from the protocol's own motions (generator → retarget onto each body)."""
    from stimuli.render.video import read_video

    out = tmp_path / "exp1"
    report = _render(short_protocol("exp1_shape_motion"), out, only="M-jog-Hi2-Lo1", source="protocol",
                     resolution="320x180", fps=15)
    assert report.rendered == ["M-jog-Hi2-Lo1"]
    # 138 steps/min in 16 frames at 15 fps (1.07 s): one whole cycle, played at 112.5 steps/min
    assert _manifest(out)[0]["cadence_spm"] == "112.50"
    frames, _ = read_video(out / _manifest(out)[0]["file"])
    body = (np.abs(frames.astype(int) - 158).max(axis=-1) < 40).sum(axis=(1, 2))
    assert body.min() > 500 and np.abs(np.diff(frames.astype(int), axis=0)).mean() > 0.1


def test_preview_writes_one_clip_and_its_poster(tmp_path, run_cli):
    from stimuli.render.video import read_video

    out = tmp_path / "p.mp4"
    code, stdout, err = run_cli("preview", "--stepping", "--body", "sex=M,height=1.8,bmi=25", "--out", out,
                                "--resolution", "160x90", "--fps", "12", "--duration", "1", "--layout", "point_light")
    assert code == 0, err
    frames, meta = read_video(out)
    assert frames.shape == (12, 90, 160, 3) and meta["fps"] == 12 and out.with_suffix(".png").exists()
    assert frames.mean() < 30, "point-light: dots on black"
    code, _, err = run_cli("preview", "--stepping", "--body", "sex=X,height=tall", "--out", out)
    assert code == 2 and "--body" in err


def test_familiarization_clip_shows_the_body_alone(short_protocol, tmp_path):
    out = tmp_path / "fam"
    report = _render(short_protocol("exp2_com_vs_average"), out, only="fam-F_Lo2")
    row = _manifest(out)[0]
    assert report.rendered == ["fam-F_Lo2"] and row["kind"] == "familiarization"
    assert row["left"] == row["right"] == "" and row["practice"] == "1"


@pytest.mark.parametrize("settings, expected", [
    # Renamed levels: the motion comes from level_settings, not from the name "NoCOM".
    ({"levels": ["Avg", "Phys"], "abbreviations": {}, "level_settings": {"Avg": {"motion": "average"},
                                                                          "Phys": {"motion": "physics"}}},
     {"Avg": "nocom/F_walk.npz", "Phys": "motions/COM_F_Hi1_walk.npz"}),
    # The setting wins over the name.
    ({"level_settings": {"NoCOM": {"motion": "physics"}, "COM": {"motion": "average"}}},
     {"NoCOM": "motions/COM_F_Hi1_walk.npz", "COM": "nocom/F_walk.npz"}),
    # No setting: the name decides (NoCOM = average, any other = physics), as before.
    ({"level_settings": {}}, {"NoCOM": "nocom/F_walk.npz", "COM": "motions/COM_F_Hi1_walk.npz"}),
])
def test_method_motion_follows_level_settings(settings, expected, protocol_path, tmp_path):
    """Bad-input audit: METHOD levels named [Avg, Phys] passed validation but both read the COM file."""
    from stimuli.design import build_design
    from stimuli.protocol import load_protocol
    from stimuli.render.sources import motion_files

    data = yaml.safe_load(protocol_path("exp2_com_vs_average").read_text())
    data["factors"][3].update(settings)
    path = tmp_path / "renamed.yaml"
    path.write_text(yaml.safe_dump(data))
    protocol = load_protocol(path)
    stimulus = next(s for s in build_design(protocol).stimuli
                    if s.kind == "test" and s.body_actor == "F_Hi1" and "walk" in s.levels.values())
    files = motion_files(protocol, stimulus, tmp_path / "motions")
    got = {level: str(f.relative_to(tmp_path / "motions")) for level, f in zip(stimulus.arrangement, files)}
    assert got == expected


def test_exp2_clips_of_a_condition_retarget_each_motion_once(protocol_path, tmp_path, monkeypatch):
    """NoCOM_COM and COM_NoCOM loaded and retargeted both motions again for every clip (~0.5 s each);
    a rewritten file is read again."""
    from stimuli.design import build_design
    from stimuli.motion.generate import GaitParams, generate
    from stimuli.protocol import load_protocol
    from stimuli.render import sources
    from stimuli.render.settings import look_for

    protocol = load_protocol(protocol_path("exp2_com_vs_average"))
    motions = tmp_path / "physics"
    walk = generate(GaitParams(gait="walk", cadence_spm=112, speed_mps=1.2), height_m=1.6, fps=30, cycles=2)
    for name in ("nocom/F_walk.npz", "motions/COM_F_Hi1_walk.npz"):
        (motions / name).parent.mkdir(parents=True, exist_ok=True)
        walk.save(motions / name)
    calls, real = [], sources.on_rig
    monkeypatch.setattr(sources, "on_rig", lambda motion, body: calls.append(1) or real(motion, body))
    pair = [s for s in build_design(protocol).stimuli
            if s.kind == "test" and s.body_actor == "F_Hi1" and "walk" in s.levels.values()]

    def figures():
        for s in pair:
            sources.protocol_figures(protocol, s, look_for(protocol, s, (160, 90), 10, False), motions)

    figures()
    assert sorted(s.arrangement for s in pair) == [("COM", "NoCOM"), ("NoCOM", "COM")] and len(calls) == 2
    walk.slice(0, 32).save(motions / "nocom" / "F_walk.npz")
    figures()
    assert len(calls) == 3


def test_library_checks_limit_and_motions_as_the_cli_does(protocol_path, tmp_path):
    """render accepted --limit 0 only through the API; --motions was checked only by the CLI."""
    from stimuli.errors import StimuliError
    from stimuli.render.pipeline import render_protocol

    with pytest.raises(StimuliError, match="--limit: expected a whole number >= 1, got 0"):
        render_protocol(protocol_path("exp1_shape_motion"), tmp_path / "a", limit=0, progress=False)
    with pytest.raises(StimuliError, match="has no METHOD factor"):
        render_protocol(protocol_path("exp1_shape_motion"), tmp_path / "b", motions_dir=tmp_path, progress=False)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize("args, message", [
    (["--resolution", "7682x90"], "--resolution: width 7682 is outside 64–7680 pixels"),
    (["--resolution", "62x90"], "--resolution: width 62 is outside 64–7680 pixels"),
    (["--resolution", "160x4322"], "--resolution: height 4322 is outside 64–4320 pixels"),
    (["--fps", "241"], "--fps: expected a whole number of frames per second from 5 to 240"),
    (["--fps", "4"], "--fps: expected a whole number of frames per second from 5 to 240"),
    (["--fps", "0"], "--fps: expected a whole number of frames per second from 5 to 240"),
    # 1 jog cycle at 138 steps/min is 0.87 s: 4 frames at 5 fps, too few for the generator
    (["--fps", "5"], "--fps 5: 1 cycle(s) of jog at 138 steps/min last only 4 frames at 5 fps"),
])
def test_render_options_beyond_the_protocol_bounds_stop_before_any_output(args, message, short_protocol, tmp_path,
                                                                          run_cli):
    """Bad-input audit: these rendered (or failed at render time leaving an empty folder)."""
    out = tmp_path / "y"
    code, _, err = run_cli("render", short_protocol("exp1_shape_motion"), "--out", out, "--limit", "1",
                           "--no-progress", *args)
    assert code == 2 and "Traceback" not in err
    assert message in " ".join(err.split())
    assert not out.exists()
