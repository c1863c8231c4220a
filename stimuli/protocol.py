"""Protocol files: the researcher's description of an experiment, validated with pydantic.

A protocol is YAML, read by a safe loader with limits (:data:`MAX_PROTOCOL_BYTES` of file; nodes, nesting
and alias expansion bounded by :mod:`analysis.io_yaml`). :func:`load_protocol`
turns it into a :class:`Protocol`, or raises :class:`~stimuli.errors.StimuliError` with one short
paragraph naming the file, the field, the YAML line and what was expected.

>>> from stimuli.protocol import load_protocol
>>> p = load_protocol("protocols/exp1_shape_motion.yaml")
>>> [f.name for f in p.factors]
['SEX', 'GAIT', 'BODY', 'MOTION']
>>> p.actor("F", "Hi1").bmi
28.1
"""

from __future__ import annotations

import json
import math
import re
import stat
import types
import typing
from pathlib import Path
from typing import Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator, model_validator

from analysis.io_yaml import MAX_YAML_CHARACTERS, load_bounded, yaml_problem
from stimuli.errors import StimuliError

# What a factor's levels mean on screen.
MapsTo = Literal["sex", "gait", "body", "motion", "method", "strength", "parameter", "source", "view", "none"]
SAFE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")   # used with fullmatch: "$" would let a trailing newline through
# Ids, labels, factor names and levels become parts of stimulus ids, file names and column headers.
MAX_NAME_LENGTH = 40
# The design a protocol may make (counted before it is made): the bundled ones make 1–64 test clips and
# 96–1,024 test trials; beyond these limits the design alone takes minutes and gigabytes.
MAX_STIMULI = 100_000
MAX_TRIALS = 1_000_000
# Columns of conditions.csv, trials.csv and the analysis's answer table (analysis.responses.tidy): a
# factor of one of these names would share its column with the design's own (a between factor called
# block was overwritten by the block number in trials.csv).
RESERVED_FACTOR_NAMES = ("participant", "condition_id", "stimulus_id", "practice", "kind", "body_actor",
                         "motion_actor", "left", "right", "positions", "block", "block_label", "trial",
                         "repetition", "response", "rating", "chosen", "position", "ranking", "rt", "row")
# The human ranges of a body (metres, kg/m²): the protocol's actors and the CLI's --height/--bmi/girths.
HEIGHT_RANGE_M = (1.2, 2.3)
# A gait's cadence (steps/min) and belt speed (m/s): the protocol's gaits, the generator's
# GaitParams and the CLI's --cadence/--speed all take these.
CADENCE_RANGE_SPM = (40.0, 260.0)
SPEED_RANGE_MPS = (0.2, 6.0)
BMI_RANGE = (13.0, 60.0)
GIRTH_RANGES_M = {"waist_m": (0.4, 2.0), "hip_m": (0.5, 2.0), "chest_m": (0.5, 2.0)}
BODY_FAT_RANGE_PCT = (0.0, 70.0)
# A clip's frame rate and size (pixels): the protocol's clip settings and render's --fps/--resolution.
CLIP_FPS_RANGE = (5, 240)
CLIP_WIDTH_RANGE = (64, 7680)
CLIP_HEIGHT_RANGE = (64, 4320)
# The level settings the renderer reads, by the maps_to of the factors they belong to (None: any factor).
LEVEL_SETTINGS = {"view_deg": None, "modifies": ("parameter",), "motion": ("source", "method"),
                  "base_scale": ("source",)}
SOURCE_MOTIONS = ("lean_walk", "modifier", "generator")  # or "bvh:<path>"
# What a METHOD level shows: its ``level_settings.<level>.motion`` when given, else by its name
# (NoCOM = the average motion, any other name = the physics (COM) motion): see method_motion_of.
METHOD_MOTIONS = ("average", "physics")
HEX_COLOUR = re.compile(r"^#?[0-9A-Fa-f]{6}$")
# What an alternatives factor's levels may map to: the renderer makes a motion for each of these
# (stimuli.render.sources); any other mapping would leave the side-by-side clips without motions.
ALTERNATIVE_MOTIONS = ("method", "strength", "source")
# The dependent measures that fit each response type (analysis.io_design checks the same pairs).
MEASURES_OF_RESPONSE = {"likert": ("mean_rating",), "afc": ("percent_chosen", "votes"), "ranking": ("rank_points",)}


class Strict(BaseModel):
    """Base model: unknown fields are errors (a typo must not be silently ignored)."""

    # use_attribute_docstrings: the docstring under a field is its description in the JSON Schema
    # (shapemotion schema) and the generated field reference
    model_config = ConfigDict(extra="forbid", frozen=True, use_attribute_docstrings=True)


# What an actor's capture may be (``motions:`` per gait): read by ``stimuli.motion.captures``.
CAPTURE_SUFFIXES = (".bvh", ".npz")
CAPTURE_GAITS = ("walk", "jog", "run")   # stimuli.motion.steady.GAITS: what capture_loop finds


# What the JSON Schema (shapemotion schema) allows where a before-validator widens the field: a level
# may be a YAML number (levels_as_text), a capture its file name alone (Actor._captures).
LEVEL_SCHEMA = {"type": ["string", "number"]}


def _capture_or_file_name(schema: dict) -> None:
    schema["additionalProperties"] = {"anyOf": [{"type": "string", "minLength": 1}, schema["additionalProperties"]]}


class Capture(Strict):
    """One gait of an actor as captured: a BVH or AMASS ``.npz`` file (relative paths start from the
    protocol's folder) and, optionally, the time range (seconds) to take the loop from; written as
    the file name alone or as ``{file: F, start_s: S, end_s: E}``."""

    file: str = Field(min_length=1)
    """the BVH or AMASS .npz capture file; a relative path starts from the protocol's folder"""
    start_s: float | None = Field(default=None, ge=0.0)
    """start of the range the loop is taken from, in seconds (default: the capture's start)"""
    end_s: float | None = Field(default=None, gt=0.0)
    """end of that range, in seconds, after start_s (default: the capture's end)"""

    @field_validator("file")
    @classmethod
    def _format(cls, value: str) -> str:
        if Path(value).suffix.lower() not in CAPTURE_SUFFIXES:
            raise ValueError(f"{shown(value)} is not a motion capture: expected a .bvh file or an AMASS .npz")
        return value

    @model_validator(mode="after")
    def _range(self) -> "Capture":
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise ValueError(f"end_s: {self.end_s:g} s must come after start_s ({self.start_s:g} s)")
        return self


class Actor(Strict):
    """A person whose body (and motion) the stimuli show. Units: metres, kg/m². ``motions``: the
    actor's own captures per gait (``{walk: captures/a_walk.bvh}``); a gait without one is generated."""

    id: str
    """unique id of the actor (letters, digits, '_', '-', '.', '+'; at most 40 characters), e.g. F_Hi1"""
    label: str
    """the short name by which BODY and MOTION levels name the actor (e.g. Hi1); one actor per label and sex"""
    sex: Literal["F", "M"]
    """F or M: the sex of the fitted body"""
    height_m: float = Field(ge=HEIGHT_RANGE_M[0], le=HEIGHT_RANGE_M[1], description="standing height in metres")
    bmi: float = Field(ge=BMI_RANGE[0], le=BMI_RANGE[1], description="body-mass index in kg/m²")
    group: str | None = None
    """optional group name (e.g. higher, lower), for the reader"""
    waist_m: float | None = Field(default=None, ge=GIRTH_RANGES_M["waist_m"][0], le=GIRTH_RANGES_M["waist_m"][1])
    """optional waist girth in metres the fitted body matches"""
    hip_m: float | None = Field(default=None, ge=GIRTH_RANGES_M["hip_m"][0], le=GIRTH_RANGES_M["hip_m"][1])
    """optional hip girth in metres the fitted body matches"""
    chest_m: float | None = Field(default=None, ge=GIRTH_RANGES_M["chest_m"][0], le=GIRTH_RANGES_M["chest_m"][1])
    """optional chest girth in metres the fitted body matches"""
    body_fat_pct: float | None = Field(default=None, ge=BODY_FAT_RANGE_PCT[0], le=BODY_FAT_RANGE_PCT[1])
    """optional body-fat percentage of the actor"""
    practice_only: bool = Field(default=False, strict=True)
    """true: the actor's body and motion appear in practice trials only, never in the test"""
    motions: dict[str, Capture] = Field(default={}, json_schema_extra=_capture_or_file_name)
    """the actor's own captures per gait (walk, jog, run): a file name, or {file, start_s, end_s}; a gait without
    one is generated"""

    @field_validator("motions", mode="before")
    @classmethod
    def _captures(cls, value):
        """A capture may be written as its file name alone."""
        if isinstance(value, dict):
            return {gait: {"file": spec} if isinstance(spec, str) else spec for gait, spec in value.items()}
        return value

    @field_validator("id", "label")
    @classmethod
    def _safe(cls, value: str) -> str:
        if not SAFE_ID.fullmatch(value):
            raise ValueError(f"{shown(value)} must use letters, digits, '_', '-', '.' or '+' only")
        _check_name_length(value)
        return value

    @property
    def weight_kg(self) -> float:
        return self.bmi * self.height_m**2


class Factor(Strict):
    """An independent variable: its levels, who varies it (between/within) and what it shows."""

    name: str
    """factor name: a letter, then letters, digits or '_'; not a column of the design files (block, trial, …)"""
    role: Literal["between", "within", "alternatives"]
    """between (each participant sees one level), within (every participant sees every level) or alternatives (the
    levels shown side by side and chosen between, e.g. METHOD)"""
    levels: list[str] = Field(min_length=2, json_schema_extra={"items": LEVEL_SCHEMA})
    """the levels (at least 2, none repeated; letters, digits, '_', '-', '.', '+'); body and motion levels are
    actor labels"""
    maps_to: MapsTo = "none"
    """what a level means on screen: sex, gait, body or motion (actor labels), method, strength, parameter, source,
    view, or none"""
    abbreviations: dict[str, str] = {}
    """per level, the text tables and figures show (e.g. Hi1: H1b); none blank, repeated or another level's name"""
    level_settings: dict[str, dict[str, float | str]] = {}
    """per level, settings the renderer reads: view_deg (any factor), modifies (parameter), motion (source or
    method), base_scale (source)"""

    @field_validator("levels", mode="before")
    @classmethod
    def _levels_as_text(cls, value):
        return levels_as_text(value)

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", value):
            raise ValueError(f"factor name {shown(value)} must start with a letter and use letters, digits or '_'")
        _check_name_length(value)
        if value in RESERVED_FACTOR_NAMES:
            raise ValueError(f"factor name {value!r} is a column of the design or answer files (reserved: "
                             f"{', '.join(RESERVED_FACTOR_NAMES)}); name the factor otherwise (e.g. {value.upper()})")
        return value

    @model_validator(mode="after")
    def _levels_known(self) -> "Factor":
        if len(set(self.levels)) != len(self.levels):
            raise ValueError(f"levels of {self.name} repeat: {shown(self.levels)}")
        for level in self.levels:
            if not SAFE_ID.fullmatch(level):
                raise ValueError(f"level {shown(level)} of {self.name} must use letters, digits, '_', '-', '.' or '+'")
            _check_name_length(level)
        _check_stimulus_id_parts(self)
        for where in (self.abbreviations, self.level_settings):
            unknown = sorted(set(where) - set(self.levels))
            if unknown:
                raise ValueError(f"{shown(unknown)} are not levels of {self.name} (levels: {shown(self.levels)})")
        _check_abbreviations(self)
        for level, settings in self.level_settings.items():
            for key, value in settings.items():
                _check_level_setting(self, level, key, value)
        if self.maps_to == "strength":
            _check_strength_levels(self)
        return self

    def abbreviation(self, level: str) -> str:
        return self.abbreviations.get(level, level)


def levels_as_text(value):
    """A list of levels as text: YAML reads ``3`` or ``12.5`` as numbers, which name levels as well as
    words. Anything else is left for the field's own check to refuse: a string is not iterated into
    letters (``BODY: P1`` is not ``[P, 1]``), ``yes``/``no``/``on``/``off`` (true and false to YAML)
    are refused rather than silently renamed ``True``/``False``.

    >>> levels_as_text([3, 12.5, "Hi1"]), levels_as_text("P1")
    (['3', '12.5', 'Hi1'], 'P1')
    """
    if not isinstance(value, list):
        return value
    for item in value:
        if isinstance(item, bool):
            raise ValueError(f"level {item}: YAML reads yes, no, on, off, true and false as true or false; "
                             "put the level in quotes (\"yes\") or rename it")
    return [str(v) if isinstance(v, (int, float)) else v for v in value]


def _check_name_length(name: str) -> None:
    if len(name) > MAX_NAME_LENGTH:
        raise ValueError(f"{shown(name)} is longer than {MAX_NAME_LENGTH} characters (ids, labels, factor names "
                         "and levels become parts of stimulus ids, file names and column headers)")


def _check_stimulus_id_parts(factor: "Factor") -> None:
    """Two levels of one factor must not make the same stimulus id: ids keep letters, digits, ``_``,
    ``.`` and ``+`` (``a-b`` and ``a_b`` both become ``a_b``), and a repeated id silently merged two
    conditions' clips and answers."""
    from stimuli.design import _safe   # the one spelling of ids (stimuli.design)

    seen: dict[str, str] = {}
    for level in factor.levels:
        part = _safe(level)
        if part in seen:
            raise ValueError(f"levels: {factor.name} levels {seen[part]!r} and {level!r} make the same stimulus id "
                             f"{part!r} (a '-' becomes '_'); rename one of them")
        seen[part] = level


def _check_abbreviations(factor: "Factor") -> None:
    """What tables and figures show for each level (its abbreviation, else its name) must tell the levels
    apart: a blank, a repeated abbreviation or one that is another level's name would label two cells
    alike or one cell as another.

    >>> _check_abbreviations(Factor(name="GAIT", role="within", levels=["walk", "jog"]))
    """
    shown_as: dict[str, str] = {}
    for level in factor.levels:
        abbreviation = factor.abbreviations.get(level)
        if abbreviation is not None and not abbreviation.strip():
            raise ValueError(f"abbreviations: the abbreviation of {level!r} is blank; give it some text, or leave "
                             f"{level!r} out of abbreviations (it is then shown by its name)")
        if abbreviation is not None and abbreviation != level and abbreviation.strip() in factor.levels:
            raise ValueError(f"abbreviations: {level!r} is abbreviated {shown(abbreviation)}, the name of another "
                             f"{factor.name} level; tables and figures would show one level as the other")
        text = factor.abbreviation(level).strip()
        if text in shown_as:
            raise ValueError(f"abbreviations: {factor.name} levels {shown_as[text]!r} and {level!r} are both shown "
                             f"as {shown(text)}; give each level an abbreviation of its own")
        shown_as[text] = level


def _check_level_setting(factor: "Factor", level: str, key: str, value) -> None:
    """One ``level_settings`` entry, checked as the renderer will read it (a typo fails here, not
    half-way through a render)."""
    where = f"level_settings.{level}.{_key_text(key)}"
    if key not in LEVEL_SETTINGS:
        raise ValueError(f"{where}: unknown setting (known: {', '.join(LEVEL_SETTINGS)})")
    owners = LEVEL_SETTINGS[key]
    if owners is not None and factor.maps_to not in owners:
        raise ValueError(f"{where}: only read for a factor with maps_to: {' or '.join(owners)} ({factor.name} "
                         f"maps to {factor.maps_to})")
    if key == "view_deg":
        if isinstance(value, str) or not -360.0 <= value <= 360.0:
            raise ValueError(f"{where}: expected a view angle in degrees between -360 and 360, got {shown(value)}")
    elif key == "base_scale":
        if isinstance(value, str) or not value > 0:
            raise ValueError(f"{where}: expected a number > 0, got {shown(value)}")
    elif key == "motion" and factor.maps_to == "method":
        if value not in METHOD_MOTIONS:
            raise ValueError(f"{where}: expected one of {', '.join(METHOD_MOTIONS)}, got {shown(value)}")
    elif key == "motion":
        if not isinstance(value, str) or not (value in SOURCE_MOTIONS or value.startswith("bvh:")
                                              and value[4:].strip()):
            raise ValueError(f"{where}: expected one of {', '.join(SOURCE_MOTIONS)} or bvh:<path>, got {shown(value)}")
    elif key == "modifies":
        from stimuli.motion.modifier import STRENGTH_ROWS

        names = [n.strip() for n in str(value).split("+")]
        unknown = [n for n in names if n not in STRENGTH_ROWS]
        if unknown:
            raise ValueError(f"{where}: unknown Table 4-1/5-2 row(s) {shown(unknown)}; expected names joined by '+' "
                             f"from: {', '.join(STRENGTH_ROWS)}")


def _check_strength_levels(factor: "Factor") -> None:
    """A strength level is a body-fat % within Table 4-1's columns."""
    from stimuli.motion.modifier import STRENGTH_BODY_FAT

    low, high = STRENGTH_BODY_FAT[0], STRENGTH_BODY_FAT[-1]
    for level in factor.levels:
        try:
            ok = low <= float(level) <= high
        except ValueError:
            ok = False
        if not ok:
            raise ValueError(f"levels: {factor.name} maps to strength, so level {shown(level)} must be a body-fat % "
                             f"between {low:g} and {high:g}")


class GaitSpec(Strict):
    """Cadence and belt speed of one gait: every actor walks (or jogs) at these."""

    cadence_spm: float = Field(ge=CADENCE_RANGE_SPM[0], le=CADENCE_RANGE_SPM[1], description="steps per minute")
    speed_mps: float = Field(ge=SPEED_RANGE_MPS[0], le=SPEED_RANGE_MPS[1], description="belt speed in m/s")


class Camera(Strict):
    """Where the camera stands, relative to the body."""

    azimuth_deg: float = 30.0
    """horizontal angle of the camera around the body, in degrees"""
    elevation_deg: float = 10.0
    """height of the camera as an angle above the horizon, in degrees"""
    distance_m: float = Field(default=4.0, gt=0.5, le=50)
    """camera distance in metres (on a floor layout a framing rule sets it so that treadmill and body fill the
    frame)"""
    fov_deg: float = Field(default=40.0, gt=5, lt=150)
    """field of view in degrees"""


class ClipSettings(Strict):
    """A clip's length and look. ``cycles`` is the fewest whole gait cycles every declared gait must
    show (the clip shows as many as fit: see ``stimuli.render.timing``); ``width`` and ``height``
    are even because H.264 in yuv420p halves them for the colour planes."""

    duration_s: float = Field(gt=0, le=120)
    """clip length in seconds (at most 120)"""
    # strict: YAML's true, "2" or 0 are not a number of cycles, a frame rate or a yes/no
    cycles: int = Field(default=1, ge=1, strict=True)
    """the fewest whole gait cycles every gait must show (default 1)"""
    fps: int = Field(default=30, ge=CLIP_FPS_RANGE[0], le=CLIP_FPS_RANGE[1], strict=True)
    """frames per second (5–240)"""
    width: int = Field(default=1280, ge=CLIP_WIDTH_RANGE[0], le=CLIP_WIDTH_RANGE[1], strict=True)
    """clip width in pixels, even (64–7680)"""
    height: int = Field(default=720, ge=CLIP_HEIGHT_RANGE[0], le=CLIP_HEIGHT_RANGE[1], strict=True)
    """clip height in pixels, even (64–4320)"""
    camera: Camera = Camera()
    """where the camera stands"""
    background: str = "#ffffff"
    """background colour, #rrggbb"""
    loop: bool = Field(default=True, strict=True)
    """true: the clip shows whole gait cycles and loops cleanly (cadence rounded to fit); false: the protocol's
    cadence, cut at duration_s"""

    @field_validator("width", "height")
    @classmethod
    def _even(cls, value: int) -> int:
        if value % 2:
            raise ValueError(f"expected an even number of pixels (H.264 yuv420p cannot encode an odd size), got "
                             f"{value}; use {value - 1} or {value + 1}")
        return value

    @field_validator("background")
    @classmethod
    def _colour(cls, value: str) -> str:
        if not HEX_COLOUR.match(value.strip()):
            raise ValueError(f"expected a colour like '#ffffff' (#rrggbb), got {shown(value)}")
        return value


class Display(Strict):
    """How a stimulus is shown. ``alternatives`` clips put the levels of one factor side by side."""

    layout: Literal["treadmill", "side_by_side", "point_light", "row"]
    """treadmill (one character), side_by_side (two clips), point_light (15 dots on the background) or row (several
    clips)"""
    labels: list[str] | None = None
    """names of the screen positions (e.g. A–F); none blank or repeated"""
    body: str | None = Field(default=None, description="actor id whose body is shown when no factor maps to body")
    # The renderer draws the 15 markers of SPEC §1.3 (the thesis's set); other counts were accepted and ignored.
    point_light_markers: int | None = Field(default=None, strict=True, description="15: the only marker set drawn")
    # Meshes stand on treadmills on a checker floor unless false (the thesis's renders: figures on a
    # plain background); point lights never have one, so the setting is refused there.
    floor: bool | None = Field(default=None, strict=True, description="treadmills and checker floor (default true)")
    label_position: Literal["above", "below"] | None = Field(default=None, description="labels above (default) or below")
    label_colour: str | None = Field(default=None, pattern=r"^#[0-9a-fA-F]{6}$",
                                     description="#rrggbb (default: black or white against the background)")

    @model_validator(mode="after")
    def _labels_tell_positions_apart(self):
        check_distinct_labels(self.labels or [], "labels", "every screen position")
        return self

    @model_validator(mode="after")
    def _floor_is_for_meshes(self):
        if self.floor is not None and self.layout == "point_light":
            raise ValueError("floor: point-light walkers are drawn on the background alone; remove floor")
        return self

    @model_validator(mode="after")
    def _label_style_needs_labels(self):
        styled = [k for k in ("label_position", "label_colour") if getattr(self, k) is not None]
        if styled and not self.labels:
            raise ValueError(f"{' and '.join(styled)}: no labels to draw; give display.labels or remove it")
        return self

    @model_validator(mode="after")
    def _markers_are_the_drawn_set(self):
        if self.point_light_markers is None:
            return self
        if self.point_light_markers != 15:
            raise ValueError(f"point_light_markers must be 15 (SPEC §1.3's marker set, the one the renderer draws), "
                             f"got {self.point_light_markers}")
        if self.layout != "point_light":
            raise ValueError(f"point_light_markers is only used with layout point_light, not {self.layout}")
        return self


class Alternatives(Strict):
    """Counterbalancing of the positions of an ``alternatives`` factor's levels on screen.

    ``arrangements``: ``all`` (every permutation), ``latin_square`` (k orders, each level
    once in each position; shuffled by ``seed`` from three levels on, see
    :func:`stimuli.orders.arrangements`), ``fixed`` (the declared order only). ``counterbalance``: ``within``
    (every participant sees every arrangement) or ``between`` (each participant sees one
    arrangement per condition, rotated so positions balance over participants).
    """

    arrangements: Literal["all", "latin_square", "fixed"] = "all"
    """screen orders of the alternatives: all (every permutation), latin_square (k orders, each level once in each
    position) or fixed (the declared order)"""
    counterbalance: Literal["within", "between"] = "within"
    """within (every participant sees every arrangement) or between (one arrangement per condition, rotated over
    participants)"""


class Blocks(Strict):
    """Which within factors define blocks, how block order varies over participants, and the order
    of the test trials inside a block.

    ``order`` — ``counterbalanced`` (alias ``latin_square``): rows of a Williams Latin square dealt
    out evenly; ``random``: a fresh random order per participant; ``fixed``: the declared order for
    everyone. ``trials`` — ``random``: the block's test trials shuffled per participant, never the
    same clip twice in a row; ``fixed``: the declared order of the factor levels for everyone (the
    first-declared factor varying slowest), the whole sequence once per repetition.
    ``nested`` — ``false`` (the default): every combination of the ``by`` levels is one block, the
    blocks ordered as a whole; ``true``: the first ``by`` factor makes main blocks and the others
    sub-blocks inside each, a main block's sub-blocks shown one after the other (``order`` applies
    at both levels; familiarisation comes once before each main block: see :mod:`stimuli.design`).
    """

    by: list[str] = []
    """the within factors that define blocks"""
    order: Literal["counterbalanced", "latin_square", "random", "fixed"] = "counterbalanced"
    """block order over participants: counterbalanced (alias latin_square: Williams Latin square rows dealt
    evenly), random or fixed"""
    trials: Literal["random", "fixed"] = "random"
    """test order inside a block: random (per participant, never a clip twice in a row) or fixed (the declared
    order of the levels)"""
    nested: bool = Field(default=False, strict=True)   # strict: 1 or a quoted "true" is refused
    """true: the first 'by' factor makes main blocks, the others sub-blocks inside each (needs two or more 'by'
    factors)"""


class Practice(Strict):
    """Practice trials before each block, built from practice-only levels (not used in the test)."""

    per_block: int = Field(default=0, ge=0, strict=True)
    """practice trials before each block (0: none)"""
    levels: dict[str, list[str]] = Field(default={}, json_schema_extra={
        "additionalProperties": {"type": "array", "items": LEVEL_SCHEMA}})
    """practice-only levels per within factor that does not define blocks (not test levels)"""

    @field_validator("levels", mode="before")
    @classmethod
    def _as_text(cls, value):
        return {k: levels_as_text(vs) for k, vs in value.items()} if isinstance(value, dict) else value


class Familiarization(Strict):
    """Before each block, the block's bodies shown one by one (e.g. in increasing BMI order)."""

    enabled: bool = Field(default=False, strict=True)
    """true: before each block, show the block's bodies one by one"""
    order: Literal["bmi_ascending", "bmi_descending", "declared"] = "bmi_ascending"
    """order of the bodies shown: bmi_ascending, bmi_descending or declared"""


class Response(Strict):
    """What the participant answers after each clip."""

    type: Literal["likert", "afc", "ranking"]
    """likert (a rating scale), afc (a forced choice among the alternatives) or ranking (of the alternatives)"""
    question: str
    """the question shown with every clip"""
    labels: list[str] = []
    """the Likert scale's labels (2 or more), or names for the choices; none blank or repeated (answers are matched
    to labels ignoring case and spacing)"""
    instructions: str = ""
    """text shown before the trials"""

    @model_validator(mode="after")
    def _labels(self) -> "Response":
        if self.type == "likert" and len(self.labels) < 2:
            raise ValueError("a likert response needs at least 2 labels (e.g. 'Very Inconsistent' … 'Very Consistent')")
        check_distinct_labels(self.labels, "labels", "every point of the scale")
        return self


def check_distinct_labels(labels: list[str], field: str, who: str) -> None:
    """Labels that answers are matched to must tell the answers apart: none blank, none repeated once
    case and spacing are ignored (as :mod:`analysis.responses.scoring` matches them). A repeated Likert
    label silently moved every answer of the second to the first (ratings 2, 3, 5 only).

    >>> check_distinct_labels(["Disagree", "Neutral", "agree "], "labels", "every point of the scale")
    >>> check_distinct_labels(["Agree", " agree"], "labels", "every point of the scale")
    Traceback (most recent call last):
    ...
    ValueError: labels.1: label 2 ' agree' repeats label 1 ('Agree'); answers are matched to labels ignoring case and spacing, so every point of the scale needs a label of its own
    """
    seen: dict[str, int] = {}
    for index, label in enumerate(labels):
        if not label.strip():
            raise ValueError(f"{field}.{index}: label {index + 1} is blank; {who} needs a label to show and to "
                             "read answers by")
        key = " ".join(label.split()).casefold()
        if key in seen:
            raise ValueError(f"{field}.{index}: label {index + 1} {shown(label)} repeats label {seen[key] + 1} "
                             f"({shown(labels[seen[key]])}); answers are matched to labels ignoring case and "
                             f"spacing, so {who} needs a label of its own")
        seen[key] = index


class Assignment(Strict):
    """How participants are assigned to between groups and block orders."""

    method: Literal["balanced"] = "balanced"
    """balanced: participants are dealt evenly over the between groups and block orders"""


class Recruitment(Strict):
    """Hand-off to a recruitment platform for ``shapemotion serve``: where a finished participant is sent.

    ``completion_url`` may hold ``{code}``; for Prolific it defaults to Prolific's completion address.
    ``participant_param`` names the URL parameter that carries a platform's participant id
    (Prolific: ``PROLIFIC_PID``).
    """

    platform: Literal["prolific", "other"] = "prolific"
    """prolific or other"""
    completion_code: str = Field(default="", max_length=200, pattern=r"^[A-Za-z0-9_-]*$")
    """the code a finished participant is given (letters, digits, '_', '-')"""
    completion_url: str = Field(default="", max_length=2000, pattern=r"^(https?://\S*)?$")
    """where a finished participant is sent; may hold {code} (for Prolific, Prolific's completion address by
    default)"""
    participant_param: str = Field(default="", max_length=100, pattern=r"^[A-Za-z0-9_]*$")
    """the URL parameter carrying the platform's participant id (Prolific: PROLIFIC_PID)"""


class AttentionChecks(Strict):
    """Instructed-response checks between the test trials (jsPsych and serve; the Qualtrics and PsychoPy
    exports put them at fixed slots of the test blocks, stimuli/survey/checks.py): after every ``every``-th
    test trial a screen asks for one given answer (``prompt``'s ``{answer}`` is replaced by it) and shows
    the usual answer buttons. The data mark them ``attention_check = 1``; the response import reports the
    failed checks per participant and excludes every answer of a participant who failed
    ``exclude_if_failed`` or more (None: report only).

    >>> AttentionChecks(every=16, answer="Neutral").prompt
    "To show that you are reading this, please select '{answer}'."
    """

    every: int = Field(ge=1, le=10_000, strict=True)
    """a check after every N-th test trial"""
    answer: str = Field(min_length=1, max_length=200)
    """the answer the check asks for: one of the answer buttons"""
    prompt: str = Field(default="To show that you are reading this, please select '{answer}'.", max_length=2000)
    """the check's text; {answer} is replaced by the answer"""
    exclude_if_failed: int | None = Field(default=None, ge=1, strict=True)
    """exclude every answer of a participant who failed this many checks or more (null: report only)"""


def answer_labels_of(p: "Protocol") -> list[str]:
    """The buttons of one answer: the Likert labels, or the screen positions' names (:func:`position_labels_of`).

    >>> answer_labels_of(load_protocol("protocols/exp2_com_vs_average.yaml"))
    ['Left', 'Right']
    """
    return list(p.response.labels) if p.response.type == "likert" else position_labels_of(p)


def position_labels_of(p: "Protocol") -> list[str]:
    """What the choices of a forced choice / ranking are called: the display's labels, else Left/Right for
    two, A, B, … for more; none without an alternatives factor.

    >>> position_labels_of(load_protocol("protocols/thesis_pointlight.yaml"))
    ['A', 'B', 'C', 'D', 'E', 'F']
    """
    alternatives = p.factors_with_role("alternatives")
    if not alternatives:
        return []
    if p.display.labels:
        return list(p.display.labels)
    k = len(alternatives[0].levels)
    return ["Left", "Right"] if k == 2 else [chr(ord("A") + i) for i in range(k)]


class Analysis(Strict):
    """The analysis of the answers: the dependent measure, alpha and the post-hoc tests."""

    dependent_measure: Literal["mean_rating", "percent_chosen", "votes", "rank_points"]
    """mean_rating (likert), percent_chosen or votes (afc), rank_points (ranking)"""
    alpha: float = Field(default=0.05, gt=0, lt=1)
    """significance level of the tests (0–1)"""
    posthoc: Literal["tukey", "none"] = "tukey"
    """pairwise comparisons of the significant effects: tukey or none"""
    # how the post-hoc pairs are tested (analysis.posthoc; None = its defaults: univariate, tukey, emmeans means)
    followup: Literal["univariate", "multivariate", "statistica"] | None = None
    """how post-hoc pairs are tested: univariate (default), multivariate or statistica (the paper's convention:
    each effect's own error term)"""
    adjust: Literal["tukey", "holm", "bonferroni", "none"] | None = None
    """p adjustment over each effect's pairs: tukey (default), holm, bonferroni or none"""
    means: Literal["emmeans", "observed"] | None = None
    """marginal means: emmeans (equal weights over groups; default) or observed (n-weighted)"""


class Protocol(Strict):
    """A whole experiment. See ``protocols/*.yaml`` for annotated examples."""

    name: str
    """the experiment's name: one line without control characters (written into survey syntax and matched by the
    response import)"""
    title: str = ""
    """a human-readable title"""
    seed: int = Field(ge=0, strict=True)
    """seed of every random choice (a whole number ≥ 0): the same seed gives the same design"""
    participants: int = Field(ge=1, le=100_000, strict=True)
    """number of participants; a multiple of the number of between groups"""
    actors: list[Actor] = []
    """the people whose bodies and motions the stimuli show"""
    factors: list[Factor] = Field(min_length=1)
    """the independent variables (at least one)"""
    gaits: dict[str, GaitSpec] = {}
    """cadence and belt speed per gait (walk, jog, run)"""
    display: Display
    """how a stimulus is shown"""
    alternatives: Alternatives = Alternatives()
    """counterbalancing of the alternatives' screen positions"""
    clip: ClipSettings
    """length and look of every clip"""
    blocks: Blocks = Blocks()
    """blocks and the order of blocks and trials"""
    repetitions: int = Field(default=1, ge=1, le=20, strict=True)
    """times each test clip is shown in its block (1–20)"""
    practice: Practice = Practice()
    """practice trials before each block"""
    familiarization: Familiarization = Familiarization()
    """the bodies shown one by one before each block"""
    response: Response
    """what the participant answers"""
    assignment: Assignment = Assignment()
    """how participants are assigned to groups and orders"""
    analysis: Analysis
    """the analysis of the answers"""
    consent: str = ""
    """consent text shown before the study"""
    source: str = ""
    """where the design comes from (paper, section, table)"""
    recruitment: Recruitment | None = None   # shapemotion serve's platform hand-off; None: none
    """optional: hand-off to a recruitment platform (shapemotion serve)"""
    attention_checks: AttentionChecks | None = None   # instructed-response checks (every export); None: none
    """optional: instructed-response checks between test trials (jsPsych export)"""

    @field_validator("name")
    @classmethod
    def _one_line_name(cls, value: str) -> str:
        # The name is written verbatim into survey syntax (Qualtrics' [[ED:…]] line) and matched by the
        # response import: a line break or control character would split or inject lines there.
        if not value.strip() or any(ord(c) < 32 or ord(c) == 127 for c in value):
            raise ValueError(f"name {shown(value)} must be one line of text without control characters")
        return value
    _folder: Path | None = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _consistent(self) -> "Protocol":
        check_consistency(self)
        return self

    @property
    def folder(self) -> Path:
        """Where relative file paths in the protocol's settings start: the protocol file's folder
        (:func:`load_protocol`), or the working directory for a protocol parsed from text."""
        return self._folder or Path.cwd()

    # -- look-ups -------------------------------------------------------------------------------
    def factor(self, name: str) -> Factor:
        for factor in self.factors:
            if factor.name == name:
                return factor
        raise KeyError(name)

    def factors_with_role(self, role: str) -> list[Factor]:
        return [f for f in self.factors if f.role == role]

    def factor_mapped_to(self, maps_to: str) -> Factor | None:
        return next((f for f in self.factors if f.maps_to == maps_to), None)

    def actor(self, sex: str | None, label: str) -> Actor:
        """The actor with this label (and sex, when the protocol has a SEX-like factor)."""
        matches = [a for a in self.actors if a.label == label and (sex is None or a.sex == sex)]
        if len(matches) != 1:
            raise KeyError(f"{sex}/{label}")
        return matches[0]

    def to_json_dict(self) -> dict:
        data = json.loads(self.model_dump_json())
        if self.blocks.trials == "random":   # the default: left out, so that designs written before
            del data["blocks"]["trials"]     # blocks.trials existed stay byte-identical
        if not self.blocks.nested:           # likewise for blocks.nested
            del data["blocks"]["nested"]
        for key in ("floor", "label_position", "label_colour"):   # and the display's later settings
            if getattr(self.display, key) is None:
                del data["display"][key]
        for key in ("followup", "adjust", "means"):               # and the post-hoc settings
            if getattr(self.analysis, key) is None:
                del data["analysis"][key]
        if self.recruitment is None:                              # and the serve hand-off
            del data["recruitment"]
        if self.attention_checks is None:                         # and the attention checks
            del data["attention_checks"]
        return data


def check_consistency(p: Protocol) -> None:
    """Cross-field rules pydantic cannot express per field. Raises ValueError naming the field."""
    names = [f.name for f in p.factors]
    if len(set(names)) != len(names):
        raise ValueError(f"factors: names repeat: {shown(names)}")
    ids = [a.id for a in p.actors]
    if len(set(ids)) != len(ids):
        raise ValueError(f"actors: ids repeat: {sorted(i for i in ids if ids.count(i) > 1)}")
    alternatives = p.factors_with_role("alternatives")
    if len(alternatives) > 1:
        raise ValueError("factors: at most one factor may have role 'alternatives'")
    if alternatives and p.display.layout == "treadmill":
        raise ValueError("display.layout: 'treadmill' shows one clip; an 'alternatives' factor needs side_by_side or row")
    if alternatives and p.display.layout == "side_by_side" and len(alternatives[0].levels) != 2:
        raise ValueError(f"display.layout: side_by_side shows 2 clips but {alternatives[0].name} has "
                         f"{len(alternatives[0].levels)} levels; use layout 'row'")
    if p.response.type == "afc" and not alternatives:
        raise ValueError("response.type: 'afc' needs a factor with role 'alternatives' (the choices)")
    if p.response.type == "ranking" and not alternatives:
        raise ValueError("response.type: 'ranking' needs a factor with role 'alternatives' (what is ranked)")
    _check_design_size(p)
    _check_actor_labels(p)
    _check_actor_motions(p)
    _check_arrangement_ids(p)
    for name in p.blocks.by:
        if name not in names:
            raise ValueError(f"blocks.by: unknown factor {shown(name)} (factors: {shown(names)})")
        if p.factor(name).role != "within":
            raise ValueError(f"blocks.by: {name} is a {p.factor(name).role} factor; blocks must be within factors")
    if p.blocks.nested and len(p.blocks.by) < 2:
        raise ValueError(f"blocks.nested: nested: true needs at least two factors in blocks.by (the first makes "
                         f"the main blocks, the others the sub-blocks inside each), got blocks.by: "
                         f"[{', '.join(p.blocks.by)}]; add a factor to blocks.by or remove nested")
    _check_trial_order(p)
    _check_alternatives_motion(p)
    _check_measure(p)
    _check_clip_timing(p)
    _check_practice(p, names)
    _check_screen_mapping(p)
    _check_attention_answer(p)
    if p.practice.per_block:
        _check_practice_pool(p)
    between_cells = 1
    for f in p.factors_with_role("between"):
        between_cells *= len(f.levels)
    if p.participants % between_cells:
        raise ValueError(
            f"participants: {p.participants} participants cannot be balanced over {between_cells} between-subject "
            f"groups; use a multiple of {between_cells}")


def _check_attention_answer(p: Protocol) -> None:
    """The answer an attention check asks for must be one of its buttons (matched as the import matches
    labels: ignoring case and spacing), or no participant could pass it."""
    checks = p.attention_checks
    if checks is None:
        return
    labels = answer_labels_of(p)
    key = " ".join(checks.answer.split()).casefold()
    if key not in {" ".join(label.split()).casefold() for label in labels}:
        raise ValueError(f"attention_checks.answer: {shown(checks.answer)} is not one of the answer buttons "
                         f"{shown(labels)}; ask for one of them")


def _check_design_size(p: Protocol) -> None:
    """The design a protocol makes must fit :data:`MAX_STIMULI` test clips and :data:`MAX_TRIALS` test
    trials, counted without making them: ten alternatives with ``arrangements: all`` (10! screen
    orders) made a 3 KB protocol run ``validate`` past a minute and gigabytes."""
    alternatives = p.factors_with_role("alternatives")
    k = len(alternatives[0].levels) if alternatives else 0
    kind = p.alternatives.arrangements
    orders = 1 if not alternatives or kind == "fixed" else k if kind == "latin_square" and k > 2 else math.factorial(k)
    stimuli = math.prod(len(f.levels) for f in p.factors if f.role != "alternatives") * orders
    if stimuli > MAX_STIMULI:
        crossing = " × ".join(f"{f.name} {len(f.levels):,}" for f in p.factors if f.role != "alternatives")
        shown_orders = f" × {_count_text(orders)} screen orders of {alternatives[0].name}" if orders > 1 else ""
        hint = (f"; arrangements: latin_square shows each of the {k} levels once in each position in {k} orders"
                if kind == "all" and k > 2 else "")
        raise ValueError(f"factors: the design makes {_count_text(stimuli)} test clips ({crossing}{shown_orders}); "
                         f"a protocol may make at most {MAX_STIMULI:,}{hint}")
    check_trial_count(p, p.participants, "participants")


def check_trial_count(p: Protocol, participants: int, field: str) -> None:
    """``participants`` × the test trials each sees must fit :data:`MAX_TRIALS` (also run on
    ``design --participants``, which overrides the protocol's number).

    >>> check_trial_count(load_protocol("protocols/exp1_shape_motion.yaml"), 10**6, "--participants")
    Traceback (most recent call last):
    ...
    ValueError: --participants: 1,000,000 participants × 64 test trials each make 64,000,000 rows of trials.csv; a protocol may make at most 1,000,000
    """
    per_participant = math.prod(len(f.levels) for f in p.factors_with_role("within")) * p.repetitions
    alternatives = p.factors_with_role("alternatives")
    if alternatives and p.alternatives.counterbalance == "within":
        k, kind = len(alternatives[0].levels), p.alternatives.arrangements
        per_participant *= 1 if kind == "fixed" else k if kind == "latin_square" and k > 2 else math.factorial(k)
    if per_participant * participants > MAX_TRIALS:
        raise ValueError(f"{field}: {participants:,} participants × {_count_text(per_participant)} test trials each "
                         f"make {_count_text(per_participant * participants)} rows of trials.csv; a protocol may "
                         f"make at most {MAX_TRIALS:,}")


def _check_actor_motions(p: Protocol) -> None:
    """An actor's captures are for the protocol's gaits (the gait's cadence and speed are needed
    for the generated actors it is shown beside)."""
    for a in p.actors:
        unknown = sorted(set(a.motions) - set(p.gaits))
        if unknown:
            raise ValueError(f"actors.{a.id}.motions.{unknown[0]}: actor {a.id} names a capture for gait "
                             f"{shown(unknown[0])}, which is not declared under gaits (declared: "
                             f"{', '.join(p.gaits) or 'none'})")
        other = sorted(set(a.motions) - set(CAPTURE_GAITS))
        if other:
            raise ValueError(f"actors.{a.id}.motions.{other[0]}: actor {a.id}: a capture's gait must be one of "
                             f"{', '.join(CAPTURE_GAITS)} (the gaits a loop is found for), got {shown(other[0])}")


def _count_text(count: int) -> str:
    """A count for a message: digits while readable, else its order of magnitude (20,000! has 77,338 digits)."""
    return f"{count:,}" if count < 10**15 else f"about 10^{len(str(count)) - 1}"


def _check_actor_labels(p: Protocol) -> None:
    """A BODY or MOTION level names an actor by label, and by sex when a factor maps to sex: two actors
    one level would name left the design to fail on a look-up (``KeyError: 'F/Hi1'``)."""
    if p.factor_mapped_to("body") is None and p.factor_mapped_to("motion") is None:
        return
    by_sex = p.factor_mapped_to("sex") is not None
    seen: dict[tuple, int] = {}
    for index, actor in enumerate(p.actors):
        key = (actor.sex if by_sex else None, actor.label)
        if key in seen:
            first = p.actors[seen[key]].id
            what = (f"are both sex {actor.sex} with label {actor.label!r}; a level names one actor of each sex"
                    if by_sex else f"share label {actor.label!r} and no factor maps to sex, so a level names one "
                    "actor whatever the sex")
            raise ValueError(f"actors.{index}.label: {first} and {actor.id} {what}: give each its own label")
        seen[key] = index


def _check_arrangement_ids(p: Protocol) -> None:
    """Screen orders of the alternatives are joined by ``_`` into stimulus ids: levels that hold ``_``
    (or ``-``) could make two orders one id (``a``, ``b_c`` and ``a_b``, ``c``)."""
    alternatives = p.factors_with_role("alternatives")
    if not alternatives or not any(set("_-") & set(level) for level in alternatives[0].levels):
        return
    from stimuli.design import _safe
    from stimuli.orders import arrangements

    seen: dict[str, tuple[str, ...]] = {}
    for arrangement in arrangements(p):
        text = "_".join(_safe(level) for level in arrangement)
        if text in seen:
            raise ValueError(f"factors.{alternatives[0].name}.levels: the screen orders {' '.join(seen[text])} and "
                             f"{' '.join(arrangement)} make the same stimulus id part {text!r}; rename levels so "
                             "that they hold no '_' or '-'")
        seen[text] = tuple(arrangement)


def _check_practice(p: Protocol, names: list[str]) -> None:
    """practice.levels, whatever per_block is: practice-only levels of within factors that do not
    define blocks (a practice trial keeps its block's and between group's levels, so practice levels
    of those factors would make clips no block shows), each list non-empty and without repeats."""
    for name, levels in p.practice.levels.items():
        where = f"practice.levels.{name}"
        if name not in names:
            raise ValueError(f"practice.levels: unknown factor {shown(name)} (factors: {shown(names)})")
        factor = p.factor(name)
        if factor.role != "within" or name in p.blocks.by:
            what = ("defines the blocks (blocks.by)" if factor.role == "within"
                    else f"is an {factor.role} factor" if factor.role == "alternatives"
                    else f"is a {factor.role} factor")
            raise ValueError(f"{where}: {name} {what}; practice levels are for within factors that do not define "
                             "blocks (practice trials keep the levels of their block, their between group and "
                             f"every alternative shown side by side); leave {name} out of practice.levels")
        if not levels:
            raise ValueError(f"{where}: the list is empty; give one or more practice-only levels of {name}, or "
                             f"leave {name} out of practice.levels")
        repeated = sorted({level for level in levels if levels.count(level) > 1})
        if repeated:
            raise ValueError(f"{where}: levels repeat: {shown(repeated)} (each practice level is one set of clips)")
        unsafe = [level for level in levels if not SAFE_ID.fullmatch(level)]
        if unsafe:
            raise ValueError(f"{where}: level {shown(unsafe[0])} must use letters, digits, '_', '-', '.' or '+'")
        for level in levels:
            try:
                _check_name_length(level)
            except ValueError as exc:
                raise ValueError(f"{where}: {exc}") from None
        clash = sorted(set(levels) & set(factor.levels))
        if clash:
            raise ValueError(f"{where}: {shown(clash)} are test levels; practice must use other levels")
    if p.practice.per_block and not p.practice.levels:
        raise ValueError("practice.per_block > 0 needs practice.levels (the practice-only levels to show)")


def _check_practice_pool(p: Protocol) -> None:
    """Each block needs enough distinct practice clips for ``per_block`` trials with no clip twice in
    a row: one clip cannot be repeated (it would play back to back), none at all means no practice."""
    from stimuli.design import practice_pool

    wanted, pool = p.practice.per_block, practice_pool(p)
    shown = ", ".join(f"{name}: {', '.join(levels)}" for name, levels in p.practice.levels.items())
    if not pool:  # _check_practice makes this unreachable; kept so that a future rule cannot crash here
        raise ValueError(f"practice.per_block: {wanted} practice trial(s) per block asked for, but no practice clip "
                         f"belongs to any block ({shown})")
    if pool == 1 and wanted > 1:
        raise ValueError(f"practice.per_block: {wanted} practice trials per block asked for, but each block has only "
                         f"1 distinct practice clip ({shown}), which would play {wanted} times back to back; use "
                         "per_block: 1 or add practice levels (with 2 or more clips a block may repeat them, never "
                         "twice in a row)")


def _test_clips_per_block(p: Protocol) -> int:
    """Distinct test clips one participant sees in one block: the crossing of the within factors that
    do not define blocks, times the screen arrangements when every participant sees every one."""
    count = 1
    for f in p.factors_with_role("within"):
        if f.name not in p.blocks.by:
            count *= len(f.levels)
    alternatives = p.factors_with_role("alternatives")
    if alternatives and p.alternatives.counterbalance == "within":
        from stimuli.orders import arrangements

        count *= len(arrangements(p))
    return count


def _check_trial_order(p: Protocol) -> None:
    """``blocks.trials: fixed`` shows a block's test clips in declared order, the whole sequence once
    per repetition: a block of one clip would play it back to back, which a fixed order cannot avoid."""
    if p.blocks.trials != "fixed" or p.repetitions == 1:
        return
    clips = _test_clips_per_block(p)
    if clips == 1:
        more = " (fewer factors in blocks.by)" if p.blocks.by else ""
        raise ValueError(f"blocks.trials: fixed shows a block's test clips in the declared order once per repetition, "
                         f"but each block shows a participant only 1 test clip, which would play {p.repetitions} "
                         f"times back to back (repetitions: {p.repetitions}); use repetitions: 1, or give each "
                         f"block more than one test clip{more}")


def _check_alternatives_motion(p: Protocol) -> None:
    """The levels of an alternatives factor are the motions shown side by side: the renderer makes
    them only for some mappings, so any other would pass here and fail on every clip."""
    for index, f in enumerate(p.factors):
        if f.role == "alternatives" and f.maps_to not in ALTERNATIVE_MOTIONS:
            hint = f" (to compare {f.maps_to} levels, make {f.name} a within factor)" if f.maps_to != "none" else ""
            raise ValueError(f"factors.{index}.maps_to: {f.name} is an alternatives factor, whose levels are motions "
                             f"shown side by side; the renderer makes those for maps_to "
                             f"{', '.join(ALTERNATIVE_MOTIONS)} only, got {f.maps_to!r}{hint}")
        if f.role == "alternatives":
            _check_distinct_motions(f, index)


def method_motion_of(factor: Factor, level: str) -> str:
    """What a METHOD level shows (``average`` or ``physics``): its ``level_settings.<level>.motion``,
    or, with no setting, by its name: NoCOM = the average motion, any other name = physics (COM).

    >>> from stimuli.protocol import Factor
    >>> f = Factor(name="METHOD", role="alternatives", levels=["Avg", "COM"], maps_to="method",
    ...            level_settings={"Avg": {"motion": "average"}})
    >>> method_motion_of(f, "Avg"), method_motion_of(f, "COM")
    ('average', 'physics')
    """
    setting = factor.level_settings.get(level, {}).get("motion")
    if setting is not None:
        return str(setting)
    return "average" if level == "NoCOM" else "physics"


def _motion_source(factor: Factor, level: str) -> str | None:
    """The motion an alternatives level resolves to (None: not known before the render)."""
    if factor.maps_to == "method":
        return method_motion_of(factor, level)
    if factor.maps_to == "strength":
        return f"body fat {float(level):g} %"
    spec = factor.level_settings.get(level, {}).get("motion")   # "source": its setting, if any
    if isinstance(spec, str) and spec.startswith("bvh:"):
        return "bvh:" + str(Path(spec[4:].strip()).expanduser())
    return spec


def _check_distinct_motions(f: Factor, index: int) -> None:
    """Alternatives shown side by side must differ: two levels with the same motion would show the
    same clip twice and make the choice meaningless."""
    seen: dict[str, str] = {}
    for level in f.levels:
        source = _motion_source(f, level)
        if source is None:
            continue
        if source in seen:
            how = ("(level_settings.<level>.motion, or by name: NoCOM = average, any other name = physics)"
                   if f.maps_to == "method" else "")
            field = (f"factors.{index}.level_settings.{level}.motion" if "motion" in f.level_settings.get(level, {})
                     else f"factors.{index}.levels")
            raise ValueError(f"{field}: {f.name} levels {seen[source]!r} and {level!r} both "
                             f"show the {source} motion{' ' + how if how else ''}; the alternatives shown side by "
                             "side must differ")
        seen[source] = level


def _check_measure(p: Protocol) -> None:
    """The analysis reads the answers of one response type only (analysis.io_design)."""
    allowed = MEASURES_OF_RESPONSE[p.response.type]
    if p.analysis.dependent_measure not in allowed:
        raise ValueError(f"analysis.dependent_measure: {p.analysis.dependent_measure} does not fit response.type "
                         f"{p.response.type}; expected {' or '.join(allowed)}")


def _check_clip_timing(p: Protocol) -> None:
    """A looping clip shows whole gait cycles: at least one of every declared gait (shorter clips
    would play the gait many times too fast), and at least ``clip.cycles``."""
    if not p.gaits:
        return  # motions from captures keep their own cadence (stimuli.render.timing)
    from stimuli.render.timing import TOLERANCE, protocol_fits, seconds_text

    fits = protocol_fits(p)
    slowest = min(fits, key=lambda fit: fit.cadence_spm)
    cycle_s = 120.0 / slowest.cadence_spm
    if not p.clip.loop:   # the exact cadence, cut at the end: only the cycles shown can fall short
        if slowest.shown_cycles * (1 + TOLERANCE) < p.clip.cycles:
            lower = " or lower clip.cycles" if p.clip.cycles > 1 else ""   # 1 is the fewest
            field = "clip.cycles" if p.clip.cycles > 1 else "clip.duration_s"
            raise ValueError(f"{field}: the {p.clip.duration_s:g} s clip shows {slowest.shown_cycles:.2f} cycles of "
                             f"{slowest.gait} ({slowest.cadence_spm:g} steps/min), fewer than {p.clip.cycles}; use "
                             f"duration_s >= {seconds_text(p.clip.cycles * cycle_s, p.clip.fps)} s{lower}")
        return
    if slowest.clip_s * (1 + TOLERANCE) < cycle_s:
        shortest = math.ceil(cycle_s / (1 + TOLERANCE) * p.clip.fps) / p.clip.fps
        raise ValueError(f"clip.duration_s: {p.clip.duration_s:g} s is shorter than one gait cycle of "
                         f"{slowest.gait} ({slowest.cadence_spm:g} steps/min: {cycle_s:.2f} s per cycle of two "
                         f"steps), so the clip would play it at {slowest.effective_cadence_spm:.0f} steps/min; a "
                         f"looping clip shows at least one whole cycle of every gait: use duration_s >= "
                         f"{seconds_text(shortest, p.clip.fps)} s (within {TOLERANCE:.0%})")
    short = [fit for fit in fits if fit.cycles < p.clip.cycles]
    if short:
        needed = p.clip.cycles * cycle_s
        shown = ", ".join(f"{fit.gait} ({fit.cadence_spm:g} steps/min) {fit.cycles}" for fit in short)
        raise ValueError(f"clip.cycles: every gait must show at least {p.clip.cycles} whole cycles, but the "
                         f"{p.clip.duration_s:g} s clip shows {shown}; use duration_s >= "
                         f"{seconds_text(needed, p.clip.fps)} s ({p.clip.cycles} cycles of {slowest.gait}) or "
                         "lower clip.cycles")


def _check_screen_mapping(p: Protocol) -> None:
    """Levels that name actors or gaits must exist, so that every stimulus can be made."""
    if p.display.body is not None and p.display.body not in {a.id for a in p.actors}:
        raise ValueError(f"display.body: {shown(p.display.body)} is not an actor id (actors: "
                         f"{shown([a.id for a in p.actors])})")
    if p.display.body is None and p.factor_mapped_to("body") is None:
        raise ValueError("display.body: no factor maps to body, so display.body must name the actor whose body is shown")
    labels = p.display.labels
    alternatives = p.factors_with_role("alternatives")
    if labels is not None and alternatives and len(labels) != len(alternatives[0].levels):
        raise ValueError(f"display.labels: {len(labels)} labels for {len(alternatives[0].levels)} alternatives "
                         f"of {alternatives[0].name}")
    sex_factor = p.factor_mapped_to("sex")
    sexes = sex_factor.levels if sex_factor else [None]
    for f in p.factors:
        practice = p.practice.levels.get(f.name, [])
        if f.maps_to in ("body", "motion"):
            for sex in sexes:
                for level in f.levels + practice:
                    if not any(a.label == level and (sex is None or a.sex == sex) for a in p.actors):
                        who = f"sex {sex}, " if sex else ""
                        raise ValueError(f"factors.{f.name}: level {level!r} names no actor ({who}label {level!r}); "
                                         f"declare it under actors")
        if f.maps_to == "sex":
            bad = sorted(set(f.levels + practice) - {"F", "M"})
            if bad:
                raise ValueError(f"factors.{f.name}: sex levels must be F or M, got {shown(bad)}")
        if f.maps_to == "parameter" and p.factor_mapped_to("strength") is not None:
            # The renderer exaggerates, per parameter level, the Table 4-1/5-2 rows its setting names.
            bare = [level for level in f.levels if not f.level_settings.get(level, {}).get("modifies")]
            if bare:
                raise ValueError(f"factors.{f.name}: levels {shown(bare)} need level_settings.<level>.modifies: Table "
                                 "4-1/5-2 rows joined by '+' (e.g. \"arm_abduction+arm_bob\")")
        if f.maps_to == "gait":
            missing = sorted(set(f.levels + practice) - set(p.gaits))
            if missing:
                raise ValueError(f"factors.{f.name}: gait levels {shown(missing)} are not declared under gaits")


# -- loading ------------------------------------------------------------------------------------

# Limits on what the loader reads, so that no file can take minutes or gigabytes (issue 26: a 4 KB
# 'billion laughs' file ran past 120 s at 5.7 GB). The bundled protocols are 2–4 KB, under 300 nodes.
MAX_PROTOCOL_BYTES = MAX_YAML_CHARACTERS  # 1 MiB of file; nodes, nesting and aliases: analysis.io_yaml
MAX_PROBLEMS = 10                         # problems one error paragraph lists; the rest are counted
SHOWN_CHARACTERS = 60                     # a value longer than this is named by its size in messages


def load_protocol(path: str | Path) -> Protocol:
    """Read and validate a protocol file; every problem becomes a :class:`StimuliError`."""
    path = Path(path)
    protocol = parse_protocol(read_protocol_text(path), source=str(path))
    protocol._folder = path.resolve().parent
    return protocol


def read_protocol_text(path: Path) -> str:
    """The text of a protocol file: a regular file (a FIFO would hang the reader, ``/dev/zero`` fill
    memory) of at most :data:`MAX_PROTOCOL_BYTES`, UTF-8.

    >>> len(read_protocol_text(Path("protocols/exp1_shape_motion.yaml"))) > 1000
    True
    """
    try:
        info = path.stat()
        if stat.S_ISDIR(info.st_mode):
            raise StimuliError(f"{path}: is a folder; expected a protocol YAML file")
        if not stat.S_ISREG(info.st_mode):
            raise StimuliError(f"{path}: is not a regular file (a device, pipe or socket); expected a protocol "
                               "YAML file")
        if info.st_size > MAX_PROTOCOL_BYTES:
            raise StimuliError(_too_large(path, info.st_size))
        with path.open("rb") as handle:
            data = handle.read(MAX_PROTOCOL_BYTES + 1)   # + 1: a file that grew since stat() is still caught
    except FileNotFoundError:
        raise StimuliError(f"{path}: protocol file not found") from None
    except OSError as exc:
        raise StimuliError(f"{path}: cannot read the protocol ({exc.strerror or exc})") from None
    if len(data) > MAX_PROTOCOL_BYTES:
        raise StimuliError(_too_large(path, len(data)))
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StimuliError(f"{path}: cannot read the protocol as UTF-8 text ({exc})") from None


def _too_large(source: str | Path, size: int, unit: str = "bytes") -> str:
    return (f"{source}: the protocol is {size:,} {unit}; a protocol file may hold at most "
            f"{MAX_PROTOCOL_BYTES:,} (1 MiB)")


def shown(value, limit: int = SHOWN_CHARACTERS) -> str:
    """A value as messages echo it: its ``repr`` when short, else its size, so that a 1 MB value gives
    a one-line message, not a 1 MB one.

    >>> shown("Hi1"), shown("x" * 1_048_576), shown(list(range(1000)))
    ("'Hi1'", '1,048,576 characters', 'a list of 1,000 items')
    """
    if isinstance(value, str) and len(value) > limit:
        return f"{len(value):,} characters"
    if isinstance(value, (list, tuple, set)) and len(value) > limit:   # repr of a huge list costs time too
        return f"a list of {len(value):,} items"
    text = repr(value)
    if len(text) <= limit:
        return text
    if isinstance(value, dict):
        return f"a mapping of {len(value):,} keys"
    if isinstance(value, (list, tuple, set)):
        return f"a list of {len(value):,} items"
    return f"{len(text):,} characters"


def capture_file(protocol: Protocol, spec: str) -> Path:
    """The file a ``bvh:<path>`` motion setting names; a relative path starts from the protocol's folder."""
    path = Path(spec[len("bvh:"):].strip()).expanduser()
    return path if path.is_absolute() else protocol.folder / path


def actor_capture_file(protocol: Protocol, capture: Capture) -> Path:
    """The file of an actor's capture (``motions.<gait>.file``); a relative path starts from the
    protocol's folder."""
    path = Path(capture.file).expanduser()
    return path if path.is_absolute() else protocol.folder / path


def capture_line(protocol_path: str | Path, actor_id: str, gait: str) -> int | None:
    """The YAML line of ``actors.<actor_id>.motions.<gait>`` in a protocol file (for messages)."""
    text = read_protocol_text(Path(protocol_path))
    return _line_of(read_yaml(text, str(protocol_path))[1], ["actors", actor_id, "motions", gait])


def check_capture_files(protocol: Protocol, path: str | Path) -> None:
    """``motion: "bvh:<path>"`` settings must name files that exist (relative to the protocol's folder).

    Run by ``validate``; loading does not require them, so that a protocol can be prepared (and its
    design written) before the captures are in place. The render names a missing one too.
    """
    path = Path(path)
    text = read_protocol_text(path)
    for f in protocol.factors:
        for level, settings in f.level_settings.items():
            spec = settings.get("motion")
            if not isinstance(spec, str) or not spec.startswith("bvh:"):
                continue
            capture = capture_file(protocol, spec)
            if not capture.is_file():
                index = protocol.factors.index(f)
                line = _line_of(read_yaml(text, str(path))[1], ["factors", index, "level_settings", level, "motion"])
                where = f" (line {line})" if line else ""
                raise StimuliError(f"{path}: invalid protocol: factors.{index}.level_settings.{level}.motion{where}: "
                                   f"{capture} not found (a BVH capture; relative paths start from the protocol's "
                                   f"folder)")


def read_yaml(text: str, source: str = "<protocol>") -> tuple[object, yaml.Node | None]:
    """The data of a protocol's YAML and its node tree (for line numbers), read with the limits of
    :mod:`analysis.io_yaml`; a YAML error becomes a :class:`StimuliError` naming ``source`` and the line.

    >>> read_yaml("name: x")[0]
    {'name': 'x'}
    """
    if len(text) > MAX_PROTOCOL_BYTES:
        raise StimuliError(_too_large(source, len(text), "characters"))
    try:
        return load_bounded(text)
    except yaml.YAMLError as exc:
        raise StimuliError(f"{source}:{yaml_problem(exc, text)}") from None


def parse_protocol(text: str, source: str = "<protocol>") -> Protocol:
    """Validate protocol text (see :func:`load_protocol`); ``source`` names it in messages."""
    data, root = read_yaml(text, source)
    if not isinstance(data, dict):
        raise StimuliError(f"{source}: a protocol must be a YAML mapping (name:, factors:, …), got {type(data).__name__}")
    try:
        return Protocol.model_validate(data)
    except ValidationError as exc:
        raise StimuliError(describe_validation_error(exc, source, root)) from None


def describe_validation_error(exc: ValidationError, source: str, root) -> str:
    """One paragraph: every problem as 'field (line N): message', fields in dotted form; long values
    named by their size (:func:`shown`), at most :data:`MAX_PROBLEMS` problems and a count of the rest."""
    parts = []
    errors = exc.errors(include_url=False, include_context=False)
    for err in errors[:MAX_PROBLEMS]:
        loc = list(err["loc"])
        message = err["msg"].removeprefix("Value error, ")
        named = re.match(r"^([A-Za-z_][\w.]*): (.*)$", message, re.S)
        if named:  # a rule names its own field, relative to where it runs: "blocks.by: …", "labels.1: …"
            loc += [int(x) if x.isdigit() else x for x in named.group(1).split(".")]
            message = named.group(2)
        field = ".".join(_key_text(x) for x in loc) if loc else "(top level)"
        line = _line_of(root, loc)
        where = f" (line {line})" if line else ""
        if len(loc) > 3 and loc[0] == "actors" and loc[2] == "motions":   # a capture: whose, of which gait
            where = f" ({'line ' + str(line) + '; ' if line else ''}actor {_actor_id(root, loc[1])}, gait {loc[3]})"
        if err["type"] == "extra_forbidden":
            known = ", ".join(_known_fields(loc[:-1]))
            message = f"unknown field (check the spelling; the known fields here: {known})"
        elif err["type"] == "missing":
            message = "required field is missing"
        elif "input" in err and err["type"] not in ("value_error",):
            message += f" (got {shown(err['input'])})"
            if err["type"] in ("int_type", "bool_type"):  # strict fields: no true for 1, no "2", no 0 for false
                message += ("; write a whole number without quotes" if err["type"] == "int_type"
                            else "; write true or false without quotes")
        parts.append(f"{field}{where}: {message}")
    if len(errors) > MAX_PROBLEMS:
        parts.append(f"and {len(errors) - MAX_PROBLEMS:,} more problems")
    return f"{source}: invalid protocol: " + "; ".join(parts)


def _actor_id(root, index) -> str:
    """The ``id`` of the actor at ``index`` in the YAML (for messages about its fields), else its index."""
    actors = next((v for k, v in getattr(root, "value", []) if getattr(k, "value", None) == "actors"), None)
    if isinstance(actors, yaml.SequenceNode) and isinstance(index, int) and index < len(actors.value):
        item = actors.value[index]
        if isinstance(item, yaml.MappingNode):
            return next((str(v.value) for k, v in item.value if getattr(k, "value", None) == "id"
                         and isinstance(v, yaml.ScalarNode)), str(index))
    return str(index)


def _key_text(key) -> str:
    """A key of an error location as the field name shows it; a long one (a 1 MB key) by its size."""
    text = str(key)
    return text if len(text) <= SHOWN_CHARACTERS else f"<a key of {len(text):,} characters>"


def _known_fields(loc) -> list[str]:
    """The field names of the protocol model that holds location ``loc`` (e.g. ``["clip"]`` → the
    clip settings' fields), following lists and mappings of models."""
    model = Protocol
    for key in loc:
        annotation = model.model_fields[str(key)].annotation if str(key) in model.model_fields else model
        while typing.get_origin(annotation) in (list, dict, typing.Union, types.UnionType):
            annotation = next(a for a in reversed(typing.get_args(annotation)) if a is not type(None))
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            model = annotation
    return list(model.model_fields)


def _line_of(root, loc) -> int | None:
    """The 1-based YAML line of a pydantic error location, following the composed node tree; a name in
    a list (``factors.BODY``) is the item whose ``name`` (or ``id``) it is."""
    node, line = root, None
    for key in loc:
        if isinstance(node, yaml.MappingNode):
            child = next(((k, v) for k, v in node.value if k.value == str(key)), None)
            if child is None:
                break
            node = child[1]
            line = child[0].start_mark.line + 1
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, int) and key < len(node.value):
            node = node.value[key]
            line = node.start_mark.line + 1
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, str) and _item_named(node, key) is not None:
            node = _item_named(node, key)
            line = node.start_mark.line + 1
        else:
            break
    if line is None and node is not None and node is not root:
        line = node.start_mark.line + 1
    return line


def _item_named(sequence: yaml.SequenceNode, name: str) -> yaml.Node | None:
    """The mapping in ``sequence`` whose ``name`` or ``id`` is ``name`` (factors by name, actors by id)."""
    for item in sequence.value:
        if isinstance(item, yaml.MappingNode) and any(
                isinstance(k, yaml.ScalarNode) and k.value in ("name", "id") and getattr(v, "value", None) == name
                for k, v in item.value):
            return item
    return None
