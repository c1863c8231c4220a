"""What a survey is made from: a design folder (``design.json``, ``conditions.csv``, ``trials.csv``)
and, when the clips are rendered, the ``manifest.csv`` next to them.

Without a manifest the clip of a stimulus is ``clips/<stimulus_id>.mp4`` (the renderer's naming), so a
survey can be drafted before any clip exists.

>>> from stimuli.survey.source import clip_url
>>> clip_url("https://example.org/study", "clips/a b.mp4")
'https://example.org/study/clips/a%20b.mp4'
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from urllib.parse import quote

from pydantic import ValidationError

from stimuli.errors import StimuliError
from stimuli.protocol import Protocol

MANIFEST_REQUIRED = ["stimulus_id", "file"]
DESIGN_KEYS = ["name", "stimuli", "protocol", "repetitions"]


@dataclass(frozen=True)
class StimulusInfo:
    """One clip of the design as the survey needs it."""

    stimulus_id: str
    condition_id: str
    kind: str                       # test | practice | familiarization
    levels: dict[str, str]
    arrangement: tuple[str, ...]    # alternatives levels by screen position
    body_actor: str
    file: str                       # path relative to the source folder (and to the exported folder)


@dataclass
class SurveySource:
    """The protocol, its stimuli in design order, every participant's trial list and where clips live."""

    folder: Path
    protocol: Protocol
    stimuli: list[StimulusInfo]
    trials: list[dict[str, str]]
    has_manifest: bool
    design: dict = field(repr=False, default_factory=dict)

    def stimulus(self, stimulus_id: str) -> StimulusInfo:
        return self._by_id[stimulus_id]

    @cached_property
    def _by_id(self) -> dict[str, StimulusInfo]:
        return {s.stimulus_id: s for s in self.stimuli}

    def of_kind(self, kind: str) -> list[StimulusInfo]:
        return [s for s in self.stimuli if s.kind == kind]

    @property
    def between(self) -> list[str]:
        return [f.name for f in self.protocol.factors_with_role("between")]

    @property
    def participants(self) -> list[int]:
        return sorted({int(t["participant"]) for t in self.trials})


def clip_url(base_url: str | None, file: str) -> str:
    """The address a survey uses for a clip: ``base_url`` + the clip's relative path, URL-quoted."""
    path = quote(file.replace("\\", "/"))
    if not base_url:
        return path
    return base_url.rstrip("/") + "/" + path


def load_source(folder: str | Path) -> SurveySource:
    """Read a design or render folder; every problem is a :class:`StimuliError` naming the file."""
    folder = Path(folder)
    if not folder.is_dir():
        raise StimuliError(f"{folder}: not a folder; expected the output folder of 'shapemotion design' or "
                           f"'shapemotion render'")
    design = _read_design(folder / "design.json")
    protocol = _protocol(design, folder / "design.json")
    trials = _read_csv(folder / "trials.csv", ["participant", "block", "block_label", "trial", "stimulus_id",
                                               "repetition", "practice", "kind"])
    manifest_path = folder / "manifest.csv"
    files = _manifest_files(manifest_path) if manifest_path.exists() else {}
    stimuli = [_stimulus(raw, files, folder, manifest_path.exists()) for raw in design["stimuli"]]
    known = {s.stimulus_id for s in stimuli}
    for number, row in enumerate(trials, start=2):
        if row["stimulus_id"] not in known:
            raise StimuliError(f"{folder / 'trials.csv'}: row {number}: stimulus_id {row['stimulus_id']!r} is not "
                               f"a stimulus of design.json")
    return SurveySource(folder, protocol, stimuli, trials, manifest_path.exists(), design)


def _read_design(path: Path) -> dict:
    if not path.exists():
        raise StimuliError(f"{path}: not found; a survey needs the design files: run 'shapemotion design "
                           f"PROTOCOL --out {path.parent}' (or render into this folder)")
    try:
        design = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise StimuliError(f"{path}: not valid JSON ({exc})") from None
    missing = [k for k in DESIGN_KEYS if not isinstance(design, dict) or k not in design]
    if missing:
        raise StimuliError(f"{path}: missing keys {missing}; expected the design.json that 'shapemotion design' writes")
    return design


def _protocol(design: dict, path: Path) -> Protocol:
    try:
        return Protocol.model_validate(design["protocol"])
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise StimuliError(f"{path}: protocol.{where}: {first['msg']}") from None


def _read_csv(path: Path, required: list[str]) -> list[dict[str, str]]:
    if not path.exists():
        raise StimuliError(f"{path}: not found; run 'shapemotion design PROTOCOL --out {path.parent}'")
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        missing = [c for c in required if c not in (reader.fieldnames or [])]
        if missing:
            raise StimuliError(f"{path}: missing columns {missing} (columns: {reader.fieldnames})")
        return list(reader)


def _manifest_files(path: Path) -> dict[str, str]:
    rows = _read_csv(path, MANIFEST_REQUIRED)
    files = {}
    for number, row in enumerate(rows, start=2):
        sid, file = row["stimulus_id"].strip(), row["file"].strip()
        if not sid or not file:
            raise StimuliError(f"{path}: row {number}: stimulus_id and file must not be empty")
        if Path(file).is_absolute() or ".." in Path(file).parts:
            raise StimuliError(f"{path}: row {number}: file {file!r} must be a path inside the folder "
                               f"(e.g. clips/{sid}.mp4)")
        files[sid] = file
    return files


def _stimulus(raw: dict, files: dict[str, str], folder: Path, has_manifest: bool) -> StimulusInfo:
    sid = raw["stimulus_id"]
    if has_manifest and sid not in files:
        raise StimuliError(f"{folder / 'manifest.csv'}: no row for stimulus {sid!r} of design.json; "
                           f"render every stimulus (or remove the manifest to use clips/<stimulus_id>.mp4)")
    return StimulusInfo(sid, raw.get("condition_id", sid), raw["kind"], dict(raw.get("levels", {})),
                        tuple(raw.get("arrangement", [])), raw.get("body_actor", ""),
                        files.get(sid, f"clips/{sid}.mp4"))
