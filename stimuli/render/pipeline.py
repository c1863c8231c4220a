"""``render_protocol``: every stimulus of a protocol's design as a clip, in parallel, resumable.

Output folder: ``clips/<stimulus_id>.mp4``, ``posters/<stimulus_id>.png``, ``manifest.csv`` and
``contact_sheet.png``. A clip whose inputs hash (stimulus, actors, gaits, look, renderer version)
and file hash match the existing manifest is not rendered again. The manifest is rewritten after
every finished clip, so an interrupted run keeps what it finished; clips are written under
temporary names and renamed once they decode, so an interruption or a full disk never leaves half a
file under a clip's name. What a killed run leaves under temporary names is swept by the next run
(:func:`sweep_temporaries`), and the workers die with the process that started them
(``stimuli.workers``).
"""

from __future__ import annotations

import errno
import os
import signal
from concurrent.futures import FIRST_COMPLETED, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from stimuli.errors import StimuliError
from stimuli.fileio import folder_lock
from stimuli.interrupts import check_interrupted, install_interrupt_handler, was_interrupted
from stimuli.render.clip import Look
from stimuli.render.manifest import MANIFEST, manifest_row, read_manifest, with_all_columns, write_manifest
from stimuli.render.settings import inputs_hash, look_for
from stimuli.workers import process_pool

SOURCES = ("protocol", "procedural")


@dataclass(frozen=True)
class Job:
    stimulus: object
    look: Look
    digest: str
    clip: Path
    poster: Path


@dataclass
class RenderReport:
    out_dir: Path
    manifest: Path | None = None
    rendered: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    contact_sheet: Path | None = None
    warnings: list[str] = field(default_factory=list)
    design: object = None  # the stimuli.design.Design rendered (for the survey exports)

    def summary(self) -> str:
        return (f"{len(self.rendered)} rendered, {len(self.skipped)} unchanged, {len(self.failed)} not renderable"
                f" → {self.out_dir}")


def select(stimuli: list, only: str | list[str] | None, limit: int | None) -> list:
    """Stimuli whose id contains one of ``only`` (comma-separated or a list), then the first ``limit``."""
    if only:
        wanted = [w.strip() for w in (only.split(",") if isinstance(only, str) else only) if w.strip()]
        stimuli = [s for s in stimuli if any(w in s.stimulus_id for w in wanted)]
        if not stimuli:
            raise StimuliError(f"--only: no stimulus id contains any of {wanted}")
    if limit is not None:
        if limit < 1:
            raise StimuliError(f"--limit: expected a whole number >= 1, got {limit}")
        stimuli = stimuli[:limit]
    return stimuli


def plan(protocol, stimuli, out_dir: Path, resolution=None, fps=None, quick=False, motions_dir=None,
         source: str = "protocol") -> list[Job]:
    from stimuli.render.sources import motion_files

    jobs = []
    for s in stimuli:
        look = look_for(protocol, s, resolution, fps, quick)
        digest = inputs_hash(protocol, s, look, motion_files(protocol, s, motions_dir), poses=source)
        jobs.append(Job(s, look, digest, out_dir / "clips" / f"{s.stimulus_id}.mp4",
                        out_dir / "posters" / f"{s.stimulus_id}.png"))
    return jobs


def _check_motions_dir(protocol, motions_dir, where) -> None:
    """``motions_dir`` (the physics step's folder) only for a protocol that reads it, and present."""
    if motions_dir is None:
        return
    alternatives = protocol.factors_with_role("alternatives")
    if not alternatives or alternatives[0].maps_to != "method":
        raise StimuliError(f"--motions {motions_dir}: {where} has no METHOD factor (maps_to: method), so it reads "
                           "no motions of 'shapemotion physics protocol'; leave --motions out")
    if not Path(motions_dir).is_dir():
        raise StimuliError(f"--motions {motions_dir}: folder not found (the --out folder of 'shapemotion physics "
                           "protocol')")


def check_frames(protocol, fps: int | None, source: str = "protocol") -> None:
    """Before any folder or clip is made: the frame rate gives the generator enough frames."""
    from stimuli.render.timing import generator_frames_problem

    problem = generator_frames_problem(protocol, fps) if fps and source == "protocol" else None
    if problem:
        option = "--fps" if fps != protocol.clip.fps else "clip.fps"
        raise StimuliError(f"{option} {fps}: {problem}; use a higher frame rate or a longer clip.duration_s")


def is_current(job: Job, row: dict | None) -> bool:
    """A finished clip can be kept: same inputs hash, file present with the recorded SHA-256."""
    from stimuli.render.video import sha256_file

    return bool(row) and row.get("inputs_hash") == job.digest and job.clip.exists() \
        and sha256_file(job.clip) == row.get("sha256")


def render_job(protocol, job: Job, source: str = "protocol", motions_dir=None) -> dict:
    """Render one clip (any process); returns its manifest row."""
    from stimuli.render.clip import render_frames
    from stimuli.render.video import write_video

    if source == "procedural":
        from stimuli.render.procedural import procedural_figures

        figures = procedural_figures(protocol, job.stimulus, job.look)
    else:
        from stimuli.render.sources import protocol_figures

        figures = protocol_figures(protocol, job.stimulus, job.look, motions_dir)
    look = job.look
    info = write_video(render_frames(look, figures), job.clip, look.fps, look.width, look.height, look.n_frames,
                       poster=job.poster)
    return manifest_row(protocol, job.stimulus, look, info, job.clip.parents[1], job.poster, job.digest, source)


def _worker_job(args):
    protocol, job, source, motions_dir = args
    try:
        return job.stimulus.stimulus_id, render_job(protocol, job, source, motions_dir), None
    except StimuliError as exc:  # a missing motion source: report it, keep rendering the rest
        return job.stimulus.stimulus_id, None, str(exc)


def render_protocol(protocol_path, out_dir, resolution=None, fps=None, limit=None, only=None, workers=None,
                    quick: bool = False, progress: bool = True, source: str = "protocol", strict: bool = True,
                    sheet: bool = True, motions_dir=None, warn=None, scheduler=None) -> RenderReport:
    """Render every test, practice and familiarization stimulus of a protocol's design.

    ``strict``: raise StimuliError after rendering what can be rendered when some stimuli could
    not be (their motion source is missing); otherwise only report them in the result.
    ``motions_dir``: the folder of ``shapemotion physics protocol`` (Exp 2's NoCOM/COM motions).
    ``warn``: called with each warning (a gait whose cadence the clip changes) before rendering;
    the warnings are also kept in ``report.warnings``.
    ``scheduler``: a ``shapemotion.execution.Scheduler`` to render on a Dask cluster (None: the local
    process pool of ``workers``); the clips come back as bytes and are written here.
    """
    from stimuli.design import build_design
    from stimuli.protocol import load_protocol
    from stimuli.render.timing import cadence_warnings

    if source not in SOURCES:
        raise StimuliError(f"--poses: expected one of {', '.join(SOURCES)}, got {source!r}")
    protocol = load_protocol(protocol_path)
    _check_motions_dir(protocol, motions_dir, protocol_path)
    if source == "protocol":   # every actor's capture imports and loops, before a folder or clip is made
        from stimuli.motion.captures import check_captures

        check_captures(protocol, protocol_path)
    out_dir = Path(out_dir)
    design = build_design(protocol)
    order = [s.stimulus_id for s in design.stimuli]
    jobs = plan(protocol, select(design.stimuli, only, limit), out_dir, resolution, fps, quick, motions_dir, source)
    check_frames(protocol, jobs[0].look.fps if jobs else None, source)
    previous = read_manifest(out_dir)
    report = RenderReport(out_dir, warnings=cadence_warnings(protocol, jobs[0].look.fps if jobs else None),
                          design=design)
    for line in report.warnings if warn else ():
        warn(line)
    rows = {sid: with_all_columns(row) for sid, row in previous.items()
            if sid in order and (out_dir / row["file"]).exists()}
    todo = []
    for job in jobs:
        if is_current(job, previous.get(job.stimulus.stimulus_id)):
            report.skipped.append(job.stimulus.stimulus_id)
        else:
            rows.pop(job.stimulus.stimulus_id, None)
            todo.append(job)
    out_dir.mkdir(parents=True, exist_ok=True)
    workers = max(1, min(workers or min(2, os.cpu_count() or 1), len(todo) or 1))
    with output_lock(out_dir), disk_full_is_a_user_error(out_dir, report):
        sweep_temporaries(out_dir)
        report.manifest = _update_manifest(out_dir, _ordered(rows, order))
        previous_handler = install_interrupt_handler()
        try:
            run = _run if scheduler is None else _run_on(scheduler)
            for sid, row, error in run(protocol, todo, (source, motions_dir), workers, progress, protocol.name):
                if row is not None:
                    rows[sid] = row
                    report.rendered.append(sid)
                    report.manifest = write_manifest(out_dir, _ordered(rows, order))
                else:
                    report.failed[sid] = error
            if previous_handler is not None:
                check_interrupted()   # one that came during the last clip, and was lost
        except BaseException as exc:
            _drop_unrecorded(todo, rows)
            interrupted = previous_handler is not None and was_interrupted()
            if interrupted and not isinstance(exc, (KeyboardInterrupt, SystemExit)):
                # The user's Ctrl-C, come back as another error: ctypes reports an interrupt raised while
                # it converts an argument (PyOpenGL's) as ctypes.ArgumentError, and Ctrl-C reaches the
                # whole process group, so the decode check's ffmpeg can die of it before Python raises it.
                raise KeyboardInterrupt from exc
            raise
        finally:
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)
        if sheet:
            from stimuli.render.contact import contact_sheet

            posters = [(sid, out_dir / rows[sid]["poster"]) for sid in _ordered_ids(rows, order)]
            report.contact_sheet = contact_sheet(posters, out_dir / "contact_sheet.png")
    if report.failed and strict:
        raise StimuliError(_failure_message(protocol, report))
    return report


def _drop_unrecorded(todo: list[Job], rows: dict) -> None:
    """After an interrupted run: delete the clip and poster of every job the manifest does not record.

    A worker can be interrupted after its clip got its name but before its row came back (Ctrl-C
    reaches the whole process group), and a clip of an older version of the job lost its row when the
    run started; either file would sit in ``clips/`` unaccounted for. The rerun renders those jobs.
    """
    for job in todo:
        if job.stimulus.stimulus_id not in rows:
            job.clip.unlink(missing_ok=True)
            job.poster.unlink(missing_ok=True)


def survey_for_render(report: RenderReport, video_base_url=None) -> tuple[list[str], list | None]:
    """Make a render folder a complete survey source: the design files and every survey export.

    Only when every stimulus of the report's design has its clip (a ``limit``/``only`` render is
    partial, and a survey pointing at missing clips would be wrong). Returns the stimulus ids without
    a clip and the exports written (``stimuli.survey.ExportResult`` s; None: nothing written).
    """
    from stimuli.design import write_design
    from stimuli.survey import export_all

    missing = sorted({s.stimulus_id for s in report.design.stimuli} - set(read_manifest(report.out_dir)))
    if missing or report.failed:
        return missing, None
    write_design(report.design, report.out_dir)
    return [], export_all(report.out_dir, video_base_url=video_base_url)


# Temporary names this package writes into a render folder and renames when complete (mkstemp and
# mkdtemp add 8 characters of [a-z0-9_]). Left behind only when a process was killed outright.
TEMPORARY_NAMES = {
    ".": r"\.(manifest\.csv|contact_sheet\.png|design\.json|conditions\.csv|trials\.csv)\.[a-z0-9_]{8}\.tmp",
    "clips": r"\..+\.[a-z0-9_]{8}\.tmp",            # video.write_video's private folder per clip
    "posters": r"\..+\.\d+\.tmp\.png|\..+\.[a-z0-9_]{8}\.tmp",   # video.write_png; fileio (--scheduler)
    "survey": r"\.(survey\.qsf|survey_qualtrics\.txt|qualtrics_manual_steps\.txt)\.[a-z0-9_]{8}\.tmp"
              r"|\.jspsych(\.old)?\.[a-z0-9_]{8}",   # stimuli.survey's staging folders
    "survey/psychopy": r"\..+\.[a-z0-9_]{8}\.tmp",
}


def sweep_temporaries(out_dir: str | Path) -> list[Path]:
    """Remove what killed runs left in a render folder: only this package's temporary names
    (:data:`TEMPORARY_NAMES`), only in the folders it writes; returns what was removed.

    Call it only while holding :func:`output_lock` (a running render's temporaries look the same).

    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> (folder / "clips" / ".a-1.x2_9kq0z.tmp").mkdir(parents=True)
    >>> (folder / "clips" / "notes.tmp").write_text("yours")
    5
    >>> [p.name for p in sweep_temporaries(folder)]
    ['.a-1.x2_9kq0z.tmp']
    >>> import shutil; shutil.rmtree(folder)
    """
    import re
    import shutil

    out_dir = Path(out_dir)
    removed = []
    for sub, pattern in TEMPORARY_NAMES.items():
        folder = out_dir / sub
        if not folder.is_dir():
            continue
        for path in sorted(folder.iterdir()):
            if not re.fullmatch(pattern, path.name):
                continue
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
            removed.append(path)
    return removed


def output_lock(out_dir: Path):
    """Hold an exclusive lock on the render folder (:func:`stimuli.fileio.folder_lock`).

    Two renders into one folder would each take the other's temporary files for leftovers, and race
    on the manifest; the second is refused.
    """
    return folder_lock(out_dir, busy=f"{out_dir}: another 'shapemotion render' is writing into this folder; "
                                    "let it finish, or render into another --out folder")


NO_SPACE = (errno.ENOSPC, errno.EDQUOT)


@contextmanager
def disk_full_is_a_user_error(out_dir: Path, report: RenderReport | None = None):
    """A full disk (or quota) while rendering or exporting: a StimuliError saying what is kept, not a
    traceback. Every writer removes its own temporary file first, so nothing half-written is left."""
    try:
        yield
    except OSError as exc:
        if exc.errno not in NO_SPACE:
            raise
        kept = (f"; the {len(report.rendered)} clip(s) finished in this run are kept and listed in {MANIFEST}"
                if report is not None else "")
        raise StimuliError(f"{out_dir}: no space left on the device ({exc.strerror or exc}){kept}; free some space "
                           "and run the same command again to go on from there") from None


def _update_manifest(out_dir: Path, rows: list[dict]) -> Path | None:
    """Write the manifest of the clips kept so far; with none, remove a stale one rather than leave
    an empty file (a CSV without even a header) that later steps would misread."""
    if rows:
        return write_manifest(out_dir, rows)
    (out_dir / MANIFEST).unlink(missing_ok=True)
    return None


def _ordered_ids(rows: dict, order: list[str]) -> list[str]:
    return [sid for sid in order if sid in rows]


def _ordered(rows: dict, order: list[str]) -> list[dict]:
    return [rows[sid] for sid in _ordered_ids(rows, order)]


def _worker_signals() -> None:
    """In a worker: make Ctrl-C stick (see ``stimuli.interrupts``).

    SIGTERM already raises SystemExit there (``stimuli.workers``): on Ctrl-C a worker that was idle
    dies of the interrupt and the pool terminates the others, and when this process dies its workers
    get SIGTERM too; either way a clip being written deletes its temporary folder.
    """
    install_interrupt_handler()


def _run(protocol, jobs: list[Job], source: tuple, workers: int, progress: bool, name: str):
    """Yield (stimulus_id, row or None, error or None) as clips finish; Ctrl-C stops cleanly."""
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), desc=f"render {name}", unit="clip", disable=not progress or not jobs)
    try:
        if workers == 1:
            for job in jobs:
                check_interrupted()
                result = _worker_job((protocol, job, *source))
                bar.update(1)
                yield result
            return
        with process_pool(workers, initializer=_worker_signals) as pool:
            pending = {pool.submit(_worker_job, (protocol, job, *source)) for job in jobs}
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        bar.update(1)
                        yield future.result()
            except KeyboardInterrupt:
                for future in pending:  # stop queued clips
                    future.cancel()
                # Clips already running either finish (and are recorded) or, interrupted too,
                # delete their temporary files; either way no clip is left unaccounted for.
                for future in pending:
                    if not future.cancelled():
                        try:
                            result = future.result()
                        except BaseException:
                            continue
                        yield result
                raise
            except BaseException:  # an error (a full disk) or the caller stopped reading: render no more
                for future in pending:
                    future.cancel()
                raise
    finally:
        bar.close()


def _run_on(scheduler):
    """:func:`_run` on a Dask cluster: each clip is a task keyed by its inputs hash, rendered in the
    worker's own temporary folder; the client writes the returned clip and poster atomically before
    the clip enters the manifest, so no worker needs this folder."""
    def run(protocol, jobs: list[Job], source: tuple, workers: int, progress: bool, name: str):
        from shapemotion.execution import dask_client, run_tasks
        from stimuli.fileio import atomic_write_bytes

        by_key = {f"render-{job.stimulus.stimulus_id}-{job.digest}": job for job in jobs}
        with dask_client(scheduler) as client:
            tasks = {key: (protocol, job, *source) for key, job in by_key.items()}
            for key, (sid, row, error, files) in run_tasks(client, remote_job, tasks, f"render {name}", "clip",
                                                           progress):
                if row is not None:
                    atomic_write_bytes(by_key[key].clip, files["clip"])
                    atomic_write_bytes(by_key[key].poster, files["poster"])
                yield sid, row, error
    return run


def remote_job(protocol, job: Job, source: str, motions_dir):
    """On a Dask worker: render one clip into a private temporary folder and return
    (stimulus_id, manifest row or None, error or None, {"clip": bytes, "poster": bytes} or None)."""
    import dataclasses
    import tempfile

    with tempfile.TemporaryDirectory(prefix="shapemotion-render-") as tmp:
        here = dataclasses.replace(job, clip=Path(tmp) / "clips" / job.clip.name,
                                   poster=Path(tmp) / "posters" / job.poster.name)
        sid, row, error = _worker_job((protocol, here, source, motions_dir))
        files = None if row is None else {"clip": here.clip.read_bytes(), "poster": here.poster.read_bytes()}
    return sid, row, error, files


MAX_REASONS, MAX_EXAMPLES = 8, 3  # enough to act on; the rest is counted, never dropped silently


def failure_groups(protocol_name: str, failed: dict[str, str]) -> dict[str, list[str]]:
    """Failed clips grouped by reason, largest group first. A reason is the message without the
    protocol's name in front and with the clip's own id replaced by ``<clip>``, so that one cause
    shared by many clips is one group. Ids are sorted (workers finish in any order: the message of
    the same failure must not change from run to run), equal-sized groups by reason.

    >>> failure_groups("p", {"b-2": "p: b-2 has no motion", "a-1": "p: a-1 has no motion", "c": "x missing"})
    {'<clip> has no motion': ['a-1', 'b-2'], 'x missing': ['c']}
    """
    groups: dict[str, list[str]] = {}
    for sid, message in sorted(failed.items()):
        reason = message.removeprefix(f"{protocol_name}: ").replace(sid, "<clip>")
        groups.setdefault(reason, []).append(sid)
    return dict(sorted(groups.items(), key=lambda item: (-len(item[1]), item[0])))


def _failure_message(protocol, report: RenderReport) -> str:
    """One paragraph: how many clips failed, then each reason once with its count and a few ids."""
    groups = list(failure_groups(protocol.name, report.failed).items())
    parts = []
    for reason, ids in groups[:MAX_REASONS]:
        more = f", … {len(ids) - MAX_EXAMPLES} more" if len(ids) > MAX_EXAMPLES else ""
        parts.append(f"{len(ids)} clip(s) ({', '.join(ids[:MAX_EXAMPLES])}{more}): {reason}")
    rest = groups[MAX_REASONS:]
    if rest:
        parts.append(f"{len(rest)} other reason(s) for {sum(len(ids) for _, ids in rest)} clip(s), e.g. "
                     f"{rest[0][1][0]}: {rest[0][0]}")
    return (f"{protocol.name}: {len(report.failed)} stimulus clip(s) could not be rendered, for "
            f"{len(groups)} reason(s); {len(report.rendered)} rendered, {len(report.skipped)} unchanged. "
            + " | ".join(parts))
