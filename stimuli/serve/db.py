"""The study server's SQLite database: sessions, one row per answered trial, and browser events.

WAL mode with ``synchronous=NORMAL``: a committed answer is in the write-ahead log before the server
replies, so killing the server (even SIGKILL) loses nothing it acknowledged. ``answers`` has the key
(session, position), so a retried POST cannot store a trial twice.

>>> db = Database(":memory:", "demo")
>>> s = db.create_session(list_number=1, participant="p1", params={}, user_agent="test", now=0.0)
>>> db.add_answer(s["id"], 0, {"response": 1}, now=1.0)
True
>>> db.add_answer(s["id"], 0, {"response": 1}, now=2.0)   # a retry: already there
False
>>> db.answered(s["id"])
[0]
"""

from __future__ import annotations

import json
import secrets
import sqlite3
import threading
from pathlib import Path

from stimuli.errors import StimuliError

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS sessions (
    id TEXT PRIMARY KEY,
    token TEXT NOT NULL,
    list INTEGER NOT NULL,
    participant TEXT NOT NULL UNIQUE,
    params TEXT NOT NULL,
    user_agent TEXT NOT NULL,
    started REAL NOT NULL,
    seen REAL NOT NULL,
    finished REAL
);
CREATE TABLE IF NOT EXISTS answers (
    session TEXT NOT NULL REFERENCES sessions(id),
    position INTEGER NOT NULL,
    row TEXT NOT NULL,
    received REAL NOT NULL,
    PRIMARY KEY (session, position)
);
CREATE TABLE IF NOT EXISTS events (
    session TEXT NOT NULL REFERENCES sessions(id),
    kind TEXT NOT NULL,
    detail TEXT NOT NULL,
    time REAL NOT NULL
);
"""
SESSION_COLUMNS = ["id", "token", "list", "participant", "params", "user_agent", "started", "seen", "finished"]


class Database:
    """One connection shared by the server's requests (serialised by a lock: SQLite writes one at a time)."""

    def __init__(self, path: str | Path, fingerprint: str):
        self.path = str(path)
        try:
            self.conn = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None, timeout=10)
            self.conn.execute("PRAGMA journal_mode=WAL")
            self.conn.execute("PRAGMA synchronous=NORMAL")
            self.conn.execute("PRAGMA foreign_keys=ON")
            self.conn.executescript(SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise StimuliError(f"{path}: not a shapemotion serve database ({exc})") from None
        self.lock = threading.Lock()
        self._check_fingerprint(fingerprint)

    def _check_fingerprint(self, fingerprint: str) -> None:
        """A database belongs to one design: answers are positions in that design's lists."""
        row = self.conn.execute("SELECT value FROM meta WHERE key = 'study'").fetchone()
        if row is None:
            self.conn.execute("INSERT INTO meta VALUES ('study', ?)", (fingerprint,))
        elif fingerprint and row[0] != fingerprint:
            raise StimuliError(f"{self.path}: this database holds answers of another design (study {row[0]}, "
                               f"the folder is study {fingerprint}); give a new --db file for this design")

    def close(self) -> None:
        self.conn.close()

    # -- sessions ---------------------------------------------------------------------------------
    def create_session(self, list_number: int, participant: str | None, params: dict, user_agent: str,
                       now: float) -> dict:
        """A new session with fresh random id and token; ``participant`` defaults to the session id."""
        sid, token = secrets.token_hex(8), secrets.token_urlsafe(24)
        with self.lock:
            self.conn.execute("INSERT INTO sessions VALUES (?, ?, ?, ?, ?, ?, ?, ?, NULL)",
                              (sid, token, list_number, participant or sid, json.dumps(params),
                               user_agent[:400], now, now))
        return self.session(sid)

    def session(self, sid: str) -> dict | None:
        row = self.conn.execute("SELECT * FROM sessions WHERE id = ?", (sid,)).fetchone()
        return dict(zip(SESSION_COLUMNS, row)) if row else None

    def session_of(self, participant: str) -> dict | None:
        row = self.conn.execute("SELECT * FROM sessions WHERE participant = ?", (participant,)).fetchone()
        return dict(zip(SESSION_COLUMNS, row)) if row else None

    def sessions(self) -> list[dict]:
        rows = self.conn.execute("SELECT * FROM sessions ORDER BY started, id").fetchall()
        return [dict(zip(SESSION_COLUMNS, r)) for r in rows]

    def touch(self, sid: str, now: float) -> None:
        with self.lock:
            self.conn.execute("UPDATE sessions SET seen = ? WHERE id = ?", (now, sid))

    def finish(self, sid: str, now: float) -> None:
        with self.lock:
            self.conn.execute("UPDATE sessions SET finished = COALESCE(finished, ?), seen = ? WHERE id = ?",
                              (now, now, sid))

    def occupancy(self, since: float) -> dict[int, int]:
        """Sessions per list that hold a slot: finished, or seen at or after ``since`` (not expired)."""
        rows = self.conn.execute("SELECT list, COUNT(*) FROM sessions WHERE finished IS NOT NULL OR seen >= ? "
                                 "GROUP BY list", (since,)).fetchall()
        return dict(rows)

    # -- answers and events -----------------------------------------------------------------------
    def add_answer(self, sid: str, position: int, row: dict, now: float) -> bool:
        """Store one answer; False when that position was already stored (a retried request)."""
        with self.lock, self.conn:   # one transaction: the answer and the session's last-seen time
            self.conn.execute("BEGIN")
            cur = self.conn.execute("INSERT OR IGNORE INTO answers VALUES (?, ?, ?, ?)",
                                    (sid, position, json.dumps(row), now))
            self.conn.execute("UPDATE sessions SET seen = ? WHERE id = ?", (now, sid))
        return cur.rowcount == 1

    def answer(self, sid: str, position: int) -> dict | None:
        row = self.conn.execute("SELECT row FROM answers WHERE session = ? AND position = ?",
                                (sid, position)).fetchone()
        return json.loads(row[0]) if row else None

    def answered(self, sid: str) -> list[int]:
        rows = self.conn.execute("SELECT position FROM answers WHERE session = ? ORDER BY position", (sid,))
        return [r[0] for r in rows]

    def answer_rows(self) -> list[tuple[str, dict]]:
        """(session id, export row) of every stored answer, by session start and list position."""
        rows = self.conn.execute("SELECT a.session, a.row FROM answers a JOIN sessions s ON s.id = a.session "
                                 "ORDER BY s.started, s.id, a.position").fetchall()
        return [(sid, json.loads(row)) for sid, row in rows]

    def count_answers(self) -> dict[str, int]:
        return dict(self.conn.execute("SELECT session, COUNT(*) FROM answers GROUP BY session").fetchall())

    def add_event(self, sid: str, kind: str, detail: str, now: float, limit: int = 200) -> bool:
        """Record a browser event (a clip that failed to load or play); at most ``limit`` per session."""
        with self.lock:
            (n,) = self.conn.execute("SELECT COUNT(*) FROM events WHERE session = ?", (sid,)).fetchone()
            if n >= limit:
                return False
            self.conn.execute("INSERT INTO events VALUES (?, ?, ?, ?)", (sid, kind, detail[:500], now))
        return True

    def events(self) -> list[dict]:
        rows = self.conn.execute("SELECT session, kind, detail, time FROM events ORDER BY time").fetchall()
        return [dict(zip(["session", "kind", "detail", "time"], r)) for r in rows]


def open_existing(path: str | Path) -> Database:
    """An existing database, for export; a missing or foreign file is a StimuliError naming it."""
    path = Path(path)
    if not path.is_file():
        raise StimuliError(f"{path}: no such database; give the --db file the server wrote")
    with path.open("rb") as handle:
        if handle.read(16) != b"SQLite format 3\x00":
            raise StimuliError(f"{path}: not an SQLite database; give the --db file 'shapemotion serve' wrote")
    probe = sqlite3.connect(path)   # look before Database() creates its tables in someone else's file
    try:
        tables = {r[0] for r in probe.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError as exc:
        raise StimuliError(f"{path}: not a readable SQLite database ({exc})") from None
    finally:
        probe.close()
    if not {"meta", "sessions", "answers"} <= tables:
        raise StimuliError(f"{path}: not a shapemotion serve database (no sessions/answers tables)")
    return Database(path, "")
