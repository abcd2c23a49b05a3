"""Bash completion written from the parser itself, so that it lists what the verbs take now:

    python -m chaincomp.cli.completion > tools/chaincomp-completion.bash
    source tools/chaincomp-completion.bash     # or copy it to /etc/bash_completion.d/chaincomp

Verbs, each verb's options, and the values of options with a fixed set of them; anything
else (files) falls back to bash's own completion."""

from __future__ import annotations

import argparse
import re
import shlex

from .common import DeprecatedAlias
from .main import build_parser


def _values(action: argparse.Action) -> list[str]:
    metavar = action.metavar if isinstance(action.metavar, str) else ""
    # the values shown: {1,2,exact} of a type= function, or those of choices that also take an
    # older spelling (export's --format text|json, which takes a controller's name too)
    m = re.fullmatch(r"\{(.+)\}", metavar)
    if m:
        return m.group(1).split(",")
    return [str(c) for c in action.choices] if action.choices else []


def bash_script(parser: argparse.ArgumentParser | None = None) -> str:
    parser = parser or build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    top = [s for a in parser._actions for s in a.option_strings]
    cases = []
    for verb, p in sub.choices.items():
        actions = list(p._actions)
        group = [a for a in actions if isinstance(a, argparse._SubParsersAction)]
        if group:   # a group of verbs (thermal fit, thermal check): their names, and all their options
            actions = [a for a in actions if a not in group] + [a for q in group[0].choices.values() for a in q._actions]
        actions = [a for a in actions if not isinstance(a, DeprecatedAlias)]   # offered no more
        opts = list(dict.fromkeys(s for a in actions for s in a.option_strings))
        values = [f"            {verb}) words={shlex.quote(' '.join(group[0].choices))};;"] if group else []
        for a in actions:
            words = _values(a)
            if a.option_strings and words and a.nargs != 0:
                values.append(f"            {'|'.join(a.option_strings)}) words={shlex.quote(' '.join(words))};;")
        values = list(dict.fromkeys(values))
        cases.append(f"        {verb})\n"
                     f"          case \"$prev\" in\n" + "".join(v + "\n" for v in values) +
                     f"            *) words={shlex.quote(' '.join(opts))}; [[ $cur == -* ]] || return 0;;\n"
                     f"          esac;;")
    verbs = " ".join(sub.choices)
    return f"""# bash completion for chaincomp; generated from its parser by
#   python -m chaincomp.cli.completion > tools/chaincomp-completion.bash
# (tests/python/cli/test_cli_consistency.py checks that it is up to date). Source it, or copy it
# to /etc/bash_completion.d/chaincomp.
_chaincomp() {{
    local cur="${{COMP_WORDS[COMP_CWORD]}}" prev="${{COMP_WORDS[COMP_CWORD-1]}}" verb="" words i
    COMPREPLY=()
    for ((i = 1; i < COMP_CWORD; i++)); do
        case "${{COMP_WORDS[i]}}" in -*) ;; *) verb="${{COMP_WORDS[i]}}"; break;; esac
    done
    if [[ -z $verb ]]; then
        words={shlex.quote(verbs + " " + " ".join(top))}
    else
        case "$verb" in
{chr(10).join(cases)}
        *) return 0;;
        esac
    fi
    COMPREPLY=($(compgen -W "$words" -- "$cur"))
}}
# -o default: file names where no word fits (machine files, params, outputs)
complete -o default -F _chaincomp chaincomp
"""


if __name__ == "__main__":
    print(bash_script(), end="")
