"""Entry point: dispatches to the verb modules; user errors exit 2 with one clear line."""

from __future__ import annotations

import argparse
import sys

from ..errors import ChaincompError
from . import derive, eval as eval_, generate, testvectors

VERBS = (derive, eval_, generate, testvectors)
from . import identify, protocol, simulate_measurements  # noqa: E402
VERBS += (protocol, identify, simulate_measurements)
from . import plot, replay, simulate_log  # noqa: E402
VERBS += (simulate_log, replay, plot)
from . import check, report  # noqa: E402
VERBS += (check, report)
from . import budget  # noqa: E402
VERBS += (budget,)
from . import simulate_calibration  # noqa: E402
VERBS += (simulate_calibration,)
from . import build; VERBS += (build,)  # noqa: E402,E702


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="chaincomp",
        description="Geometric error models of machine tools: derive, evaluate and generate "
                    "compensation code from a machine description.")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb in VERBS:
        verb.add_parser(sub)
    return parser


# Options whose values may start with '-' (e.g. --range -60:60), which argparse would
# otherwise take for an option.
_SIGNED_VALUE_OPTIONS = ("--range", "--range2")


def _join_signed_values(argv: list[str]) -> list[str]:
    out: list[str] = []
    for token in argv:
        if out and out[-1] in _SIGNED_VALUE_OPTIONS and token.startswith("-"):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_signed_values(sys.argv[1:] if argv is None else argv))
    try:
        return args.run(args) or 0
    except ChaincompError as exc:
        print(f"chaincomp {args.verb}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"chaincomp {args.verb}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
