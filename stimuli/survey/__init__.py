"""Survey export: a design (or render) folder → Qualtrics QSF, Qualtrics Advanced TXT, a self-hosted
jsPsych experiment, or PsychoPy conditions files.

>>> from stimuli.survey import FORMATS
>>> FORMATS
('qsf', 'qualtrics-txt', 'jspsych', 'psychopy')

The data each export produces is documented in ``docs/readme_survey.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from stimuli.fileio import atomic_write_text
from stimuli.survey.source import SurveySource, load_source

FORMATS = ("qsf", "qualtrics-txt", "jspsych", "psychopy")

__all__ = ["FORMATS", "ExportResult", "export_all", "export_survey", "load_source", "SurveySource"]
# Where export_all puts each format inside its output folder.
ALL_OUTPUTS = {"qsf": "survey.qsf", "qualtrics-txt": "survey_qualtrics.txt", "jspsych": "jspsych",
               "psychopy": "psychopy"}


@dataclass
class ExportResult:
    """What was written, and what the researcher still has to do."""

    path: Path
    format: str
    notes: list[str] = field(default_factory=list)
    manual_steps: list[str] = field(default_factory=list)


def export_survey(folder: str | Path, fmt: str, out: str | Path, video_base_url: str | None = None,
                  post_url: str = "") -> ExportResult:
    """Export the survey of ``folder`` (design or render output) as ``fmt`` into ``out``."""
    from stimuli.errors import StimuliError

    if fmt not in FORMATS:
        raise StimuliError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    source = load_source(folder)
    out = Path(out)
    result = ExportResult(out, fmt)
    if fmt in ("qsf", "qualtrics-txt") and not video_base_url:
        result.notes.append("no --video-base-url: clips are referenced by relative paths (clips/…), which a "
                            "survey hosted by Qualtrics cannot load; pass the URL where the clips are served")
    if fmt in ("qsf", "qualtrics-txt"):
        result.notes += practice_repeat_notes(source)
    doubled = doubled_folder(video_base_url, [s.file for s in source.stimuli])
    if doubled:
        from stimuli.survey.source import clip_url

        example = clip_url(video_base_url, source.stimuli[0].file)
        result.notes.append(f"--video-base-url ends in {doubled}/ and every clip's file starts with {doubled}/, so "
                            f"clips are addressed as {example}; if the clips themselves are at that URL, "
                            f"give the address of the folder above {doubled}/")
    if fmt == "qsf":
        from stimuli.survey.qsf import qsf_text

        atomic_write_text(out, qsf_text(source, video_base_url))
    elif fmt == "qualtrics-txt":
        from stimuli.survey.qualtrics_txt import manual_steps, txt_text

        atomic_write_text(out, txt_text(source, video_base_url))
        result.manual_steps = manual_steps(source)
    elif fmt == "jspsych":
        from stimuli.survey.jspsych import write_jspsych

        missing = write_jspsych(source, out, post_url, video_base_url)
        if missing:
            result.notes.append(f"{len(missing)} clip(s) not found in {source.folder} (e.g. "
                                f"{source.stimulus(missing[0]).file}); copy them into {out}/clips/ before running")
    else:
        from stimuli.survey.psychopy import write_psychopy

        write_psychopy(source, out)
        if source.protocol.blocks.trials == "fixed":
            result.notes.append("blocks.trials is fixed: set each test loop's loopType to sequential (blocks.csv "
                                "column test_loop), so that every participant sees the test clips in the listed "
                                "order, once per repetition")
        if source.protocol.attention_checks is not None:
            result.notes.append("attention_checks: inside each test loop, after the trial routine, add a check "
                                "routine (conditions/attention_check.csv) skipped unless "
                                "str(test_loop.thisN + 1) in check_after.split() (blocks.csv column check_after)")
    return result


def _refresh_jspsych(folder: Path, target: Path, video_base_url: str | None) -> ExportResult:
    """Export jsPsych over an existing ``target``: kept as it is when the new export is the same files,
    replaced when it differs and holds only files an export writes. Kept whatever its contents, it ran
    the trials and clips of an earlier design while the exports beside it had the new ones. A folder
    with files of its own (a lab's data script, collected data) is never touched."""
    import shutil
    import tempfile

    foreign = _not_exported(target)
    if foreign:
        return ExportResult(target, "jspsych", [
            f"{target} exists and holds files an export does not write (e.g. {foreign[0]}); left as it is, so it "
            f"may show an earlier design's trials or clips: export into a new folder with 'shapemotion survey "
            f"{folder} --format jspsych --out DIR'"])
    old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
    target.rename(old / target.name)
    try:
        result = export_survey(folder, "jspsych", target, video_base_url)
    except BaseException:
        if not target.exists():   # the export writes all or nothing: put the old folder back
            (old / target.name).rename(target)
        shutil.rmtree(old, ignore_errors=True)
        raise
    if _same_files(old / target.name, target):
        shutil.rmtree(target)
        (old / target.name).rename(target)
        result = ExportResult(target, "jspsych", [f"{target} exists; left as it is"])
    else:
        result.notes.insert(0, f"{target} held an earlier export (other trials or clips); written again")
    shutil.rmtree(old, ignore_errors=True)
    return result


def _not_exported(folder: Path) -> list[str]:
    """Files in a jsPsych folder that :func:`stimuli.survey.jspsych.write_jspsych` does not write."""
    from stimuli.survey.jspsych import LIBRARIES

    if not folder.is_dir():
        return [folder.name]
    ours = {"index.html", "config.js", "experiment.js"} | {f"lib/{name}" for _, name in LIBRARIES}
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir())
    return [f for f in files if f not in ours and not f.startswith("clips/")]


def _same_files(a: Path, b: Path) -> bool:
    """Whether two folders hold the same files with the same bytes."""
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    if files != sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file()):
        return False
    return all((a / f).read_bytes() == (b / f).read_bytes() for f in files)


def practice_repeat_notes(source) -> list[str]:
    """Blocks whose practice shows more trials than clips: Qualtrics draws them from whole copies of the
    pool at random, so it may repeat a clip back to back, which ``trials.csv`` and jsPsych never do."""
    from stimuli.survey.plan import build_plan

    blocks = {b.label: b for g in build_plan(source) for r in g.rotations for b in r.blocks
              if b.practice_count > len(b.practice)}
    return [f"practice of block {label}: {b.practice_count} trials from {len(b.practice)} clip(s); Qualtrics picks "
            f"them at random from copies of the clips and may show one twice in a row (trials.csv and the "
            f"jsPsych site never do)" for label, b in blocks.items()]


def doubled_folder(base_url: str | None, files: list[str]) -> str:
    """The folder name that ``base_url`` ends in and every clip file starts with ('' if none).

    >>> doubled_folder("https://example.org/clips/", ["clips/a.mp4", "clips/b.mp4"])
    'clips'
    >>> doubled_folder("https://example.org/exp1", ["clips/a.mp4"])
    ''
    """
    last = (base_url or "").rstrip("/").rsplit("/", 1)[-1]
    firsts = {f.replace("\\", "/").partition("/")[0] if "/" in f.replace("\\", "/") else "" for f in files}
    return last if last and firsts == {last} else ""


def export_all(folder: str | Path, out_dir: str | Path | None = None,
               video_base_url: str | None = None) -> list[ExportResult]:
    """Every format into ``out_dir`` (default ``folder/survey``), for ``render`` and ``demo``.

    The TXT's manual steps go to ``qualtrics_manual_steps.txt`` next to it. An existing jsPsych
    folder is left alone when it is what this export writes (a note says so) and written again when
    it is not (a new design or new clips), and a missing jsPsych install (no ``npm ci``) skips that
    format with a note instead of failing the whole export.
    """
    from stimuli.errors import StimuliError
    from stimuli.survey.psychopy import check_psychopy_text
    from stimuli.survey.qualtrics_txt import check_txt_text

    # Every format's refusals before the first file, so that a refused protocol leaves no partial set.
    source = load_source(folder)
    check_txt_text(source)
    check_psychopy_text(source)
    out_dir = Path(out_dir) if out_dir is not None else Path(folder) / "survey"
    results = []
    for fmt, name in ALL_OUTPUTS.items():
        target = out_dir / name
        try:
            if fmt == "jspsych" and target.exists():
                result = _refresh_jspsych(folder, target, video_base_url)
            else:
                result = export_survey(folder, fmt, target, video_base_url)
        except StimuliError as exc:
            if fmt != "jspsych" or "jsPsych is not installed" not in str(exc):
                raise
            result = ExportResult(target, fmt, [str(exc)])
        if result.manual_steps:
            steps = "\n".join(f"{n}. {step}" for n, step in enumerate(result.manual_steps, start=1))
            head = (f"After importing {name} (Qualtrics Advanced Format TXT) set these by hand; "
                    f"{ALL_OUTPUTS['qsf']} needs none of them.\n\n")
            atomic_write_text(out_dir / "qualtrics_manual_steps.txt", head + steps + "\n")
        results.append(result)
    return results
