"""Generated bad protocols (issue 26): mutations of the bundled protocols fed to ``shapemotion validate``
in-process. Whatever the mutation, the command ends with exit 0 (a clean load and design) or exit 2 and
one short paragraph naming the file — never a traceback, never another exit code.

Hypothesis runs derandomized (the same cases on every run, so the suite cannot fail by chance) and
without its example database (nothing written into the checkout). The 350 generated cases and the
1,116 exhaustive ones run in about 15 s.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from stimuli.cli import main
from stimuli.design import build_design
from stimuli.errors import StimuliError
from stimuli.protocol import Protocol, describe_validation_error

PROTOCOLS = sorted((Path(__file__).resolve().parents[1] / "protocols").glob("*.yaml"))
TEXTS = {path.stem: path.read_text() for path in PROTOCOLS}
DATA = {name: yaml.safe_load(text) for name, text in TEXTS.items()}
LONGEST_MESSAGE = 4_000   # ten problems with their fields, lines and short values fit in well under this

FUZZ = settings(max_examples=150, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def validate(text: str, folder: Path) -> tuple[int, str]:
    """``shapemotion validate`` on ``text`` in-process: (exit code, stderr)."""
    path = folder / "fuzzed.yaml"
    path.write_text(text, encoding="utf-8")
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["validate", str(path)])
    return code, err.getvalue()


def assert_clean_outcome(text: str, folder: Path) -> None:
    code, err = validate(text, folder)
    assert code in (0, 2), (code, err[-2000:])
    if code == 2:
        assert err.startswith("shapemotion: error:") and "Traceback" not in err, err[-2000:]
        assert "fuzzed.yaml" in err
        assert len(err) < LONGEST_MESSAGE, err[:2000]


def paths_of(data, prefix=()) -> list[tuple]:
    """Every place in a parsed protocol: mapping keys and list items, nested."""
    found = [prefix] if prefix else []
    if isinstance(data, dict):
        for key, value in data.items():
            found += paths_of(value, prefix + (key,))
    elif isinstance(data, list):
        for index, value in enumerate(data):
            found += paths_of(value, prefix + (index,))
    return found


def parent_and_key(data, path):
    for key in path[:-1]:
        data = data[key]
    return data, path[-1]


HUGE_TEXT = st.sampled_from([1_000, 70_000, 400_000]).map(lambda n: "x" * n)
SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=30), HUGE_TEXT)
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                      st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                      max_leaves=8)


@st.composite
def mutated_data(draw):
    """A bundled protocol with one or two changes to its parsed data: a value replaced by any other
    (wrong types, huge strings, NaN), a key deleted, a list item repeated, two labels made equal."""
    name = draw(st.sampled_from(sorted(DATA)))
    data = copy.deepcopy(DATA[name])
    for _ in range(draw(st.integers(1, 2))):
        places = paths_of(data)
        path = draw(st.sampled_from(places))
        parent, key = parent_and_key(data, path)
        kind = draw(st.sampled_from(["replace", "replace", "delete", "repeat", "same_labels"]))
        if kind == "replace":
            parent[key] = draw(VALUES)
        elif kind == "delete":
            del parent[key]
        elif kind == "repeat" and isinstance(parent, list):
            parent.insert(key, copy.deepcopy(parent[key]))
        elif kind == "same_labels":
            labels = [p for p in places if len(p) == 3 and p[1] in ("labels", "abbreviations", "levels")
                      or len(p) == 3 and p[0] == "actors" and p[2] == "label"]
            if len(labels) >= 2:
                first, second = draw(st.lists(st.sampled_from(labels), min_size=2, max_size=2, unique=True))
                (a, ka), (b, kb) = parent_and_key(data, first), parent_and_key(data, second)
                b[kb] = draw(st.sampled_from([a[ka], f" {a[ka]} ", str(a[ka]).upper(), "", "  "]))
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=math.inf)


def bomb(depth: int, fanout: int) -> str:
    value = "&a0 [lol, lol, lol]"
    for i in range(1, depth):
        value = f"[{value}, &a{i} [{', '.join([f'*a{i - 1}'] * fanout)}]]"
    return value


@st.composite
def mutated_text(draw):
    """A bundled protocol's text broken as a file can be: cut short, a character inserted or removed, a
    line repeated, a value turned into an alias bomb, a recursive alias or deep nesting, or random text."""
    name = draw(st.sampled_from(sorted(TEXTS)))
    text = TEXTS[name]
    lines = text.splitlines(keepends=True)
    kind = draw(st.sampled_from(["cut", "insert", "remove", "repeat_line", "alias", "random"]))
    if kind == "cut":
        return text[:draw(st.integers(0, len(text)))]
    if kind == "insert":
        at = draw(st.integers(0, len(text)))
        return text[:at] + draw(st.sampled_from(list("[]{}:-&*!|>'\"#%@`,?\t\n\x00")) | st.text(max_size=3)) + text[at:]
    if kind == "remove":
        at = draw(st.integers(0, len(text) - 1))
        return text[:at] + text[at + 1:]
    if kind == "repeat_line":
        at = draw(st.integers(0, len(lines) - 1))
        return "".join(lines[:at + 1] + [lines[at]] + lines[at + 1:])
    if kind == "alias":
        value = draw(st.sampled_from([bomb(draw(st.integers(2, 12)), draw(st.integers(2, 12))), "&me [*me]",
                                      "*undefined", "&x " + "[" * 200 + "]" * 200]))
        at = draw(st.sampled_from([i for i, line in enumerate(lines) if line.startswith(("title:", "seed:", "name:"))]))
        key = lines[at].split(":")[0]
        return "".join(lines[:at] + [f"{key}: {value}\n"] + lines[at + 1:])
    return draw(st.text(max_size=200))


@FUZZ
@given(text=mutated_data())
def test_mutated_protocol_data_loads_or_is_refused_cleanly(text, tmp_path_factory):
    assert_clean_outcome(text, tmp_path_factory.mktemp("fuzz"))


@FUZZ
@given(text=mutated_text())
def test_mutated_protocol_text_loads_or_is_refused_cleanly(text, tmp_path_factory):
    assert_clean_outcome(text, tmp_path_factory.mktemp("fuzz"))


@settings(max_examples=50, deadline=None, derandomize=True, database=None)
@given(labels=st.lists(st.sampled_from(["Agree", "agree", " Agree ", "Disagree", "", " ", "Neutral"]),
                       min_size=2, max_size=6))
def test_likert_labels_load_only_when_they_tell_answers_apart(labels, tmp_path_factory):
    """Exit 0 exactly when no label is blank and none repeats ignoring case and spacing."""
    data = copy.deepcopy(DATA["exp1_shape_motion"])
    data["response"]["labels"] = labels
    code, err = validate(yaml.safe_dump(data, sort_keys=False), tmp_path_factory.mktemp("labels"))
    keys = [" ".join(label.split()).casefold() for label in labels]
    distinct = all(keys) and len(set(keys)) == len(keys)
    assert code == (0 if distinct else 2), err
    if not distinct:
        assert "response.labels." in err


# Wrong types a hand-edited file can hold; each replaces every value, list and mapping of a protocol in
# turn (the random cases above met 'practice.levels.BODY: 5', a TypeError traceback, only once in 11,000).
WRONG_TYPES = [None, 2.5, True, "x", [], {"x": 1}]


def test_every_place_replaced_by_a_wrong_type():
    """Exhaustive over exp2 (the protocol with most kinds of fields): every place × 6 wrong types,
    validated from the data (the YAML reading is the generated cases' part; pure-Python YAML would take
    10 ms a case): a ValidationError with a short description, or a protocol whose design builds."""
    data = DATA["exp2_com_vs_average"]
    cases = 0
    for path in paths_of(data):
        for value in WRONG_TYPES:
            changed = copy.deepcopy(data)
            parent, key = parent_and_key(changed, path)
            parent[key] = value
            try:
                build_design(Protocol.model_validate(changed))
            except ValidationError as exc:
                message = describe_validation_error(exc, "fuzzed.yaml", None)
                assert len(message) < LONGEST_MESSAGE, (path, value, message)
            except StimuliError as exc:   # a check of the design itself
                assert len(str(exc)) < LONGEST_MESSAGE, (path, value, exc)
            cases += 1
    assert cases > 1_000
