"""PsychoPy Builder inputs: a conditions file per block and part, a blocks file, and the trial lists.

Written into one folder::

    blocks.csv                       outer loop: one row per block (declared order) with the names of
                                     its conditions files; set the loop to random/sequential per protocol
    conditions/<block>_test.csv      one row per test stimulus, in declared order (set the inner loop's
                                     nReps to ``repetitions`` and its type to random, or — with
                                     ``blocks.trials: fixed``, when blocks.csv has ``test_loop`` =
                                     ``sequential`` — to sequential, which shows the rows in order once
                                     per repetition, as the design does)
    conditions/<block>_practice.csv  the practice pool (draw ``practice_per_block`` rows)
    conditions/<block>_familiarization.csv   the familiarisation clips, in order (sequential loop)
    trials.csv                       every participant's seeded trial list with its movie file, for a
                                     script that replays the design exactly (loop over rows where
                                     ``participant`` is the session's participant)

With ``blocks.nested`` (e.g. SEX blocks holding GAIT sub-blocks) also::

    main_blocks.csv                  outer loop: one row per main block (declared order) with its
                                     ``familiarization_file`` (shown once, before its sub-blocks) and
                                     ``blocks_file``
    conditions/<main>_blocks.csv     inner loop (conditionsFile ``$blocks_file``): the main block's
                                     sub-blocks, rows as in blocks.csv
    conditions/<main>_familiarization.csv   the main block's familiarisation clips, in order

and blocks.csv (all sub-blocks) gains ``main_block``, its ``familiarization_file`` left empty. In
Builder: loop over main_blocks.csv → familiarisation loop → loop over ``$blocks_file`` → practice
and test loops; set both block loops random (``order: random``/``counterbalanced``) or sequential
(``fixed``), as for flat blocks.

Each conditions row has ``stimulus_id``, ``movie`` (path relative to the folder, as PsychoPy's
MovieStim wants), the factor levels, ``left``/``right`` or ``positions``, ``question`` and the answer
options (``options`` = labels joined by ``|``). With several between groups, the files carry the group in
their name (``SEX=F|GAIT=walk`` → ``SEX-F_GAIT-walk``).

With ``attention_checks`` also ``conditions/attention_check.csv`` (one row: ``attention_check`` = 1,
``attention_answer`` spelled as its button, ``prompt``, ``options``), and blocks.csv gains ``check_after``:
the test trials of the block (1-based, counted over the test loop's repetitions too) after which the
check comes, space-separated (:mod:`stimuli.survey.checks`). The test loop stays random: in Builder a
check routine follows the trial routine inside the test loop and is skipped unless
``str(test_loop.thisN + 1) in check_after.split()``, so the checks keep their slots while the clips
are shuffled around them. ``trials.csv`` then has a row ``kind`` = ``attention_check`` (no movie) where
jsPsych shows a check in that participant's list.
"""

from __future__ import annotations

import keyword
import os
import re
from pathlib import Path

from stimuli.errors import StimuliError
from stimuli.fileio import csv_text, write_all_or_nothing
from stimuli.protocol import shown
from stimuli.survey.checks import block_slots, with_check_rows
from stimuli.survey.plan import build_plan
from stimuli.survey.source import StimulusInfo, SurveySource
from stimuli.survey.text import answer_labels


def check_psychopy_text(source: SurveySource) -> None:
    """Refuse, naming the protocol field, what PsychoPy's conditions files cannot carry unchanged.

    PsychoPy (``data.importConditions``) reads each column header as a Python variable name, runs
    ``eval`` on any cell that starts with ``[`` and ends with ``]`` (so the cell would be executed as
    code), and a Builder routine splits ``options`` at ``|`` (a label holding one made an extra option).
    """
    p = source.protocol
    where = source.folder / "design.json"
    field = "response.labels" if p.response.type == "likert" else "display.labels"
    labels = answer_labels(p)
    for index, label in enumerate(labels):
        if "|" in label:
            raise StimuliError(f"{where}: protocol field {field}.{index} {shown(label)} holds '|', which separates "
                               f"the answer options in PsychoPy's options column: the {len(labels)} labels would "
                               f"make {len('|'.join(labels).split('|'))} options; write the label without '|'")
    cells = {"response.question": p.response.question, field: "|".join(labels)}
    if p.attention_checks is not None:
        cells["attention_checks.prompt"] = check_prompt(p)
    for name, text in cells.items():
        if text.startswith("[") and text.endswith("]"):
            raise StimuliError(f"{where}: protocol field {name} {shown(text)}: PsychoPy evaluates a conditions cell "
                               "that starts with '[' and ends with ']' as Python code; reword it (e.g. drop the "
                               "brackets)")
    for index, factor in enumerate(p.factors):
        if factor.role != "alternatives" and not is_psychopy_column(factor.name):
            raise StimuliError(f"{where}: protocol field factors.{index}.name {shown(factor.name)}: PsychoPy reads "
                               "conditions columns as Python variable names (letters, digits and '_', not "
                               "starting with a digit, not a Python keyword); rename the factor")


def is_psychopy_column(name: str) -> bool:
    """Whether PsychoPy accepts ``name`` as a conditions column (a Python variable name).

    >>> is_psychopy_column("BODY"), is_psychopy_column("BODY-TYPE"), is_psychopy_column("2x"), is_psychopy_column("if")
    (True, False, False, False)
    """
    return name.isascii() and name.isidentifier() and not keyword.iskeyword(name)


def check_prompt(protocol) -> str:
    """The check's request as plain text (a PsychoPy TextStim shows no HTML)."""
    checks = protocol.attention_checks
    return checks.prompt.replace("{answer}", checks.answer)


def _check_row(protocol) -> dict[str, object]:
    """The one row of ``conditions/attention_check.csv``: what the check asks, with the answer as its button."""
    labels = answer_labels(protocol)
    key = " ".join(protocol.attention_checks.answer.split()).casefold()
    answer = next(label for label in labels if " ".join(label.split()).casefold() == key)
    return {"attention_check": 1, "attention_answer": answer, "prompt": check_prompt(protocol),
            "options": "|".join(labels)}


def _name(label: str) -> str:
    return "".join(c if c.isalnum() or c in "._" else "-" for c in label.replace("|", "_").replace("=", "-"))


def _row(source: SurveySource, s: StimulusInfo, movie_prefix: str) -> dict[str, object]:
    p = source.protocol
    factors = [f.name for f in p.factors if f.role != "alternatives"]
    row = {"stimulus_id": s.stimulus_id, "movie": movie_prefix + s.file, "kind": s.kind}
    row |= {name: s.levels.get(name, "") for name in factors}
    if len(s.arrangement) == 2:
        row |= {"left": s.arrangement[0], "right": s.arrangement[1]}
    elif s.arrangement:
        row["positions"] = "|".join(s.arrangement)
    return row | {"question": p.response.question, "options": "|".join(answer_labels(p))}


def psychopy_files(source: SurveySource, movie_prefix: str = "") -> dict[str, str]:
    """File name (relative to the output folder) → CSV text."""
    check_psychopy_text(source)
    files: dict[str, str] = {}
    blocks, mains = [], []
    for plan in build_plan(source):
        for rotation in plan.rotations:
            parts = list(plan.groups.items()) + ([("rotation", str(rotation.index))]
                                                  if rotation.index is not None else [])
            prefix = "_".join(f"{k}-{v}" for k, v in parts) + ("_" if parts else "")
            where = dict(plan.groups) | ({"rotation": rotation.index} if rotation.index is not None else {})
            main_of = {b.label: m.label for m in rotation.main_blocks for b in m.blocks}
            slots = block_slots(rotation.blocks, source.protocol.attention_checks)
            entries = {block.label: _block_entry(source, files, block, _name(prefix + block.label), movie_prefix,
                                                 where | ({"main_block": main_of[block.label]} if main_of else {}),
                                                 slots.get(id(block)))
                       for block in rotation.blocks}
            blocks += entries.values()
            for main in rotation.main_blocks:
                stem = _name(prefix + main.label)
                entry = where | {"main_block": main.label, "familiarization_file": "",
                                 "blocks_file": f"conditions/{stem}_blocks.csv"}
                files[entry["blocks_file"]] = csv_text([entries[b.label] for b in main.blocks])
                if main.familiarization:
                    entry["familiarization_file"] = f"conditions/{stem}_familiarization.csv"
                    files[entry["familiarization_file"]] = csv_text(
                        [_row(source, s, movie_prefix) for s in main.familiarization])
                mains.append(entry)
    if mains:
        files["main_blocks.csv"] = csv_text(mains)
    files["blocks.csv"] = csv_text(blocks)
    if source.protocol.attention_checks is not None:
        files["conditions/attention_check.csv"] = csv_text([_check_row(source.protocol)])
    files["trials.csv"] = csv_text(_replay_rows(source, movie_prefix))
    return files


def _replay_rows(source: SurveySource, movie_prefix: str) -> list[dict]:
    """trials.csv's rows with their ``movie``; with attention checks also a check row (``kind`` =
    ``attention_check``, no movie) where jsPsych shows one in that participant's list."""
    rows = [t | {"movie": movie_prefix + source.stimulus(t["stimulus_id"]).file} for t in source.trials]
    checks = source.protocol.attention_checks
    if checks is None:
        return rows
    by_participant: dict[str, list[dict]] = {}
    for row in rows:
        by_participant.setdefault(str(row["participant"]), []).append(row)
    return [r for trials in by_participant.values() for r in with_check_rows(trials, checks.every)]


def _block_entry(source: SurveySource, files: dict[str, str], block, stem: str, movie_prefix: str,
                 where: dict, checks: list[int] | None) -> dict[str, object]:
    """A block's row of blocks.csv (``where``: its group, rotation, main block; ``checks``: the test trials a
    check follows, None without attention checks); its conditions files go into ``files``."""
    p = source.protocol
    entry = where | {"block_label": block.label, "nReps": p.repetitions, "test_file": f"conditions/{stem}_test.csv",
                     "practice_file": "", "practice_per_block": block.practice_count, "familiarization_file": ""}
    if p.blocks.trials == "fixed":   # the test loop's loopType (only then: other files stay as they were)
        entry["test_loop"] = "sequential"
    if checks is not None:
        entry["check_after"] = " ".join(map(str, checks))
    tests = [s for s, rep in block.tests if rep == 1]
    files[entry["test_file"]] = csv_text([_row(source, s, movie_prefix) for s in tests])
    if block.practice_count:
        entry["practice_file"] = f"conditions/{stem}_practice.csv"
        files[entry["practice_file"]] = csv_text([_row(source, s, movie_prefix) for s in block.practice])
    if block.familiarization:
        entry["familiarization_file"] = f"conditions/{stem}_familiarization.csv"
        files[entry["familiarization_file"]] = csv_text([_row(source, s, movie_prefix) for s in block.familiarization])
    return entry


def write_psychopy(source: SurveySource, out_dir: str | Path) -> list[Path]:
    """Write the PsychoPy folder. ``movie`` paths are relative to it (where the ``.psyexp`` goes) and
    point at the clips in the source folder."""
    out_dir = Path(out_dir)
    prefix = os.path.relpath(source.folder.resolve(), out_dir.resolve()).replace(os.sep, "/") + "/"
    prefix = "" if prefix == "./" else prefix
    files = psychopy_files(source, prefix)
    written = write_all_or_nothing(out_dir, files)
    _remove_stale(out_dir, files)
    return written


# The names this export gives its files; anything else in the folder belongs to the lab.
_EXPORTED = re.compile(r"main_blocks\.csv|conditions/attention_check\.csv|"
                       r"conditions/[^/]+_(test|practice|familiarization|blocks)\.csv")


def _remove_stale(out_dir: Path, files: dict[str, str]) -> None:
    """Delete what an earlier export wrote and this one does not (``main_blocks.csv`` of a nested design,
    another design's ``conditions/<block>_test.csv`` …): a Builder experiment would go on reading them.
    Only files named as this export names them go; the lab's own (``.psyexp``, data, other CSVs) stay."""
    for path in sorted(out_dir.glob("main_blocks.csv")) + sorted((out_dir / "conditions").glob("*.csv")):
        name = path.relative_to(out_dir).as_posix()
        if name not in files and _EXPORTED.fullmatch(name):
            path.unlink()
