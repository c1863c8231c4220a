"""``manifest.csv``: one row per rendered clip (DESIGN.md columns), written after every clip.

Columns: ``stimulus_id, file, sha256, width, height, fps, n_frames, duration_s, layout,
<factor columns>, left, right`` (two alternatives) or ``positions`` (k > 2), ``practice``, then
``kind, poster, inputs_hash, cadence_spm``, then the motion's source (``stimuli.motion.captures.
MOTION_COLUMNS``): ``motion_source`` (``capture`` or ``generator``), ``motion_file``,
``motion_sha256``, ``motion_range_s`` (the capture's seconds the loop took), ``motion_params`` (the
generator's parameters) — for clips showing one actor's gait; empty otherwise (Exp 2's averages,
the thesis sets, procedural poses, rows written before the columns existed). ``file`` and
``poster`` are relative to the manifest's folder; ``cadence_spm`` is the steps per minute the clip
shows (``stimuli.render.timing``; for an actor's capture, its own cadence as the looped clip plays
it), empty for the thesis validation's ``bvh:`` captures, procedural poses and rows written before
the column existed.
"""

from __future__ import annotations

import csv
from pathlib import Path

from stimuli.fileio import atomic_write_text, csv_text

MANIFEST = "manifest.csv"


def manifest_row(protocol, stimulus, look, info, out_dir: Path, poster: Path, digest: str,
                 poses: str = "protocol") -> dict[str, object]:
    """The manifest row of one finished clip (``poses``: the render's pose source)."""
    from stimuli.render.timing import clip_cadence
    row: dict[str, object] = {
        "stimulus_id": stimulus.stimulus_id, "file": info.path.relative_to(out_dir).as_posix(),
        "sha256": info.sha256, "width": look.width, "height": look.height, "fps": look.fps,
        "n_frames": info.n_frames, "duration_s": look.duration_s, "layout": look.layout,
    }
    for factor in protocol.factors:
        if factor.role != "alternatives":
            row[factor.name] = stimulus.levels.get(factor.name, "")
    alternatives = protocol.factors_with_role("alternatives")
    if alternatives and len(alternatives[0].levels) == 2:  # familiarization clips have no arrangement
        row["left"], row["right"] = stimulus.arrangement or ("", "")
    elif alternatives:
        row["positions"] = "|".join(stimulus.arrangement)
    row |= {"practice": int(stimulus.practice), "kind": stimulus.kind,
            "poster": poster.relative_to(out_dir).as_posix(), "inputs_hash": digest}
    # A procedural stepping pose does not follow the gait's cadence.
    row["cadence_spm"] = clip_cadence(protocol, stimulus, look.duration_s, look.fps) if poses == "protocol" else ""
    motion = motion_columns(protocol, stimulus, poses)
    if motion["motion_source"] == "capture":   # a capture keeps its own cadence, not the gait's
        from stimuli.motion.captures import looped_capture, shown_cadence
        from stimuli.render.sources import gait_of

        loop = looped_capture(protocol, stimulus.motion_actor or stimulus.body_actor, gait_of(protocol, stimulus))
        row["cadence_spm"] = round(shown_cadence(loop, look.duration_s, look.loop), 2)
    return row | motion


def motion_columns(protocol, stimulus, poses: str = "protocol") -> dict[str, str]:
    """Where the clip's motion came from (``stimuli.motion.captures.motion_record``): filled for a
    clip showing one actor's gait (no alternatives factor) rendered from the protocol's sources."""
    from stimuli.motion.captures import MOTION_COLUMNS, motion_record
    from stimuli.render.sources import gait_of

    if poses != "protocol" or protocol.factors_with_role("alternatives"):
        return dict.fromkeys(MOTION_COLUMNS, "")
    return motion_record(protocol, stimulus.motion_actor or stimulus.body_actor, gait_of(protocol, stimulus))


def with_all_columns(row: dict[str, str]) -> dict[str, str]:
    """A row kept from an earlier manifest, with the columns added since (empty), so that every row of
    the rewritten manifest has the same columns."""
    from stimuli.motion.captures import MOTION_COLUMNS

    return row | {column: "" for column in ("cadence_spm", *MOTION_COLUMNS) if column not in row}


def read_manifest(out_dir: str | Path) -> dict[str, dict[str, str]]:
    """Rows of an existing manifest by stimulus id ({} when there is none)."""
    path = Path(out_dir) / MANIFEST
    if not path.exists():
        return {}
    with open(path, newline="", encoding="utf-8") as handle:
        return {row["stimulus_id"]: row for row in csv.DictReader(handle)}


def write_manifest(out_dir: str | Path, rows: list[dict[str, object]]) -> Path:
    """Write the manifest atomically, rows in the given order."""
    path = Path(out_dir) / MANIFEST
    atomic_write_text(path, csv_text(rows))
    return path


def verify_manifest(out_dir: str | Path) -> list[str]:
    """One line per clip that does not verify (an empty list means all verified): a missing file, a
    SHA-256 mismatch, or a clip that does not decode to its ``n_frames`` frames — a hash only says
    the file is the one recorded, and before clips were decoded when written, a clip cut short by a
    full disk was recorded too."""
    from stimuli.render.video import decode_problem, sha256_file

    out_dir = Path(out_dir)
    problems = []
    for sid, row in read_manifest(out_dir).items():
        path = out_dir / row["file"]
        if not path.exists():
            problems.append(f"{sid}: {row['file']} is missing")
            continue
        found = [f"does not match its sha256 in {MANIFEST}"] if sha256_file(path) != row["sha256"] else []
        found += [problem for problem in [decode_problem(path, _whole_number(row.get("n_frames")))] if problem]
        if found:
            problems.append(f"{sid}: {row['file']} {' and '.join(found)}")
    return problems


def _whole_number(text: str | None) -> int | None:
    """A manifest count, or None when the cell is not one (the frame count is then not checked)."""
    try:
        return int(text)
    except (TypeError, ValueError):
        return None
