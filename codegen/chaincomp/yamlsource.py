"""YAML loading that remembers the line of every mapping key and list item.

Validation messages must name the file and line of the offending field, so the loader
returns dicts and lists that know where each of their entries came from.
"""

from __future__ import annotations

from typing import Any

import yaml

from .errors import ChaincompError


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


def describe(value) -> str:
    """A value of the wrong shape or type, as validation messages name it."""
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return f"a list of {len(value)} item" + ("" if len(value) == 1 else "s")
    if value is None:
        return "nothing"
    return f"{type(value).__name__} {value!r}"


class _Loader(yaml.SafeLoader):
    pass


def _construct_mapping(loader: _Loader, node: yaml.MappingNode) -> LineDict:
    out = LineDict()
    out.line = node.start_mark.line + 1
    out.lines = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            raise ChaincompError(f"a mapping key must be text or a number, not a list or mapping: {key!r}",
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


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


def load_yaml(path: str) -> Any:
    """Parse ``path``; syntax errors become a ChaincompError with file and line."""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as exc:
        raise ChaincompError(f"cannot read file: {exc.strerror}", path) from None
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        raise ChaincompError(f"not UTF-8 text (byte {exc.object[exc.start]:#04x})", path, line) from None
    try:
        loader = _Loader(text)
    except yaml.reader.ReaderError as exc:
        line = text[:exc.position].count("\n") + 1
        raise ChaincompError(f"YAML syntax error: unacceptable character #x{exc.character:04x}: {exc.reason}",
                             path, line) from None
    loader.name = path
    try:
        return loader.get_single_data()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        raise ChaincompError(f"YAML syntax error: {exc.problem or exc.context}", path, line) from None
    except yaml.YAMLError as exc:
        raise ChaincompError(f"YAML error: {exc}", path) from None
    finally:
        loader.dispose()
