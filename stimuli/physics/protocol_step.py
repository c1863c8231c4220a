"""All COM motions of a protocol (Experiment 2): every actor × gait, cached, two processes.

For each sex × gait the NoCOM motion is ``<motions>/<sex>_<gait>.npz`` when a motions folder is
given, otherwise the DTW average of the protocol's test actors of that sex over the whole number
of gait cycles that fills the clip. The reference body (for b) is the body the NoCOM motion
belongs to: its metadata ``height_m`` and ``weight_kg`` or ``bmi`` (read as ``physics retarget``
reads them), else the mean height and BMI of the protocol's test actors of that sex, with a warning. Each COM motion is cached under
``$SHAPEMOTION_CACHE/physics`` keyed by the motion's bytes, the actor, the gains file and the code
that makes it (the body, motion and physics packages), so a second run only copies files. A NoCOM
average's simulations start as soon as it is made, from a copy in the cache named by its content,
while the next one is averaged; ``<out>`` is written only once every NoCOM motion has been checked.

With the feed-forward controller the gains are chosen once per NoCOM motion on its reference body
(:func:`stimuli.physics.tune.tune_for_motion`) and then kept for every actor; the choice is cached
under ``$SHAPEMOTION_CACHE/physics/gains_<key>.json`` keyed as a COM motion is (motion bytes,
reference body, gains file, code), and the actors' cache keys include the chosen gains.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import shutil
from concurrent.futures import as_completed
from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError
from stimuli.fileio import atomic_write_bytes, atomic_write_text, source_digest
from stimuli.physics.checks import result_warnings
from stimuli.workers import process_pool



def cache_dir() -> Path:
    from stimuli.bodies.backend import project_cache_root

    return project_cache_root() / "physics"


def reference_targets(protocol, sex: str, motion=None, where="NoCOM motion") -> tuple[tuple[float, float], str]:
    """(height_m, bmi) of the reference body of a sex, and a note when it is a guess.

    The body the NoCOM motion records (:func:`stimuli.physics.own_body.own_body`, read as
    ``physics retarget`` reads it: ``weight_kg`` before ``bmi``, checked against the same human
    ranges); a motion that records no height or neither weight nor BMI gets the mean height and
    BMI of the protocol's test actors of that sex, and the note says so. A recorded sex other than
    ``sex`` is an error: the file is that sex's NoCOM motion.
    """
    from stimuli.physics.own_body import check_reference, own_body

    if motion is not None:
        own = own_body(motion, where, hint=" (the height and weight or BMI of the body the motion was made on)")
        if own.sex is not None and own.sex != sex:
            raise StimuliError(f"{where}: metadata sex is {own.sex!r}, but this file is the NoCOM motion of sex {sex}")
        weight = own.weight_at(own.height_m) if own.height_m is not None else None
        if weight is not None:
            check_reference(own.height_m, weight[0], f"{where}: metadata height_m", f"{where}: metadata {weight[1]}")
            return (own.height_m, own.weight_kg / own.height_m ** 2 if weight[1] == "weight_kg" else own.bmi), ""
    actors = [a for a in protocol.actors if a.sex == sex and not a.practice_only]
    if not actors:
        raise StimuliError(f"protocol {protocol.name}: no test actors of sex {sex}")
    mean = float(np.mean([a.height_m for a in actors])), float(np.mean([a.bmi for a in actors]))
    return mean, (f"{where} records no height and weight or BMI of its own body: b is measured against the "
                  f"mean {sex} test actor ({mean[0]:.2f} m, BMI {mean[1]:.1f})")


def nocom_motion(protocol, sex: str, gait: str, motions_dir: Path | None):
    """The NoCOM motion of a sex × gait: ``<motions_dir>/<sex>_<gait>.npz`` when given, else the DTW
    average of the protocol's test actors of that sex (``stimuli.motion.average.protocol_average``)
    over the whole number of gait cycles that fills the protocol's clip (as Exp 1's motions): the
    renderer plays whole loops, and a 2-cycle jog loop filled 4 s at 120 instead of 138 steps/min."""
    from stimuli.motion import Motion
    from stimuli.motion.average import protocol_average
    from stimuli.motion.loop import cycles_for_clip

    if motions_dir is not None:
        path = Path(motions_dir) / f"{sex}_{gait}.npz"
        if not path.is_file():
            raise StimuliError(f"{path}: NoCOM average motion for sex {sex}, gait {gait} not found "
                               f"(expected <motions>/<sex>_<gait>.npz)")
        return Motion.load(path)
    cycles = cycles_for_clip(protocol.clip.duration_s, protocol.gaits[gait].cadence_spm) if gait in protocol.gaits else None
    return protocol_average(protocol, sex, gait, cycles=cycles)


def check_protocol_inputs(protocol, out: Path, motions_dir, workers: int) -> None:
    """Every argument problem before the first folder is made: the output folder, the worker count
    and each NoCOM file a given ``motions_dir`` must hold."""
    from stimuli.fileio import check_output_dir

    check_output_dir(out)
    if workers < 1:
        raise StimuliError(f"--workers: expected a whole number >= 1, got {workers}")
    if motions_dir is None:
        return
    if not Path(motions_dir).is_dir():
        raise StimuliError(f"--motions {motions_dir}: folder not found (expected <motions>/<sex>_<gait>.npz files)")
    for gait in protocol.gaits:
        for sex in sorted({a.sex for a in protocol.actors}):
            path = Path(motions_dir) / f"{sex}_{gait}.npz"
            if not path.is_file():
                raise StimuliError(f"{path}: NoCOM average motion for sex {sex}, gait {gait} not found "
                                   f"(expected <motions>/<sex>_<gait>.npz)")


def _tune_job(args: dict) -> dict:
    """The gains of one NoCOM motion, chosen on its reference body (runs in a worker process)."""
    from stimuli.bodies import fit_body
    from stimuli.motion import Motion
    from stimuli.physics.tune import tune_for_motion

    gains = tune_for_motion(Motion.load(args["motion"]), fit_body(args["sex"], *args["reference"]),
                            progress=lambda line: None)
    payload = dataclasses.asdict(gains)
    atomic_write_text(args["out"], json.dumps(payload, indent=1, sort_keys=True))
    return payload


def _tune_spec(motion_path: Path, sex: str, reference, cache: Path, gains_text: str) -> dict:
    """The gain choice of one NoCOM motion: its inputs and its cache file (keyed as a COM motion is)."""
    spec = {"choice": "tune_for_motion", "sex": sex, "reference": list(reference)}
    return dict(spec, motion=str(motion_path), out=str(cache / f"gains_{_key(motion_path, spec, gains_text)}.json"))


def _actor_jobs(protocol, gait: str, sex: str, motion_path: Path, reference, feedforward: bool, cache: Path,
                gains_text: str):
    """A function of the chosen gains (None: the shipped set) giving the jobs of every actor of ``sex``."""
    def make(gains: dict | None) -> list[dict]:
        jobs = []
        for actor in (a for a in protocol.actors if a.sex == sex):
            spec = {"actor": actor.id, "sex": sex, "height_m": actor.height_m, "bmi": actor.bmi,
                    "girths": actor_girths(actor), "weight_kg": actor.weight_kg, "gait": gait,
                    "reference": list(reference)}
            if feedforward:   # only then: the pure-PD cache keys stay those of earlier runs
                spec.update(feedforward=True, gains=gains)
            key = _key(motion_path, spec, gains_text)
            jobs.append(dict(spec, motion=str(motion_path), out_motion=str(cache / f"{key}.npz"),
                             out_report=str(cache / f"{key}.json"), name=f"COM_{actor.id}_{gait}"))
        return jobs
    return make


def _key(motion_path: Path, actor: dict, gains_text: str) -> str:
    h = hashlib.sha256()
    h.update(motion_path.read_bytes())
    h.update(json.dumps(actor, sort_keys=True).encode())
    h.update(gains_text.encode())
    h.update(source_digest("bodies", "motion", "physics").encode())   # the code that makes the result
    return h.hexdigest()[:20]


def actor_girths(actor) -> dict[str, float]:
    """The girths a protocol gives an actor (``waist_m``, ``hip_m``, ``chest_m``), which shape its body.

    The renderer fits the actor's body with them (``body_for_actor``); the ragdoll must be built
    from that body, not from one fitted to height and BMI alone."""
    return {k: getattr(actor, k) for k in ("waist_m", "hip_m", "chest_m") if getattr(actor, k, None) is not None}


def _job(args: dict) -> dict:
    """One actor × gait (runs in a worker process)."""
    from stimuli.bodies import fit_body
    from stimuli.motion import Motion
    from stimuli.physics.analysis_fig7 import gait_curves, reference_heel_strike_s
    from stimuli.physics.retarget import retarget

    from stimuli.physics.controller import Gains

    motion = Motion.load(args["motion"])
    body = fit_body(args["sex"], args["height_m"], args["bmi"], **args["girths"])
    ref_body = fit_body(args["sex"], *args["reference"])
    gains = Gains(**args["gains"]) if args.get("gains") else None
    result = retarget(motion, body, args["weight_kg"], reference_body=ref_body, gains=gains,
                      feedforward=args.get("feedforward", False))
    report = result.report
    if gains is not None:   # the per-motion choice: its scale of the gait's set and whether it met the bounds
        report["gain_choice"] = {k: gains.tuning[k] for k in ("scale", "met", "history")}
    report["actor"] = args["actor"]
    report["gait"] = args["gait"]
    if not result.sim.fell:
        curves = gait_curves(result.sim, result.ragdoll, int(motion.metadata.get("cycles", 2)),
                             reference_heel_strike_s(motion))
        report["fig7"] = curves
        for key in ("knee_flexion_peak_deg", "reference_knee_flexion_peak_deg", "knee_flexion_peak_change_deg",
                    "knee_flexion_stance_peak_deg", "knee_extension_moment_peak_nm_per_kg", "root_com_excursion_cm"):
            report[key] = curves[key]
        result.motion.metadata.update(actor=args["actor"], gait=args["gait"])
        result.motion.save(args["out_motion"])
    # The report marks the entry finished, so it is written whole or not at all: written in place, a
    # write cut short (a full disk, a kill) left a truncated report that every later run failed to read.
    atomic_write_text(args["out_report"], json.dumps(report, indent=1, sort_keys=True))
    return report


@contextlib.contextmanager
def _pool(workers: int, scheduler, progress):
    """The local process pool, or with ``scheduler`` the Dask cluster behind :class:`_FilesByValue`."""
    if scheduler is None:
        with process_pool(workers) as pool:
            try:
                yield pool
            except BaseException:   # a bad input met while simulating: drop the queued work, not wait for it
                pool.shutdown(wait=True, cancel_futures=True)
                raise
        return
    from shapemotion.execution import dask_pool

    with dask_pool(scheduler, announce=progress) as pool:
        yield _FilesByValue(pool)


class _FilesByValue:
    """Physics jobs on a Dask cluster with no shared folder: the NoCOM motion travels as bytes, the job
    runs in the worker's temporary folder, and the cache files it writes come back and are written
    here atomically, the report (or gains) last because its presence marks the job done. Each task is
    keyed by its cache file's name, the job's input hash."""

    OUTPUTS = ("out_motion", "out_report", "out")

    def __init__(self, pool):
        self.pool = pool

    def submit(self, fn, job: dict):
        outputs = [k for k in self.OUTPUTS if k in job]
        key = f"physics-{Path(job[outputs[-1]]).stem}"
        return self.pool.submit_keyed(key, _on_worker, fn, job, Path(job["motion"]).read_bytes(), outputs,
                                      then=lambda result: _write_back(job, outputs, *result))

    def map(self, fn, jobs):
        futures = [self.submit(fn, job) for job in jobs]
        return (future.result() for future in futures)


def _on_worker(fn, job: dict, motion: bytes, outputs: list[str]):
    """On a Dask worker: ``fn(job)`` with the job's files in a temporary folder; (result, {key: bytes})."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="shapemotion-physics-") as tmp:
        here = dict(job, motion=str(Path(tmp) / Path(job["motion"]).name))
        Path(here["motion"]).write_bytes(motion)
        here |= {k: str(Path(tmp) / Path(job[k]).name) for k in outputs}
        result = fn(here)
        return result, {k: Path(here[k]).read_bytes() for k in outputs if Path(here[k]).is_file()}


def _write_back(job: dict, outputs: list[str], result, files: dict[str, bytes]):
    for k in outputs:
        if k in files:
            atomic_write_bytes(job[k], files[k])
    return result


def _checked_nocom_motions(protocol, out: Path, motions_dir):
    """(gait, sex, NoCOM motion, reference body (height, BMI), note) per gait × sex, each motion made
    (or read from ``motions_dir``) and its reference body checked as it comes."""
    for gait in protocol.gaits:
        for sex in sorted({a.sex for a in protocol.actors}):
            motion = nocom_motion(protocol, sex, gait, Path(motions_dir) if motions_dir else None)
            source = Path(motions_dir) / f"{sex}_{gait}.npz" if motions_dir else out / "nocom" / f"{sex}_{gait}.npz"
            yield (gait, sex, motion, *reference_targets(protocol, sex, motion, source))


class _LazyPool:
    """:func:`_pool`, entered into ``stack`` at the first task: a run whose motions are all cached
    starts no worker (and connects to no cluster)."""

    def __init__(self, stack: contextlib.ExitStack, workers: int, scheduler, progress):
        self.stack, self.args, self.pool = stack, (workers, scheduler, progress), None

    def submit(self, fn, job: dict):
        if self.pool is None:
            self.pool = self.stack.enter_context(_pool(*self.args))
        return self.pool.submit(fn, job)

    @property
    def local(self):
        """The local process pool once started (None before, and on a cluster, whose tasks send files back)."""
        return self.pool if self.args[1] is None else None


def _submit_missing(pool, jobs: list[dict]) -> list[tuple[dict, object]]:
    """(job, future) for each of ``jobs`` whose report is not cached yet."""
    return [(job, pool.submit(_job, job)) for job in jobs if not Path(job["out_report"]).is_file()]


def _staged(motion, cache: Path) -> Path:
    """``motion`` saved under ``cache`` by its content (``nocom_<digest>.npz``), for the jobs to read
    before ``<out>`` exists: the same bytes as its copy in ``<out>/nocom``, hence the same cache keys."""
    data = motion.to_bytes()
    path = cache / f"nocom_{hashlib.sha256(data).hexdigest()[:20]}.npz"
    if not path.is_file():
        atomic_write_bytes(path, data)
    return path


def run_protocol(protocol_path: str | Path, out: str | Path, motions_dir: str | Path | None = None,
                 workers: int = 2, progress=None, feedforward: bool = False, scheduler=None) -> dict:
    """Make every COM motion of the protocol under ``out``.

    ``feedforward``: the PD plus the inverse-dynamics feed-forward of the NoCOM motion on its
    reference body (:func:`stimuli.physics.retarget.retarget`), with gains chosen once per NoCOM
    motion on that body (:func:`stimuli.physics.tune.tune_for_motion`, cached) and kept for its
    every actor; default the paper's pure PD with the shipped gains.

    ``scheduler``: a ``shapemotion.execution.Scheduler`` to simulate on a Dask cluster (None: ``workers``
    local processes); :class:`_FilesByValue` sends each job's files there and back.

    Returns ``{"reports": [...], "figures": [...], "warnings": [...]}``; ``progress`` (optional) is
    called with a line per simulated motion.
    """
    progress = progress or (lambda line: None)
    from stimuli.physics.controller import GAINS_FILE
    from stimuli.protocol import load_protocol

    protocol = load_protocol(protocol_path)
    out = Path(out)
    check_protocol_inputs(protocol, out, motions_dir, workers)
    gains_text = GAINS_FILE.read_text()
    cache = cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    nocom, notes = [], []
    actor_jobs = []   # per NoCOM motion: its actors' jobs once its gains are known
    chosen = {}       # feed-forward only: gain choices running -> (the actors' jobs maker, NoCOM index)
    running = []      # (job, future) of every COM motion being simulated
    # Spawned workers (a fork of a process that has loaded torch/OpenMP can deadlock on its locks) that
    # die with this process (stimuli.workers), started at the first task. An average's work is sent as
    # soon as it is made, so the workers simulate while this process averages the next one (the Exp-2
    # averages hold one core for ~8 s); the gain choices go first, and each motion's actors as soon as
    # its gains are known, so the workers never wait for all the choices.
    with contextlib.ExitStack() as stack:
        pool = _LazyPool(stack, max(1, min(workers, os.cpu_count() or 1)), scheduler, progress)
        made = _checked_nocom_motions(protocol, out, motions_dir)
        if motions_dir:   # files, quick to read: every one checked before the first simulation
            made = list(made)
        for gait, sex, motion, reference, note in made:
            notes += [note] if note else []
            staged = _staged(motion, cache)   # the jobs read this copy: <out> waits for every check
            make = _actor_jobs(protocol, gait, sex, staged, reference, feedforward, cache, gains_text)
            tune = _tune_spec(staged, sex, reference, cache, gains_text) if feedforward else None
            if tune and not Path(tune["out"]).is_file():
                chosen[pool.submit(_tune_job, tune)] = (make, len(nocom))
                actor_jobs.append([])
            else:
                actor_jobs.append(make(json.loads(Path(tune["out"]).read_text()) if tune else None))
                running += _submit_missing(pool, actor_jobs[-1])
            nocom.append((gait, sex, staged))
        for folder in ("nocom", "motions", "reports"):
            (out / folder).mkdir(parents=True, exist_ok=True)
        for gait, sex, staged in nocom:   # the staged copy's bytes: compressed once
            atomic_write_bytes(out / "nocom" / f"{sex}_{gait}.npz", staged.read_bytes())
        progress(f"physics: {len(running)} COM motion(s) to simulate, {sum(map(len, actor_jobs)) - len(running)} cached"
                 + (f"; gains to choose for {len(chosen)} NoCOM motion(s) first" if chosen else ""))
        for done in as_completed(chosen):
            make, i = chosen[done]
            actor_jobs[i] = make(done.result())
            progress(f"  gains for {nocom[i][1]}_{nocom[i][0]}: × {actor_jobs[i][0]['gains']['tuning']['scale']:g}")
            running += _submit_missing(pool, actor_jobs[i])
        for job, future in running:
            report = future.result()
            progress(f"  {job['name']}: b {report['b_m'] * 1000:.2f} mm, tracking {report['tracking_rms_deg_overall']:.2f}°, "
                     f"{'FELL' if report['fell'] else 'ok'}")
        reports = []
        for job in (j for jobs in actor_jobs for j in jobs):
            report = json.loads(Path(job["out_report"]).read_text())
            shutil.copyfile(job["out_report"], out / "reports" / f"{job['name']}.json")
            com = out / "motions" / f"{job['name']}.npz"
            if Path(job["out_motion"]).is_file():
                shutil.copyfile(job["out_motion"], com)
            else:   # it fell: an earlier run's COM motion left here would be rendered (--motions) as this one's
                com.unlink(missing_ok=True)
            reports.append(report)
        figures = _figures(protocol, reports, out, pool.local)
    _summary(reports, out / "summary.csv")
    fell = [f"{r['actor']} ({r['gait']}): {r['fall_reason']}" for r in reports if r["fell"]]
    if fell:
        raise StimuliError(f"{protocol_path}: the ragdoll fell for {len(fell)} COM motion(s): " + "; ".join(fell)
                           + f". Reports are in {out / 'reports'}")
    return {"reports": reports, "figures": figures, "warnings": notes + clip_warnings(reports)}


def clip_warnings(reports: list[dict]) -> list[str]:
    """One line per warning about a simulated clip (:func:`stimuli.physics.checks.result_warnings`).

    >>> clip_warnings([{"actor": "F_Hi1", "gait": "walk", "flight_fraction": 0.24, "reference_flight_fraction": 0.0,
    ...                 "tracking_rms_deg_overall": 1.5}])[0][:57]
    'COM_F_Hi1_walk: no foot on the floor for 24.0 % of the wa'
    """
    return [f"COM_{r['actor']}_{r['gait']}: {line}" for r in reports if not r.get("fell")
            for line in result_warnings(r, r["gait"])]


def _figures(protocol, reports: list[dict], out: Path, pool=None) -> list[Path]:
    """Fig. 7 of each gait (:func:`stimuli.physics.analysis_fig7.plot_fig7`), drawn side by side on
    ``pool``'s workers when given (each takes a core for ~2 s), else here."""
    drawings = []
    for gait in protocol.gaits:
        curves = {f"{r['body']['sex']}/{r['actor']}": dict(r["fig7"], bmi=r["body"]["bmi"], sex=r["body"]["sex"])
                  for r in reports if r["gait"] == gait and "fig7" in r and not r["actor"].split("_")[-1].startswith("P")}
        if curves:
            args = (curves, out / f"fig7_{gait}", f"{protocol.name}: COM method, {gait}", gait)
            drawings.append(pool.submit(_figure_job, args) if pool else _figure_job(args))
    return [path for drawn in drawings for path in (drawn.result() if pool else drawn)]


def _figure_job(args: tuple) -> list[Path]:
    """One gait's Fig. 7 (curves, output stem, title, gait); runs in a worker process or here."""
    from stimuli.physics.analysis_fig7 import plot_fig7

    curves, stem, title, gait = args
    return plot_fig7(curves, stem, title=title, gait=gait)


def over_limit(peaks: dict) -> str:
    """The DoFs whose peak torque exceeds its human limit, as ``dof peak/limit`` (N·m), ';'-joined.

    >>> over_limit({"knee.L": {"peak": 320.0, "limit": 250.0}, "hip.L:X": {"peak": 90.0, "limit": 250.0}})
    'knee.L 320/250'
    """
    return ";".join(f"{d} {p['peak']:.0f}/{p['limit']:.0f}" for d, p in sorted(peaks.items()) if p["peak"] > p["limit"])


def _summary(reports: list[dict], path: Path) -> None:
    import pandas as pd

    rows = [{"actor": r["actor"], "gait": r["gait"], "sex": r["body"]["sex"], "height_m": r["body"]["height_m"],
             "weight_kg": r["body"]["weight_kg"], "bmi": r["body"]["bmi"],
             "reference_weight_kg": r["reference_body"]["weight_kg"], "b_mm": round(r["b_m"] * 1000, 4),
             "b_paper_mm": round(r["b_paper_m"] * 1000, 3),
             "tracking_rms_deg": r["tracking_rms_deg_overall"], "nocom_rms_deg": r.get("nocom_rms_deg_mean"),
             "knee_flexion_peak_deg": r.get("knee_flexion_peak_deg"),
             "reference_knee_flexion_peak_deg": r.get("reference_knee_flexion_peak_deg"),
             "knee_flexion_peak_change_deg": r.get("knee_flexion_peak_change_deg"),
             "knee_flexion_stance_peak_deg": r.get("knee_flexion_stance_peak_deg"),
             "knee_extension_moment_peak_nm_per_kg": r.get("knee_extension_moment_peak_nm_per_kg"),
             "root_com_excursion_cm": r.get("root_com_excursion_cm"),
             "root_drift_vertical_max_m": r["root_drift"]["vertical_max_m"],
             "root_tilt_mean_deg": r.get("root_tilt_deg", {}).get("mean"), "flight_fraction": r.get("flight_fraction"),
             "reference_flight_fraction": r.get("reference_flight_fraction"),
             "reference_flight_under_gravity": r.get("reference_under_gravity", {}).get("flight_fraction"),
             "flight_fraction_contact_model": r.get("flight_fraction_contact_model"),
             "controller": "feedforward" if r.get("controller", {}).get("feedforward") else "pd",
             "torques_over_limit": over_limit(r.get("torque_peaks_nm", {})),
             "fell": r["fell"], "fall_reason": r.get("fall_reason")} for r in reports]   # no wall time: the same protocol gives the same bytes
    pd.DataFrame(rows).sort_values(["gait", "sex", "actor"]).to_csv(path, index=False)
