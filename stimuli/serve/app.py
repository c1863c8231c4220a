"""The study server: an ASGI app (Starlette) that serves the jsPsych page, the clips and a small JSON API.

Routes (all answers JSON; every refused request gets a 4xx, is logged, and stores nothing)::

    GET  /  /index.html  /config.js  /experiment.js  /lib/…  /clips/…   the page and the design's clips only
    POST /api/sessions                      start or resume: {"params": {URL parameters}, "resume": {...}}
    GET  /api/sessions/{id}                 the session's list from its next unanswered trial
    POST /api/sessions/{id}/trials          one answer: {"index": position, "response": …, "rt": ms}
    POST /api/sessions/{id}/events          a clip that failed: {"kind": "load_failed"|"play_failed", "clip": id}
    POST /api/sessions/{id}/finish          all answered → {"redirect": completion URL or null}
    GET  /admin/progress  /admin/export.csv  /admin/limits   behind "Authorization: Bearer <admin token>"

The session routes need the ``X-Session-Token`` header the start route returned: a participant can
read and write only their own session. Served files are a fixed list (the page, jsPsych, the clips of
the design): no other path, the database included, can be reached. The session routes and the start
are rate limited per client address and session (:mod:`stimuli.serve.limits`): a request over the
limit gets 429 with ``Retry-After`` before anything is read or stored, and is counted for the admin.
"""

from __future__ import annotations

import hmac
import json
import logging
import math
import re
import sqlite3
import time

from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response
from starlette.routing import Route

from stimuli.serve.assign import candidate_lists, least_filled
from stimuli.serve.db import Database
from stimuli.serve.export import export_csv
from stimuli.serve.limits import BURST, MAX_KEYS, RATE, RateLimiter
from stimuli.serve.study import Study, check_answer, check_rt, export_row
from stimuli.survey import jspsych

log = logging.getLogger("shapemotion.serve")
MAX_BODY = 16 * 1024          # one answer is a few hundred bytes; a ranking of many labels a few KB
SESSION_ID = re.compile(r"^[0-9a-f]{16}$")
PARTICIPANT_ID = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
PARAM_VALUE = re.compile(r"^[A-Za-z0-9_.:-]{0,64}$")   # ':' for Prolific-like ids of other platforms
EVENT_KINDS = {"load_failed", "play_failed"}
LIMITED_ROUTES = ("start", "resume", "trials", "events", "finish")
# Preloaded clips play from blob: URLs; jsPsych sets inline styles.
SECURITY_HEADERS = [(b"x-content-type-options", b"nosniff"), (b"x-frame-options", b"DENY"),
                    (b"referrer-policy", b"same-origin"),
                    (b"content-security-policy", b"default-src 'self'; media-src 'self' blob:; img-src 'self' "
                                                  b"data: blob:; style-src 'self' 'unsafe-inline'; "
                                                  b"frame-ancestors 'none'")]


class Refused(HTTPException):
    """A request the server turns down (4xx) with a message saying what was expected."""


def create_app(study: Study, db: Database, admin_token: str, expire_s: float = 3600.0, clock=time.time,
               rate: float = RATE, burst: int = BURST):
    """The ASGI app serving ``study`` with answers in ``db``; ``rate`` requests a second per client and
    session after a ``burst`` (``rate=0``: no limit).

    >>> from starlette.testclient import TestClient            # doctest: +SKIP
    >>> TestClient(create_app(study, db, "secret")).get("/admin/progress").status_code  # doctest: +SKIP
    401
    """
    index = jspsych.index_html(study.source)
    config = jspsych.config_js(study.config)
    between = study.source.between
    limiter = RateLimiter(rate, burst) if rate else None
    limited = dict.fromkeys(LIMITED_ROUTES, 0)     # 429s since the server started, by route
    limited_sessions: dict[str, int] = {}         # … and by session id (progress counts the real ones)

    # -- helpers ----------------------------------------------------------------------------------
    def state(session: dict) -> dict:
        """What the page needs to go on: its list from the next unanswered trial."""
        entry = study.lists[session["list"]]
        answered = db.answered(session["id"])
        position = len(answered)
        return {"session": session["id"], "token": session["token"], "participant": session["participant"],
                "list": session["list"], "groups": entry["groups"], "next": position,
                "total": len(entry["trials"]), "trials": entry["trials"][position:],
                "finished": session["finished"] is not None,
                "redirect": study.completion_url() if session["finished"] is not None else None}

    def own_session(request: Request) -> dict:
        sid = request.path_params["sid"]
        token = request.headers.get("x-session-token", "")
        session = db.session(sid) if SESSION_ID.fullmatch(sid) else None
        if session is None:
            raise Refused(404, f"session {sid[:20]!r}: no such session")
        if not hmac.compare_digest(token.encode(), session["token"].encode()):
            raise Refused(403, f"session {sid}: the X-Session-Token is not this session's")
        return session

    def limit(request: Request, route: str) -> None:
        """Refuse (429, Retry-After) a request over its client's rate, before anything is read or stored.

        The key is the client's address and the session id the request names (not looked up: the limit
        comes before the database); starting a session counts against the address alone.
        """
        if limiter is None:
            return
        sid = request.path_params.get("sid", "")
        sid = sid if SESSION_ID.fullmatch(sid) else ""
        wait = limiter.take((request.client.host if request.client else "", sid or route), clock())
        if wait:
            limited[route] += 1
            if sid and (sid in limited_sessions or len(limited_sessions) < MAX_KEYS):   # made-up ids: bounded
                limited_sessions[sid] = limited_sessions.get(sid, 0) + 1
            raise Refused(429, f"{route}: too many requests from this client; retry after {math.ceil(wait)} s",
                          headers={"Retry-After": str(math.ceil(wait))})

    def check_admin(request: Request) -> None:
        given = request.headers.get("authorization", "")
        if not hmac.compare_digest(given.encode(), f"Bearer {admin_token}".encode()):
            raise Refused(401, "admin: expected the header 'Authorization: Bearer <admin token>'")

    # -- the page and its files -------------------------------------------------------------------
    async def page(request: Request) -> Response:
        return HTMLResponse(index, headers={"cache-control": "no-store"})

    async def config_js(request: Request) -> Response:
        return Response(config, media_type="text/javascript", headers={"cache-control": "no-store"})

    async def static(request: Request) -> Response:
        path = study.files.get(request.path_params["path"])
        if path is None:
            raise Refused(404, "not found")
        kind = "text/javascript" if path.suffix == ".js" else None
        return FileResponse(path, media_type=kind)

    # -- participants -----------------------------------------------------------------------------
    async def start(request: Request) -> Response:
        limit(request, "start")
        body = await read_json(request)
        given = body.get("params", {})
        if not isinstance(given, dict):
            raise Refused(400, "params: expected an object of URL parameters")
        # URL parameters are kept for the record only when plain (ids, group levels): a platform's
        # other parameters must not stop a participant from starting
        params = {k: v for k, v in list(given.items())[:50] if isinstance(k, str) and len(k) <= 40
                  and isinstance(v, str) and PARAM_VALUE.fullmatch(v)}
        id_param = study.participant_param()
        for name in (id_param, "participant"):
            if name in given and name not in params and given[name] != "":
                raise Refused(400, f"{name}: expected 1 to 64 letters, digits or _.-")
        resume = body.get("resume")
        if isinstance(resume, dict) and isinstance(resume.get("session"), str):
            session = db.session(resume["session"]) if SESSION_ID.fullmatch(resume["session"]) else None
            if session and hmac.compare_digest(str(resume.get("token", "")).encode(), session["token"].encode()):
                db.touch(session["id"], clock())
                return JSONResponse(state(session))
        participant = params.get(id_param) or params.get("participant") or None
        if participant is not None and not PARTICIPANT_ID.fullmatch(participant):
            raise Refused(400, f"{id_param}: expected 1 to 64 letters, digits or _.-")
        if participant is not None and (session := db.session_of(participant)):
            db.touch(session["id"], clock())          # a returning participant gets their own session back
            return JSONResponse(state(session))
        now = clock()
        pool = candidate_lists(study.lists, params, between)
        chosen = least_filled(pool, db.occupancy(now - expire_s))
        try:
            session = db.create_session(chosen, participant, params, request.headers.get("user-agent", ""), now)
        except sqlite3.IntegrityError:                # the same participant twice at once: one session
            session = db.session_of(participant)
        log.info("session %s: participant %s, list %d", session["id"], session["participant"], chosen)
        return JSONResponse(state(session))

    async def resume(request: Request) -> Response:
        limit(request, "resume")
        session = own_session(request)
        db.touch(session["id"], clock())
        return JSONResponse(state(session))

    async def answer(request: Request) -> Response:
        limit(request, "trials")
        session = own_session(request)
        body = await read_json(request)
        trials = study.lists[session["list"]]["trials"]
        index = body.get("index")
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(trials):
            raise Refused(400, f"index: expected the list position 0 to {len(trials) - 1}, got {str(index)[:20]}")
        trial = trials[index]
        try:
            labels = study.config["response"]["labels"]
            response = check_answer(study.response_type, labels, trial.get("positions", []), body.get("response"),
                                    trial["kind"])
            rt = check_rt(body.get("rt"))
        except ValueError as exc:
            raise Refused(422, f"trial {index}: {exc}") from None
        row = export_row(study, session, trial, response, rt)
        position = len(db.answered(session["id"]))   # answers are stored in order: 0 … position - 1
        if index < position:                          # a retry of a stored answer is fine; a change is not
            if db.answer(session["id"], index)["response"] != row["response"]:
                raise Refused(409, f"trial {index}: already answered with another response")
            return JSONResponse({"stored": False, "next": position})
        if session["finished"] is not None:
            raise Refused(409, "this session is finished")
        if index != position:
            raise Refused(409, f"index: trial {index} is not the next unanswered one ({position})")
        db.add_answer(session["id"], index, row, clock())
        return JSONResponse({"stored": True, "next": index + 1})

    async def event(request: Request) -> Response:
        limit(request, "events")
        session = own_session(request)
        body = await read_json(request)
        kind, clip = body.get("kind"), body.get("clip")
        if kind not in EVENT_KINDS or not isinstance(clip, str) or len(clip) > 300:
            raise Refused(400, f"kind: expected one of {sorted(EVENT_KINDS)} and clip: a clip id")
        detail = str(body.get("detail", ""))[:200]
        if not db.add_event(session["id"], kind, json.dumps({"clip": clip, "detail": detail}), clock()):
            raise Refused(429, "too many events for this session")
        log.warning("session %s: %s %s %s", session["id"], kind, clip, detail)
        return JSONResponse({"stored": True})

    async def finish(request: Request) -> Response:
        limit(request, "finish")
        session = own_session(request)
        total = len(study.lists[session["list"]]["trials"])
        answered = len(db.answered(session["id"]))
        if answered < total:
            raise Refused(409, f"finish: {total - answered} of {total} trials are not answered yet")
        db.finish(session["id"], clock())
        return JSONResponse({"finished": True, "redirect": study.completion_url()})

    # -- the researcher ---------------------------------------------------------------------------
    async def progress(request: Request) -> Response:
        check_admin(request)
        return JSONResponse(progress_report(study, db, clock() - expire_s, limited_sessions))

    async def limits(request: Request) -> Response:
        check_admin(request)
        setting = {"rate_per_s": limiter.rate, "burst": limiter.burst} if limiter else {"rate_per_s": None}
        return JSONResponse(setting | {"refused": limited})

    async def export(request: Request) -> Response:
        check_admin(request)
        return Response(export_csv(db), media_type="text/csv",
                        headers={"content-disposition": f'attachment; filename="{study.protocol.name}.csv"'})

    async def refused(request: Request, exc: HTTPException) -> Response:
        if exc.status_code >= 400:
            log.warning("%s %s: %d %s", request.method, request.url.path[:200], exc.status_code, exc.detail)
        return JSONResponse({"error": exc.detail}, status_code=exc.status_code,
                            headers={"cache-control": "no-store"} | (exc.headers or {}))

    routes = [Route("/", page), Route("/index.html", page), Route("/config.js", config_js),
              Route("/api/sessions", start, methods=["POST"]),
              Route("/api/sessions/{sid}", resume, methods=["GET"]),
              Route("/api/sessions/{sid}/trials", answer, methods=["POST"]),
              Route("/api/sessions/{sid}/events", event, methods=["POST"]),
              Route("/api/sessions/{sid}/finish", finish, methods=["POST"]),
              Route("/admin/progress", progress), Route("/admin/export.csv", export), Route("/admin/limits", limits),
              Route("/{path:path}", static)]
    app = Starlette(routes=routes, exception_handlers={HTTPException: refused})
    return SecurityHeaders(app)


async def read_json(request: Request, limit: int = MAX_BODY) -> dict:
    """The request's JSON object, refusing bodies over ``limit`` bytes before reading them whole."""
    declared = request.headers.get("content-length", "0")
    if not declared.isdigit() or int(declared) > limit:
        raise Refused(413, f"body: at most {limit} bytes")
    body = b""
    async for chunk in request.stream():
        body += chunk
        if len(body) > limit:
            raise Refused(413, f"body: at most {limit} bytes")
    try:
        data = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        raise Refused(400, "body: expected a JSON object") from None
    if not isinstance(data, dict):
        raise Refused(400, "body: expected a JSON object")
    return data


def progress_report(study: Study, db: Database, since: float, limited: dict[str, int] | None = None) -> list[dict]:
    """Per list: its between groups, finished and in-progress sessions, expired ones, answers stored, and
    ``rate_limited``: requests of its sessions refused with 429 since the server started (``limited``)."""
    counts, limited = db.count_answers(), limited or {}
    report = {n: {"list": n, "groups": e["groups"], "finished": 0, "in_progress": 0, "expired": 0, "answers": 0,
                  "trials": len(e["trials"]), "rate_limited": 0} for n, e in sorted(study.lists.items())}
    for s in db.sessions():
        entry = report.setdefault(s["list"], {"list": s["list"], "groups": {}, "finished": 0, "in_progress": 0,
                                              "expired": 0, "answers": 0, "trials": 0, "rate_limited": 0})
        status = "finished" if s["finished"] is not None else "in_progress" if s["seen"] >= since else "expired"
        entry[status] += 1
        entry["answers"] += counts.get(s["id"], 0)
        entry["rate_limited"] += limited.get(s["id"], 0)
    return list(report.values())


class SecurityHeaders:
    """ASGI wrapper adding the security headers to every response."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def with_headers(message):
            if message["type"] == "http.response.start":
                message = dict(message)
                message["headers"] = list(message.get("headers", [])) + SECURITY_HEADERS
            await send(message)

        await self.app(scope, receive, with_headers)
