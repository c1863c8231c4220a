"""``shapemotion init``: the folder of a new study — a commented protocol that ``validate`` accepts as
written, the protocol's JSON Schema beside it (for editors), and ``captures/`` with a README.

The protocol is the bundled template (a small Exp. 1-like design) or a copy of another protocol
(``--from``: a bundled protocol's name or a file), its comments kept and its ``name:`` set to the
study's; capture files it names by relative paths are copied along, so that the copy validates
where the original did (with their folder's README, their terms and attribution, as
``SOURCES.md``). Nothing is written unless everything can be: the folder appears whole.

>>> import tempfile
>>> with tempfile.TemporaryDirectory() as tmp:
...     written = init_study(Path(tmp) / "mystudy")
...     [p.relative_to(tmp).as_posix() for p in written]
['mystudy/protocol.yaml', 'mystudy/protocol.schema.json', 'mystudy/captures/README.md']
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
from pathlib import Path

from stimuli.errors import StimuliError

HERE = Path(__file__).resolve().parent
TEMPLATE = HERE / "init_template.yaml"
CAPTURES_README = HERE / "init_captures_README.md"
BUNDLED_PROTOCOLS = HERE.parent / "protocols"
NAME_LINE = re.compile(r"^name:[^\n]*$", re.M)   # the top-level name: (a nested one is indented)


def init_study(folder: str | Path, source: str | Path | None = None, force: bool = False) -> list[Path]:
    """Write a new study's folder; return the files written. ``folder``'s last part is the protocol's
    ``name``; ``source`` a bundled protocol's name or a protocol file (default: the template)."""
    folder = Path(folder)
    name = study_name(folder)
    source_path = protocol_source(source)
    text, named = NAME_LINE.subn(f"name: {name}", source_path.read_text(encoding="utf-8"), count=1)
    if not named:
        raise StimuliError(f"--from: {source_path} has no 'name:' line at the top level to set to {name!r}")
    protocol = _checked(text, source_path, folder / "protocol.yaml")
    from stimuli.protocol_schema import SCHEMA_FILE, SCHEMA_LINE, schema_text

    if not text.startswith("# yaml-language-server:"):
        text = SCHEMA_LINE + "\n" + text
    files = {"protocol.yaml": text, SCHEMA_FILE: schema_text(),
             "captures/README.md": CAPTURES_README.read_text(encoding="utf-8")}
    copies = {relative: source_path.parent / relative for relative in capture_paths(protocol)}
    # The captures' own README (their terms and attribution: CMU asks for it) travels with them.
    copies |= {relative.parent / "SOURCES.md": source_path.parent / relative.parent / "README.md"
               for relative in list(copies) if (source_path.parent / relative.parent / "README.md").is_file()}
    _check_target(folder, force)
    return _write(folder, files, copies)


def study_name(folder: Path) -> str:
    """The protocol name a study folder gives: its last part, a name ids and file names can carry.

    >>> study_name(Path("studies/pilot_2"))
    'pilot_2'
    >>> study_name(Path("my study"))
    Traceback (most recent call last):
    ...
    stimuli.errors.StimuliError: init: 'my study' is not a usable study name: it must use letters, digits, '_', '-', '.' or '+' only (it becomes the protocol's name and a folder name)
    """
    from stimuli.protocol import MAX_NAME_LENGTH, SAFE_ID

    name = folder.name
    problem = ("it must use letters, digits, '_', '-', '.' or '+' only" if not SAFE_ID.fullmatch(name)
               else f"it is longer than {MAX_NAME_LENGTH} characters" if len(name) > MAX_NAME_LENGTH else None)
    if problem:
        raise StimuliError(f"init: {name!r} is not a usable study name: {problem} (it becomes the protocol's "
                           "name and a folder name)")
    return name


def protocol_source(source: str | Path | None) -> Path:
    """The protocol file ``--from`` names: a bundled protocol's name (``exp1_shape_motion``) or a path."""
    if source is None:
        return TEMPLATE
    bundled = BUNDLED_PROTOCOLS / f"{source}.yaml"
    if bundled.is_file():
        return bundled
    path = Path(source)
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in BUNDLED_PROTOCOLS.glob("*.yaml")))
        raise StimuliError(f"--from: {str(source)!r} is neither a bundled protocol ({names}) nor a protocol file")
    return path


def capture_paths(protocol) -> list[Path]:
    """The capture files a protocol names by relative paths inside its folder (actors' ``motions`` and
    ``bvh:`` level settings) that exist: what a copy of the protocol needs beside it."""
    names = [capture.file for actor in protocol.actors for capture in actor.motions.values()]
    names += [str(settings["motion"])[4:].strip() for f in protocol.factors for settings in f.level_settings.values()
              if str(settings.get("motion", "")).startswith("bvh:")]
    found = []
    for name in names:
        path = Path(name)
        if not path.is_absolute() and ".." not in path.parts and (protocol.folder / path).is_file():
            found.append(path)
    return sorted(set(found))


def _checked(text: str, source: Path, target: Path):
    """The protocol the new file will hold, validated as it will be read (captures relative to ``source``)."""
    from stimuli.protocol import parse_protocol

    try:
        protocol = parse_protocol(text, source=str(source))
    except StimuliError as exc:
        raise StimuliError(f"init: cannot copy {source} to {target}: {exc}") from None
    protocol._folder = source.resolve().parent
    return protocol


def _check_target(folder: Path, force: bool) -> None:
    if folder.exists() and not folder.is_dir():
        raise StimuliError(f"{folder}: exists and is not a folder; choose another study name")
    if folder.is_dir() and any(folder.iterdir()) and not force:
        raise StimuliError(f"{folder}: exists and is not empty; choose another name, or give --force to write "
                           "protocol.yaml, protocol.schema.json and captures/README.md into it (files of those "
                           "names are replaced, others kept)")


def _write(folder: Path, files: dict[str, str], copies: dict[Path, Path]) -> list[Path]:
    """Write everything into a temporary folder beside ``folder``, then move it into place: a new study
    folder appears whole or not at all; into an existing one (``--force``) each file is renamed in."""
    parent = folder.parent
    parent.mkdir(parents=True, exist_ok=True)
    staging = parent / f".{folder.name}.init-{secrets.token_hex(4)}"   # mkdir, not mkdtemp: the usual mode
    staging.mkdir()
    try:
        for relative, content in files.items():
            (staging / relative).parent.mkdir(parents=True, exist_ok=True)
            (staging / relative).write_text(content, encoding="utf-8")
        for relative, original in copies.items():
            (staging / relative).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(original, staging / relative)
        written = [Path(r) for r in files] + sorted(copies)
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
        if not folder.exists():
            os.rename(staging, folder)
        else:
            for relative in written:
                (folder / relative).parent.mkdir(parents=True, exist_ok=True)
                os.replace(staging / relative, folder / relative)
        return [folder / relative for relative in written]
    finally:
        shutil.rmtree(staging, ignore_errors=True)
