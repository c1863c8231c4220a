"""Checks of command-line numbers, shared by the commands: a bad value stops before any work with
a message naming the option, what was given and what was expected (never a silent default).

>>> positive("--fps", 30.0)
30.0
>>> in_range("--height", 1.8, (1.2, 2.3), "m")
1.8
"""

from __future__ import annotations

import math

from stimuli.errors import StimuliError


def positive(option: str, value, what: str = "a number > 0"):
    """``value`` if it is a finite number > 0 (None, the option not given, passes)."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise StimuliError(f"{option}: expected {what}, got {value}")
    return value


def at_least(option: str, value, low: int):
    """``value`` if it is >= ``low`` (None passes); for counts such as --cycles or --workers."""
    if value is not None and value < low:
        raise StimuliError(f"{option}: expected a whole number >= {low}, got {value}")
    return value


def in_range(option: str, value, bounds: tuple[float, float], unit: str = ""):
    """``value`` if it lies in the closed range ``bounds`` (None passes)."""
    low, high = bounds
    if value is not None and not (math.isfinite(value) and low <= value <= high):
        unit = f" {unit}" if unit else ""
        raise StimuliError(f"{option}: {value:g} is outside the human range {low:g}–{high:g}{unit}")
    return value


def human_body(height_m, bmi, height_option: str = "--height", bmi_option: str = "--bmi") -> None:
    """Height (m) and BMI within the protocol's human ranges (the same limits a protocol's actors have)."""
    from stimuli.protocol import BMI_RANGE, HEIGHT_RANGE_M

    in_range(height_option, height_m, HEIGHT_RANGE_M, "m (metres, not centimetres)")
    in_range(bmi_option, bmi, BMI_RANGE, "kg/m²")


BODY_KEYS = {"sex": "sex", "height": "height_m", "bmi": "bmi"}


def parse_body(spec: str, option: str = "--body") -> dict:
    """``sex=M,height=1.80,bmi=25`` (keys in any case and order) → {"sex": "M", "height_m": 1.8, "bmi": 25.0},
    every key once, none unknown, a human height and BMI.

    >>> parse_body("SEX=f,height=1.6,bmi=28.1")
    {'sex': 'F', 'height_m': 1.6, 'bmi': 28.1}
    """
    out = {}
    for part in spec.split(","):
        if part.count("=") != 1:  # "sex=M;height=1.8" is one part with two '='
            raise StimuliError(f"{option} {spec!r}: expected comma-separated key=value pairs like "
                               "sex=M,height=1.80,bmi=25")
        k, v = (x.strip() for x in part.split("=", 1))
        key = BODY_KEYS.get(k.lower())
        if key is None:
            raise StimuliError(f"{option}: unknown key {k!r} (expected sex, height, bmi)")
        if key in out:
            raise StimuliError(f"{option} {spec!r}: {k} is given twice")
        if key == "sex":
            out[key] = v.upper()
            if out[key] not in ("F", "M"):
                raise StimuliError(f"{option}: sex must be F or M, got {v!r}")
            continue
        try:
            if "_" in v:   # float() reads "1_8" as 18
                raise ValueError(v)
            out[key] = float(v)
        except ValueError:
            raise StimuliError(f"{option}: {k} must be a number, got {v!r}") from None
    missing = [k for k, key in BODY_KEYS.items() if key not in out]
    if missing:
        raise StimuliError(f"{option} {spec!r}: missing {', '.join(missing)}")
    human_body(out["height_m"], out["bmi"], f"{option} height", f"{option} bmi")
    return out


def base_url(option: str, url: str | None, absolute: bool):
    """``url`` if clip paths can be appended to it: no spaces, no query or fragment (``…?a=1/clips/x.mp4``
    is no clip address), and with ``absolute`` (Qualtrics loads the clips from elsewhere) an http(s)
    address with a host; an http(s) address always needs its host (``http://`` gave ``http:/clips/…``).

    >>> base_url("--video-base-url", "https://lab.example/exp1", absolute=True)
    'https://lab.example/exp1'
    """
    from urllib.parse import urlsplit

    if url is None:
        return url
    if not url.strip() or any(c.isspace() for c in url):
        raise StimuliError(f"{option} {url!r}: expected an address without spaces, such as https://example.org/exp1")
    parts = urlsplit(url)
    if "?" in url or "#" in url:
        raise StimuliError(f"{option} {url!r}: clip paths are appended to this address, so it cannot carry a "
                           "query (?…) or fragment (#…)")
    web = parts.scheme in ("http", "https")
    if (absolute and not web) or (web and not parts.netloc):
        raise StimuliError(f"{option} {url!r}: expected an absolute address with a host, starting with http:// or "
                           "https:// (the Qualtrics exports load the clips from it)")
    return url
