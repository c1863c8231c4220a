"""Rate limiting in the study server: a token bucket per client and per session.

Each key (the client's address with the session it writes to, or the client's address alone for starting
a session) has a bucket of ``burst`` tokens that refills at ``rate`` tokens a second; a request takes one
token, and a request that finds the bucket empty is refused (429) with the seconds until a token is
back. A participant answers at most about one trial a second and sends a short burst after a reload
or a network outage; the defaults (:data:`RATE`, :data:`BURST`) leave that untouched and cap a script
at a few writes a second per session.

>>> limiter = RateLimiter(rate=1.0, burst=2)
>>> [limiter.take(("127.0.0.1", "s1"), now=0.0) for _ in range(3)]
[0.0, 0.0, 1.0]
>>> limiter.take(("127.0.0.1", "s2"), now=0.0)     # another session: a bucket of its own
0.0
>>> limiter.take(("127.0.0.1", "s1"), now=1.0)     # a second later a token is back
0.0
"""

from __future__ import annotations

import re

RATE = 5.0       # tokens a second per key (a participant answers about once a second)
BURST = 100      # bucket size: a block's clip-failure events or a reload's resent requests at once
MAX_KEYS = 50_000   # buckets kept; full ones are forgotten first (a full bucket is the same as none)


class RateLimiter:
    """Token buckets by key; ``take`` returns 0.0 when the request may go on, else seconds to wait."""

    def __init__(self, rate: float = RATE, burst: int = BURST):
        if not rate > 0 or burst < 1:
            raise ValueError(f"rate limit: expected a positive rate and a burst of at least 1, got {rate}/s, {burst}")
        self.rate, self.burst = float(rate), int(burst)
        self.buckets: dict[tuple, tuple[float, float]] = {}   # key -> (tokens, time they were counted)

    def take(self, key: tuple, now: float) -> float:
        tokens, then = self.buckets.get(key, (self.burst, now))
        tokens = min(self.burst, tokens + max(0.0, now - then) * self.rate)
        if tokens < 1:
            self.buckets[key] = (tokens, now)
            return (1 - tokens) / self.rate
        if len(self.buckets) >= MAX_KEYS and key not in self.buckets:
            self._forget_full(now)
        self.buckets[key] = (tokens - 1, now)
        return 0.0

    def _forget_full(self, now: float) -> None:
        """Drop the buckets that have refilled (their clients are treated as new, which is what they are)."""
        full = [k for k, (tokens, then) in self.buckets.items() if tokens + (now - then) * self.rate >= self.burst]
        for key in full:
            del self.buckets[key]


def parse_rate(text: str) -> float:
    """``--rate``: requests a second per client and session, as ``N`` or ``N/s`` or ``N/min``; 0 turns it off.

    >>> parse_rate("5/s"), parse_rate("120/min"), parse_rate("0")
    (5.0, 2.0, 0.0)
    """
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*(?:/\s*(s|min))?\s*", text)
    if match is None:
        raise ValueError(f"--rate {text!r}: expected requests per second as N/s (e.g. 5/s), N/min, or 0 for no limit")
    value = float(match.group(1))
    return value / 60 if match.group(2) == "min" else value
