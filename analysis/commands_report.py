"""CLI commands of the responses → results half. ``register(subparsers)`` adds them (see stimuli.cli).

    shapemotion responses inspect FILE|FOLDER [--json] [--design DIR]
    shapemotion simulate DIR --participants N --seed S --format long|qualtrics|jspsych --out FILE [--model M.yaml]
    shapemotion power DIR --participants N [N …] --sims K [--model M.yaml] [--effect E --target 0.8]
    shapemotion analyze DIR --responses FILE --out REPORT [--no-models]

Handlers import pandas, matplotlib and statsmodels inside themselves so ``shapemotion --help`` stays fast.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from analysis.errors import AnalysisError
from shapemotion.execution import SCHEDULER_HELP, SCHEDULER_METAVAR

SIMULATE_FORMATS = ["long", "qualtrics", "qualtrics-numeric", "qualtrics-legacy", "jspsych"]


def register(subparsers) -> None:
    _register_responses(subparsers)
    _register_simulate(subparsers)
    _register_power(subparsers)
    _register_analyze(subparsers)


# -- responses inspect ----------------------------------------------------------------------------------

def _register_responses(subparsers) -> None:
    p = subparsers.add_parser("responses", help="inspect a survey response export (Qualtrics, jsPsych, long CSV)")
    sub = p.add_subparsers(dest="responses_command", metavar="ACTION")
    q = sub.add_parser("inspect", help="format detected, number of responses, columns with their question text")
    q.add_argument("file", help="response export (CSV or JSON), or a folder of them (e.g. one jsPsych file each)")
    q.add_argument("--json", action="store_true", help="print JSON instead of text")
    q.add_argument("--design", metavar="DIR", help="also import against this design directory: counts, exclusions")
    q.set_defaults(func=run_inspect)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def run_inspect(args) -> int:
    from analysis.responses.inspect import describe_text, inspect_file
    info = inspect_file(args.file)
    if args.design:
        from analysis.io_design import load_design
        from analysis.responses import import_responses
        info["import"] = import_responses(args.file, load_design(args.design)).summary()
    print(json.dumps(info, indent=2, ensure_ascii=False) if args.json else describe_text(info))
    return 0


# -- simulate -------------------------------------------------------------------------------------------

def _register_simulate(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="synthetic participants' responses in a real export format",
                              description="Draw responses to the design in DIR from a generative model (YAML; "
                                          "default: the bundled model of the protocol, else a null model) and "
                                          "write them as a Qualtrics, jsPsych or long CSV export.")
    p.add_argument("dir", help="design directory (design.json, conditions.csv, trials.csv)")
    p.add_argument("--participants", type=int, required=True, help="number of participants")
    p.add_argument("--seed", type=int, required=True, help="random seed (same seed → same bytes)")
    p.add_argument("--format", choices=SIMULATE_FORMATS, default="long",
                   help="export format; jspsych writes JSON when FILE ends in .json (default long)")
    p.add_argument("--out", required=True, metavar="FILE", help="output file")
    p.add_argument("--model", metavar="M.yaml", help="generative model (see analysis/default_models/)")
    p.set_defaults(func=run_simulate)


def run_simulate(args) -> int:
    from analysis.io_design import load_design
    from analysis.io_files import atomic_write_text, check_output_file
    from analysis.io_writers import export_text
    from analysis.model_spec import load_model
    from analysis.simulate import list_reuse_note, simulate_responses
    out = check_output_file(args.out, "--out", _inputs(args))
    design = load_design(args.dir)
    model = load_model(args.model, design)
    _note_null_model(args, model, design)
    reuse = list_reuse_note(design, args.participants)
    if reuse:   # stderr: the response file stays byte-identical
        print(f"note: {reuse}", file=sys.stderr)
    sim = simulate_responses(design, model, args.participants, args.seed)
    atomic_write_text(out, export_text(sim, design, args.format, out.suffix, seed=args.seed))
    print(f"wrote {out}: {args.participants} participants, {int((~sim['practice']).sum())} test answers "
          f"({args.format}, model {model.name})")
    return 0


def _inputs(args) -> list:
    """The files simulate and power read (an output must never overwrite one of them)."""
    design = Path(args.dir)
    return [design / name for name in ("design.json", "conditions.csv", "trials.csv", "manifest.csv")] + [args.model]


def _note_null_model(args, model, design) -> None:
    """Say when the default model is the null model, so that nobody mistakes it for the protocol's effects."""
    if args.model is None and model.name == "null":
        name = design.protocol.get("name")
        why = (f"no bundled model for design {name!r}" if name else
               f"{design.directory / 'design.json'} names no protocol (fields 'name' and 'protocol.name' missing)")
        print(f"note: {why}; using the null model (no condition effects); pass --model M.yaml for others",
              file=sys.stderr)


# -- power ----------------------------------------------------------------------------------------------

def _register_power(subparsers) -> None:
    p = subparsers.add_parser("power", help="simulation-based power: rejection rate per effect (and a sweep over N)",
                              description="Simulate K data sets of N participants from a generative model, run "
                                          "the protocol's analysis on each, and report the rejection rate per "
                                          "effect with a 95 % Clopper-Pearson interval. Several N give a sweep.")
    p.add_argument("dir", help="design directory")
    p.add_argument("--participants", type=int, nargs="+", required=True, metavar="N",
                   help="number(s) of participants; several values sweep over N")
    p.add_argument("--sims", type=int, default=1000, metavar="K", help="simulated data sets per N (default 1000)")
    p.add_argument("--model", metavar="M.yaml", help="generative model (default: the bundled model of the protocol)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--alpha", type=float, help="significance level (default: the protocol's)")
    p.add_argument("--correction", choices=["none", "gg", "hf"], default="none",
                   help="sphericity correction of the ANOVA p-values (default none, as the paper)")
    p.add_argument("--effect", help="effect to size the study for, e.g. BODY:MOTION")
    p.add_argument("--target", type=float, default=0.8, help="power wanted for --effect (default 0.8)")
    p.add_argument("--csv", metavar="FILE", help="also write the table as CSV")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--scheduler", metavar=SCHEDULER_METAVAR, help=SCHEDULER_HELP + "; each N is one task")
    p.set_defaults(func=run_power)


def run_power(args) -> int:
    from analysis.io_design import load_design
    from analysis.io_files import atomic_write_text, check_output_file
    from analysis.model_spec import load_model
    from analysis.power import check_target, power_sweep, required_participants, required_text
    from analysis.simulate import check_seed, list_reuse_note
    from shapemotion.execution import errors_as, scheduler_option
    # options first: a bad one must not cost a whole simulation before it is reported
    if args.csv:
        check_output_file(args.csv, "--csv", _inputs(args))
    check_seed(args.seed)
    check_target(args.target)
    scheduler = scheduler_option(args.scheduler, AnalysisError)
    design = load_design(args.dir)
    model = load_model(args.model, design)
    _note_null_model(args, model, design)
    reuse = list_reuse_note(design, max(args.participants))   # as simulate says: data sets beyond N repeat lists
    if reuse:
        print(f"note: {reuse}", file=sys.stderr)
    if args.alpha is not None and not 0 < args.alpha < 1:
        raise AnalysisError(f"--alpha: expected a number between 0 and 1, got {args.alpha}")
    with errors_as(AnalysisError):
        table = power_sweep(design, model, args.participants, args.sims, args.seed, args.alpha,
                            progress=sys.stderr.isatty(), correction=args.correction, scheduler=scheduler)
    answer = text = None
    if args.effect:
        answer = required_participants(table, args.effect, args.target)
        text = required_text(table, args.effect, args.target, answer)
    # files carry no wall-clock figures: the same design, model and seed give the same bytes
    reproducible = table.drop(columns="datasets_per_second")
    if args.csv:
        atomic_write_text(args.csv, reproducible.to_csv(index=False, lineterminator="\n"))
    if args.json:
        print(json.dumps({"model": model.name, "rows": reproducible.to_dict("records"),
                          "effect": args.effect, "target": args.target, "required_participants": answer,
                          "answer": text}, indent=2))
        return 0
    cells = [f"{p:.3f} [{lo:.3f}, {hi:.3f}]" for p, lo, hi in zip(table["power"], table["ci_low"], table["ci_high"])]
    wide = table.assign(cell=cells).pivot(index="effect", columns="participants", values="cell")
    wide = wide.reindex(list(dict.fromkeys(table["effect"])))
    wide.columns = [f"N={n}" for n in wide.columns]
    print(f"model: {model.name}; {args.sims} simulated data sets per N; alpha {args.alpha or design.alpha}; "
          f"power [95% Clopper-Pearson CI]")
    print(wide.to_string())
    rate = table.groupby("participants")["datasets_per_second"].first()
    print("throughput: " + ", ".join(f"N={n}: {r:.0f} data sets/s" for n, r in rate.items()))
    if text:
        print(text)
    return 0


# -- analyze --------------------------------------------------------------------------------------------

def _register_analyze(subparsers) -> None:
    p = subparsers.add_parser("analyze", help="responses → tables, figures, exclusions and report.html",
                              description="Import the responses (explicit exclusions), run the protocol's "
                                          "analysis, and write paper-style tables, figures and a self-contained "
                                          "report.html into REPORT (a folder).")
    p.add_argument("dir", help="design directory (design.json, conditions.csv, trials.csv)")
    p.add_argument("--responses", required=True, metavar="FILE", help="response export (Qualtrics, jsPsych, long), "
                                                                       "or a folder of them")
    p.add_argument("--out", required=True, metavar="REPORT", help="output folder")
    p.add_argument("--no-models", action="store_true", help="skip the additional mixed/ordinal/GEE models")
    p.set_defaults(func=run_analyze)


def run_analyze(args) -> int:
    from analysis.report import analyze
    summary = analyze(args.dir, args.responses, args.out, models=not args.no_models)
    imp = summary["import"]
    if summary.get("simulated"):
        print("SIMULATED DATA: the responses were written by shapemotion simulate (column shapemotion_simulated); "
              "the report and tables say so at the top")
    print(f"{imp['rows']} rows: {imp['imported_rows']} imported, {imp['excluded_rows']} excluded "
          f"({', '.join(f'{k}: {v}' for k, v in imp['excluded_by_reason'].items()) or 'none'}); "
          f"{imp['participants']} participants")
    if imp.get("excluded_answers"):
        print(f"answers excluded one by one (the rest of their row imported): {imp['excluded_answers']} "
              f"({', '.join(f'{k}: {v}' for k, v in imp['answers_excluded_by_reason'].items())}) (see exclusions.csv)")
    if imp["columns_not_imported"]:
        print(f"columns not imported: {', '.join(imp['columns_not_imported'])} (see exclusions.csv)")
    if imp.get("files_not_read"):
        print(f"files not read: {'; '.join(f['name'] + ' (' + f['reason'] + ')' for f in imp['files_not_read'])} "
              f"(see exclusions.csv)")
    from analysis.position_bias import position_line
    for section in summary["sections"]:
        significant = section.get("results", {}).get("significant")
        if section.get("results", {}).get("not_computed"):
            print(f"{section['title']} — {section['results']['not_computed']}")
        elif significant is not None:
            print(f"{section['title']}: significant {', '.join(significant) or 'none'}")
        if section.get("results", {}).get("check") == "position":
            print(position_line(section["results"]))
    print(f"report: {Path(args.out) / 'report.html'}")
    return 0
