"""YAML loading that remembers the line of every mapping key and list item.

Validation messages must name the file and line of the offending field, so the loader
returns dicts and lists that know where each of their entries came from.
"""

from __future__ import annotations

import os
import re
import sys
from typing import Any

import yaml

from ..errors import ChaincompError


class LineDict(dict):
    """A mapping that knows the line of each key (``lines[key]``) and its own line."""

    line: int = 0
    lines: dict


class LineList(list):
    """A sequence that knows the line of each item (``lines[i]``) and its own line."""

    line: int = 0
    lines: list


def line_of(node, key=None, default=None) -> int | None:
    """The line of ``node[key]`` where the loader recorded one; otherwise ``default``, or
    without one the line of ``node`` itself (None for a value that is not from a file)."""
    lines = getattr(node, "lines", None)
    if key is not None and lines is not None:
        try:
            return lines[key]
        except (KeyError, IndexError, TypeError):
            pass
    return default if default is not None else getattr(node, "line", None)


# A number with an exponent that YAML 1.1 (PyYAML) takes for text: it wants a dot in the
# mantissa and a sign on the exponent (1.0e+3); 1e3, 1.5e3 and 1e+3 come as strings.
_TEXT_EXPONENT = re.compile(r"([-+]?)([0-9]*)(\.?)([0-9]*)[eE]([-+]?)([0-9]+)")


def yaml11_number(text: str) -> str | None:
    """'1e3' -> '1.0e+3', the spelling YAML 1.1 reads as the number meant; None for other text
    (and for '1.0e+3', which is text only when quoted). Number-sized text only, as the C++ loader's."""
    m = _TEXT_EXPONENT.fullmatch(text) if len(text) <= 64 else None
    if not m or not (m[2] or m[4]) or (m[3] and m[5]):
        return None
    sign, whole, _, frac, esign, exp = m.groups()
    return f"{sign}{whole}.{frac or ('' if not whole else '0')}e{esign or '+'}{exp}"


def describe(value) -> str:
    """A value of the wrong shape or type, as validation messages name it."""
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return f"a list of {len(value)} item" + ("" if len(value) == 1 else "s")
    if value is None:
        return "nothing"
    number = yaml11_number(value) if isinstance(value, str) else None
    if number:
        return f"str {value!r} (YAML reads {value} as text: write {number})"
    return f"{type(value).__name__} {value!r}"


MAX_FILE_BYTES = 16 * 1024 * 1024  # a machine, params, check or tolerance file
MAX_DEPTH = 64                     # nesting of mappings and lists, aliases expanded
MAX_EXPANSION = 10                 # nodes after alias expansion, per node written (plus _SLACK)
_SLACK = 10_000


# Numbers YAML 1.1 (PyYAML, here) and YAML 1.2 (yaml-cpp, the runtime) read alike: plain
# decimals. 0170 (octal 120 in 1.1, 170 in 1.2), 0x1f, 1_000, 1:30 are refused by both.
_PLAIN_DECIMAL = re.compile(r"[-+]?(?:(?:0|[1-9][0-9]*)(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
                            r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN)")


class _Loader(yaml.SafeLoader):
    """SafeLoader that refuses, while it composes, nesting deeper than MAX_DEPTH (the composer
    recurses, so a deep document would otherwise end in RecursionError), explicit tags,
    duplicate anchors and aliases to a node from inside it. The C++ loaders apply the same
    rules with the same messages (runtime/src/yaml_strict.cpp)."""

    _depth = 0
    nodes = 0

    def compose_node(self, parent, index):
        self._depth += 1
        self.nodes += 1
        try:
            event = self.peek_event()
            line = event.start_mark.line + 1
            if self._depth > MAX_DEPTH:
                raise ChaincompError(f"nested more than {MAX_DEPTH} levels deep", self.name, line)
            if isinstance(event, yaml.AliasEvent):
                if event.anchor in self._open_anchors:
                    raise ChaincompError("a YAML alias refers to a node that contains it", self.name, line)
                return super().compose_node(parent, index)
            if event.tag not in (None, "!"):
                raise ChaincompError(f"YAML tags are not accepted ({event.tag})", self.name, line)
            anchor = event.anchor
            if anchor is not None and anchor in self.anchors:
                raise ChaincompError(f"duplicate YAML anchor {anchor!r}", self.name, line)
            self._open_anchors.add(anchor)
            try:
                return super().compose_node(parent, index)
            finally:
                self._open_anchors.discard(anchor)
        finally:
            self._depth -= 1


def _check_expansion(root, written: int, path: str) -> None:
    """Refuse a document whose aliases expand it far beyond what was written (an alias bomb),
    or nest it deeper than MAX_DEPTH, before anything is constructed from it."""
    limit = MAX_EXPANSION * written + _SLACK
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    stack = [(root, False)]
    while stack:  # post-order, iterative: aliases can make the expanded tree deep
        node, done = stack.pop()
        if id(node) in size:
            continue
        children = []
        if isinstance(node, yaml.SequenceNode):
            children = node.value
        elif isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        if not done:
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in size)
            continue
        size[id(node)] = 1 + sum(size[id(c)] for c in children)
        depth[id(node)] = 1 + max((depth[id(c)] for c in children), default=0)
        if size[id(node)] > limit:
            raise ChaincompError(f"aliases expand the document beyond {limit} nodes "
                                 f"({written} written)", path, node.start_mark.line + 1)
        if depth[id(node)] > MAX_DEPTH:
            raise ChaincompError(f"nested more than {MAX_DEPTH} levels deep (aliases expanded)",
                                 path, node.start_mark.line + 1)


def _construct_mapping(loader: _Loader, node: yaml.MappingNode) -> LineDict:
    out = LineDict()
    out.line = node.start_mark.line + 1
    out.lines = {}
    for key_node, value_node in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            raise ChaincompError("YAML merge keys (<<) are not accepted", loader.name, key_node.start_mark.line + 1)
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            raise ChaincompError("a mapping key must be text or a number, not a list or mapping",
                                 loader.name, key_node.start_mark.line + 1) from None
        if key in out:
            raise ChaincompError(f"duplicate key {key!r}", loader.name, key_node.start_mark.line + 1,
                                 str(key))
        out[key] = loader.construct_object(value_node, deep=True)
        out.lines[key] = key_node.start_mark.line + 1
    return out


def _construct_sequence(loader: _Loader, node: yaml.SequenceNode) -> LineList:
    out = LineList(loader.construct_object(child, deep=True) for child in node.value)
    out.line = node.start_mark.line + 1
    out.lines = [child.start_mark.line + 1 for child in node.value]
    return out


def _construct_number(loader: _Loader, node: yaml.ScalarNode):
    if not _PLAIN_DECIMAL.fullmatch(node.value):
        raise ChaincompError(f"ambiguous number {node.value!r}: YAML 1.1 and 1.2 read it differently; "
                             "write it in plain decimal", loader.name, node.start_mark.line + 1)
    if node.tag == "tag:yaml.org,2002:int":
        limit = sys.get_int_max_str_digits()
        if limit and len(node.value.lstrip("+-")) > limit:
            # int() refuses so many digits (ValueError: exit 3): the value is beyond any float
            # anyway, and as ±inf every field refuses it as not finite, at its line
            return float(node.value)
        return yaml.SafeLoader.construct_yaml_int(loader, node)
    return yaml.SafeLoader.construct_yaml_float(loader, node)


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_Loader.add_constructor("tag:yaml.org,2002:int", _construct_number)
_Loader.add_constructor("tag:yaml.org,2002:float", _construct_number)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


def read_text(path: str, limit: int = MAX_FILE_BYTES) -> str:
    """The text of an input file: a regular file of at most ``limit`` bytes, UTF-8."""
    if os.path.exists(path) and not os.path.isfile(path):
        raise ChaincompError("not a regular file", path)
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise ChaincompError(f"cannot read file: {exc.strerror}", path) from None
    if len(data) > limit:
        raise ChaincompError(f"larger than {limit // (1024 * 1024)} MiB", path)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise ChaincompError(f"not UTF-8 text (byte {data[exc.start]:#04x})", path, line) from None


def load_yaml(path: str) -> Any:
    """Parse ``path``; syntax errors become a ChaincompError with file and line."""
    text = read_text(path)
    try:
        loader = _Loader(text)
    except yaml.reader.ReaderError as exc:
        line = text[:exc.position].count("\n") + 1
        raise ChaincompError(f"YAML syntax error: unacceptable character #x{exc.character:04x}: {exc.reason}",
                             path, line) from None
    loader.name = path
    loader._open_anchors = set()
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        _check_expansion(root, loader.nodes, path)
        return loader.construct_document(root)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        raise ChaincompError(f"YAML syntax error: {exc.problem or exc.context}", path, line) from None
    except yaml.YAMLError as exc:
        raise ChaincompError(f"YAML error: {exc}", path) from None
    finally:
        loader.dispose()
