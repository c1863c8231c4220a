r"""YAML read with limits: every YAML file a user gives (protocols, model files, joint mappings) is read here.

A ``yaml.safe_load`` of a 4 KB 'billion laughs' file ran past 120 s at 5.7 GB (issue 26); a 1 MiB list of
one-letter items took 20 s. :func:`load_bounded` refuses, before building any value, a text over
:data:`MAX_YAML_CHARACTERS`, more than :data:`MAX_NODES` nodes, nesting deeper than :data:`MAX_NESTING`,
aliases that expand past :data:`MAX_EXPANDED_SIZE` or contain themselves, and a key given twice in one
mapping (plain YAML silently keeps the last). :func:`yaml_problem` turns any YAML error into one short line
with its line and column. Both halves of the project use it (``stimuli`` may import ``analysis``, never
the reverse), so it lives here.

>>> load_bounded("a: [1, 2]")[0]
{'a': [1, 2]}
>>> text = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
...     f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
>>> try:
...     load_bounded(text)
... except yaml.YAMLError as exc:
...     print(yaml_problem(exc, text)[:59])
 line 7, column 4: aliases expand this value past 2,097,152
"""

from __future__ import annotations

import yaml

# The bundled protocols are 2–4 KB and under 350 nodes; model and mapping files are smaller still.
MAX_YAML_CHARACTERS = 1_048_576                # 1 MiB of text
MAX_EXPANDED_SIZE = 2 * MAX_YAML_CHARACTERS    # characters + nodes once every alias (*name) is expanded
MAX_NODES = 20_000                             # values, keys, lists, mappings as written
MAX_NESTING = 50                               # lists and mappings inside each other (a protocol needs 5)


def _shown(text: str, limit: int = 60) -> str:
    """A value as a message echoes it: quoted when short, else its size (a 1 MB key gives a short message)."""
    return repr(text) if len(text) <= limit else f"{len(text):,} characters"


class YamlRefused(yaml.MarkedYAMLError):
    """Well-formed YAML the loader will not read: over a limit, or a value PyYAML cannot build."""


class BoundedLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (YAML itself keeps the last
    one, so a second ``participants:`` line would silently override the first), lists or mappings
    nested deeper than :data:`MAX_NESTING` (PyYAML composes them recursively: 5,000 ``[`` were a
    RecursionError) and more than :data:`MAX_NODES` nodes (pure-Python PyYAML reads ~25,000 nodes a
    second: a 1 MiB list of one-letter items took 20 s; counting as it reads stops it early)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0

    def compose_node(self, parent, index):
        self._depth += 1
        self._nodes += 1
        try:
            if self._nodes > MAX_NODES:
                raise YamlRefused(None, None, f"more than {MAX_NODES:,} values, keys, lists and "
                                                  "mappings; the bundled files need a few hundred",
                                                  self.peek_event().start_mark)
            if self._depth > MAX_NESTING:
                raise YamlRefused(None, None, f"lists and mappings nested deeper than {MAX_NESTING} "
                                                  "levels; the bundled files need a handful", self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_object(self, node, deep=False):
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, OverflowError) as exc:
            # SafeConstructor's own errors: a date that does not exist (!!timestamp 2001-13-45), an
            # integer of more digits than Python reads (4,300)
            raise YamlRefused(None, None, f"cannot read the value ({_shown(str(exc), 120)})", node.start_mark) from None

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            if isinstance(key_node, yaml.ScalarNode) and key_node.tag != "tag:yaml.org,2002:merge":
                key = key_node.value
                if key in seen:
                    raise YamlRefused(
                        None, None, f"key {_shown(key)} appears twice in one mapping (first on line {seen[key]})",
                        key_node.start_mark)
                seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)


def check_expansion(root: yaml.Node) -> None:
    """Refuse a node tree whose aliases expand it past :data:`MAX_EXPANDED_SIZE` (nodes plus characters
    of text, counted once per use) or :data:`MAX_NESTING`, or make it contain itself.

    PyYAML builds an alias as a shared reference, so the expansion costs nothing until something walks
    the values (validation, JSON, an error message): a chain of anchors each listing the one before nine
    times makes 9⁹ strings from a few lines. Sizes are summed bottom-up, each distinct node once, without
    recursion (a chain of 100,000 anchors must not overflow Python's stack).
    """
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        key = id(node)
        children = node_children(node)
        if children_done:
            on_path.discard(key)
            size[key] = 1 + (len(node.value) if isinstance(node, yaml.ScalarNode) else 0) + sum(size[id(c)] for c in children)
            depth[key] = 1 + max((depth[id(c)] for c in children), default=0)
            if size[key] > MAX_EXPANDED_SIZE:
                raise YamlRefused(
                    None, None, f"aliases expand this value past {MAX_EXPANDED_SIZE:,} characters and nodes (a "
                    "'billion laughs' file); write the values out, or use fewer aliases", node.start_mark)
            if depth[key] > MAX_NESTING:
                raise YamlRefused(
                    None, None, f"aliases nest this value deeper than {MAX_NESTING} levels", node.start_mark)
            continue
        if key in size:
            continue
        if key in on_path:
            raise YamlRefused(None, None, "an alias refers to itself (the value would contain "
                                              "itself without end)", node.start_mark)
        on_path.add(key)
        stack.append((node, True))
        stack.extend((child, False) for child in children if id(child) not in size)


def node_children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def load_bounded(text: str) -> tuple[object, yaml.Node | None]:
    """The data of a YAML text and its node tree (for line numbers), checked against the limits before
    anything is built from the nodes; raises a ``yaml.YAMLError`` (see :func:`yaml_problem`)."""
    if len(text) > MAX_YAML_CHARACTERS:
        raise YamlRefused(None, None, f"the text is {len(text):,} characters, over the {MAX_YAML_CHARACTERS:,} "
                          "read", None)
    loader = None
    try:
        loader = BoundedLoader(text)   # reads the text's first characters: a control character fails here
        root = loader.get_single_node()
        if root is None:
            return None, None
        check_expansion(root)
        return loader.construct_document(root), root
    finally:
        if loader is not None:
            loader.dispose()


def yaml_problem(exc: yaml.YAMLError, text: str) -> str:
    """``" line L, column C: problem"`` of a YAML error, short (PyYAML quotes what it read: an undefined
    alias of 1 MB, say); refusals by the limits read as they are, other errors as syntax errors."""
    mark = getattr(exc, "problem_mark", None)
    where = f" line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    problem = getattr(exc, "problem", None) or str(exc)
    if isinstance(exc, yaml.reader.ReaderError):   # it has no mark, only the character's position
        line_start = text.rfind("\n", 0, exc.position) + 1
        where = f" line {text.count(chr(10), 0, exc.position) + 1}, column {exc.position - line_start + 1}"
        problem = f"character #x{exc.character:04x} is not allowed in YAML ({exc.reason})"
    if len(problem) > 300:
        problem = f"{problem[:200]}… ({len(problem):,} characters)"
    kind = "" if isinstance(exc, YamlRefused) else "YAML syntax error: "
    return f"{where}: {kind}{problem}"
