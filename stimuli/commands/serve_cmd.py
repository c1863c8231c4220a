"""``shapemotion serve``: run the study on this machine; ``shapemotion serve export``: its answers as a CSV."""

from __future__ import annotations

import argparse
import re
import secrets
import sys
from pathlib import Path

DB_NAME = "shapemotion-serve.db"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "serve", help="run the study: a self-hosted server with balanced assignment and per-trial saving",
        description="'shapemotion serve DIR' serves the jsPsych study of a design or render folder (with its "
                    "clips) and stores each answer in SQLite as it is given. 'shapemotion serve export DIR|DB "
                    "--out responses.csv' writes the answers in the format 'analyze' reads. See "
                    "docs/readme_serve.md.")
    p.add_argument("target", nargs="+", metavar="DIR | export DIR|DB",
                   help="design or render folder to serve; or 'export' and the folder or database file")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: put a TLS "
                                                       "reverse proxy in front)")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--db", type=Path, default=None, help=f"SQLite database (default DIR/{DB_NAME})")
    p.add_argument("--expire-min", type=float, default=60.0,
                   help="minutes after which an unfinished, silent session frees its list (default 60)")
    p.add_argument("--admin-token", default=None,
                   help="token for /admin/progress and /admin/export.csv (default: a random one, printed; "
                        "or $SHAPEMOTION_ADMIN_TOKEN)")
    p.add_argument("--rate", default="5/s",
                   help="requests a second each client may send per session (answers, events, finish) and to "
                        "start sessions, as N/s or N/min; over it: 429 with Retry-After, which the page "
                        "honours (default 5/s; 0: no limit)")
    p.add_argument("--burst", type=int, default=100,
                   help="requests a client may send at once before --rate applies (default 100)")
    p.add_argument("--out", type=Path, default=None, help="export: the CSV to write")
    p.set_defaults(func=run_serve)


def run_serve(args: argparse.Namespace) -> int:
    from stimuli.errors import StimuliError

    if args.target[0] == "export":
        if len(args.target) != 2 or args.out is None:
            raise StimuliError("serve export: expected 'shapemotion serve export DIR|DB --out responses.csv'")
        return run_export(Path(args.target[1]), args.db, args.out)
    if len(args.target) != 1:
        raise StimuliError(f"serve: expected one folder, got {' '.join(args.target)}; to export: "
                           f"'shapemotion serve export DIR --out responses.csv'")
    if args.out is not None:
        raise StimuliError("--out: only 'shapemotion serve export' writes a file")
    return run_server(Path(args.target[0]), args)


def check_server_options(args: argparse.Namespace) -> tuple[str, float]:
    """The admin token and the rate limit; every option checked before anything starts."""
    import os

    from stimuli.errors import StimuliError
    from stimuli.serve.limits import parse_rate

    if not 0 < args.port < 65536:
        raise StimuliError(f"--port {args.port}: expected 1 to 65535")
    if not args.expire_min > 0:
        raise StimuliError(f"--expire-min {args.expire_min}: expected a positive number of minutes")
    try:
        rate = parse_rate(args.rate)
    except ValueError as exc:
        raise StimuliError(str(exc)) from None
    if args.burst < 1:
        raise StimuliError(f"--burst {args.burst}: expected at least 1 request")
    token = args.admin_token or os.environ.get("SHAPEMOTION_ADMIN_TOKEN") or secrets.token_urlsafe(18)
    if not re.fullmatch(r"[A-Za-z0-9_.~-]{12,200}", token):
        raise StimuliError("--admin-token: expected at least 12 letters, digits or _.~- (it guards the answers)")
    return token, rate


def run_server(folder: Path, args: argparse.Namespace) -> int:
    import logging

    import uvicorn

    from stimuli.serve.app import create_app
    from stimuli.serve.db import Database
    from stimuli.serve.study import load_study

    token, rate = check_server_options(args)
    study = load_study(folder)
    db = Database(args.db or folder / DB_NAME, study.fingerprint)
    app = create_app(study, db, token, expire_s=args.expire_min * 60, rate=rate, burst=args.burst)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    limit = f"rate limit {args.rate} per client and session, burst {args.burst}" if rate else "no rate limit"
    print(f"serving {study.protocol.name} ({len(study.lists)} lists) at http://{args.host}:{args.port}/ "
          f"({limit})", file=sys.stderr)
    if not args.admin_token:
        print(f"admin token: {token}", file=sys.stderr)
    # one worker: the assignment and the database lock live in this process
    uvicorn.run(app, host=args.host, port=args.port, log_level="warning", proxy_headers=True)
    db.close()
    return 0


def run_export(source: Path, db_path: Path | None, out: Path) -> int:
    from stimuli.errors import StimuliError
    from stimuli.fileio import check_output_file
    from stimuli.serve.db import open_existing
    from stimuli.serve.export import sessions_path, write_export

    if db_path is None:
        db_path = source / DB_NAME if source.is_dir() else source
    elif not source.is_dir():
        raise StimuliError(f"{source}: with --db, give the served folder (or only the database file)")
    check_output_file(out)
    check_output_file(sessions_path(out))
    db = open_existing(db_path)
    try:
        answers, sessions = write_export(db, out)
    finally:
        db.close()
    print(answers)
    print(sessions)
    return 0
