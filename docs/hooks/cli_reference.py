"""MkDocs hook: the command-line reference, generated from chaincomp's argparse parser at build time.

For every verb of ``chaincomp.cli.main.build_parser()`` it adds a page ``reference/cli/<verb>.md``
(the usage line, the verb's description and every option: flags, metavar, default, help), and
``reference/cli/index.md`` listing the verbs with their one-line help. Nothing generated is
committed, so the reference cannot drift from the parser: a new option is on its page at the
next build.
"""
from __future__ import annotations

import argparse
import html
import os
import re

from mkdocs.structure.files import File

CLI_DIR = "reference/cli"


def _parser():
    from chaincomp.cli.main import build_parser
    return build_parser()


class _Width:
    """argparse wraps usage lines to the terminal's width: the pages use 100 columns, wherever built."""

    def __enter__(self):
        self.old = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = "100"

    def __exit__(self, *exc):
        if self.old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = self.old


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


_MD_SPECIAL = re.compile(r"([\\`*_\[\]|#])")


def _text(s: str | None) -> str:
    """Help text as literal Markdown: HTML and Markdown characters escaped, one line."""
    if not s:
        return ""
    s = " ".join(str(s).split())
    return _MD_SPECIAL.sub(r"\\\1", html.escape(s, quote=False))


def _code(s: str) -> str:
    s = str(s).replace("|", "\\|")
    return f"`` {s} ``" if "`" in s else f"`{s}`"


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    if not action.help:
        return ""
    formatter = parser._get_formatter()
    try:
        return formatter._expand_help(action)   # %(default)s and the like, as --help prints them
    except (TypeError, ValueError, KeyError):
        return action.help


def _default(action: argparse.Action) -> str:
    d = action.default
    if d is None or d is argparse.SUPPRESS or isinstance(action, (
            argparse._StoreTrueAction, argparse._StoreFalseAction, argparse._StoreConstAction,
            argparse._HelpAction, argparse._VersionAction, argparse._CountAction)):
        return ""
    if isinstance(d, (list, tuple)):
        return "" if not d else _code(",".join(map(str, d)))
    return _code(d)


def _names(action: argparse.Action) -> str:
    if action.option_strings:
        return ", ".join(_code(o) for o in action.option_strings)
    return _code(action.metavar or action.dest)


def _metavar(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    if action.nargs == 0:
        return ""
    if action.choices is not None and action.metavar is None:
        return _code("{" + ",".join(map(str, action.choices)) + "}")
    if not action.option_strings:
        return ""
    formatter = parser._get_formatter()
    return _code(formatter._format_args(action, action.dest.upper()))


def verb_page(verb: str, one_line: str, parser: argparse.ArgumentParser, level: int = 1) -> str:
    """A verb's page; a group's (thermal) holds a section for each of its verbs (thermal fit)."""
    h = "#" * level
    out = [f"{h} chaincomp {verb}", "", _text(one_line), "", "```text", parser.format_usage().strip(), "```", ""]
    if parser.description:
        out += [_text(parser.description), ""]
    group = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    for g in parser._action_groups:
        actions = [a for a in g._group_actions if a.help is not argparse.SUPPRESS and a not in group]
        if not actions:
            continue
        out += [f"{h}# {g.title[:1].upper()}{g.title[1:]}", "",
                "| option | value | default | meaning |", "|---|---|---|---|"]
        for a in actions:
            out.append(f"| {_names(a)} | {_metavar(parser, a)} | {_default(a)} | {_text(_help(parser, a))} |")
        out.append("")
    if group:
        helps = {a.dest: a.help or "" for a in group[0]._choices_actions}
        for child, p in group[0].choices.items():
            out.append(verb_page(f"{verb} {child}", helps.get(child, ""), p, level + 1))
    if parser.epilog:
        out += [_text(parser.epilog), ""]
    if level == 1:
        out += ["*Generated from the parser (`chaincomp.cli.main.build_parser`) when the manual is built; "
                f"`chaincomp {verb} --help` prints the same.*", ""]
    return "\n".join(out)


def index_page(parser: argparse.ArgumentParser, verbs: list[tuple[str, str]]) -> str:
    out = ["# Command line", "", _text(parser.description), "",
           "```text", parser.format_usage().strip(), "```", "",
           "How the verbs share options and units: [Command line](../../index.md#command-line).", "",
           "| verb | what it does |", "|---|---|"]
    out += [f"| [{verb}]({verb}.md) | {_text(one_line)} |" for verb, one_line in verbs]
    out += ["", _text(parser.epilog), "",
            "*Generated from the parser (`chaincomp.cli.main.build_parser`) when the manual is built.*", ""]
    return "\n".join(out)


def pages() -> dict[str, str]:
    """src_uri -> Markdown of every generated page."""
    with _Width():
        return _pages(_parser())


def _pages(parser: argparse.ArgumentParser) -> dict[str, str]:
    sub = _subparsers(parser)
    helps = {a.dest: a.help or "" for a in sub._choices_actions}
    verbs = [(verb, helps.get(verb, "")) for verb in sub.choices]
    out = {f"{CLI_DIR}/index.md": index_page(parser, verbs)}
    for verb, one_line in verbs:
        out[f"{CLI_DIR}/{verb}.md"] = verb_page(verb, one_line, sub.choices[verb])
    return out


def on_files(files, config):
    for src_uri, content in pages().items():
        old = files.get_file_from_path(src_uri)
        if old is not None:
            files.remove(old)
        files.append(File.generated(config, src_uri, content=content))
    return files
