"""Text a user wrote, made safe for the language of the output it lands in (design §11).

A machine file's description and meanings, a file name, a command line: each output language
has one function here, and every emitter writing into that language calls it. Each function
returns text that stays inside the construct it is written into (a comment, a string, a
table cell, a paragraph) whatever the input, and shows what it replaced rather than dropping
it. Identifiers are not text: machine and symbol names are checked against
model.expressions.NAME when the file is loaded.
"""

from __future__ import annotations

import html
import re

def _code(c: str) -> str:
    """A character as a C-style escape: \\xHH, \\uHHHH or \\UHHHHHHHH (never ends in a backslash)."""
    n = ord(c)
    return f"\\x{n:02x}" if n < 0x100 else f"\\u{n:04x}" if n < 0x10000 else f"\\U{n:08x}"


def _visible(c: str) -> str:
    """A character not printable (a control, a line break, a format or bidi mark, a surrogate)
    as its escape; any other as itself."""
    return c if c.isprintable() else _code(c)


def one_line(text: str) -> str:
    """Free text as one line of printable characters (whitespace runs, line breaks among them —
    \n, \r, \v, \f, U+0085, U+2028, U+2029, which YAML 1.1 also breaks at — as one space; other
    unprintable characters as escapes): for a terminal, or a comment of a format that reads
    UTF-8 (YAML, CSV, INI, HAL)."""
    return "".join(_visible(c) for c in " ".join(str(text).split()))


def terminal(text: str) -> str:
    """Text from outside (a bus message, a file's name) on a terminal, kept exactly otherwise:
    every unprintable character as its escape (ESC, BEL, BS, CR and the other C0 controls, DEL,
    the C1 controls of ECMA-48, line breaks, format and bidi marks) and the backslash too, so no
    byte moves the cursor, rewrites the screen or passes for an escape it is not."""
    return "".join(_code(c) if c == "\\" or not c.isprintable() else c for c in str(text))


def cpp_comment(text: str) -> str:
    """Text inside a C++ ``//`` (or ``/* */``) comment: printable ASCII as itself; a backslash,
    every other character, a ``?`` after ``?`` (trigraph ??/ is a backslash before C++17) and
    a ``/`` after ``*`` as an escape. No line break, splice or comment end survives."""
    out = []
    prev = ""
    for c in str(text):
        risky = c == "\\" or not (" " <= c <= "~") or (c == "?" and prev == "?") or (c == "/" and prev == "*")
        out.append(_code(c) if risky else c)
        prev = c
    return "".join(out)


def cpp_string(data: bytes) -> str:
    """A C++ string literal of ``data`` byte for byte: printable ASCII as is, every other byte
    as a three-digit octal escape (which, unlike \\x, cannot swallow a following digit); the
    literal is split after each newline byte to keep the source readable."""
    out = []
    for b in data:
        c = chr(b)
        if c in '"\\?':
            out.append("\\" + c)
        elif 0x20 <= b < 0x7F:
            out.append(c)
        else:
            out.append(f"\\{b:03o}")
        if b == 0x0A:
            out.append('"\n    "')
    return '"' + "".join(out) + '"'


# CommonMark: an ASCII punctuation character after a backslash is literal text. Escaped: the
# inline markup (GitHub's ~ and $ included) and # anywhere; <, > and & as entities (no tag, no
# entity, in every renderer); a line start that would open a list, rule or setext heading.
_MD_ENTITIES = {"<": "&lt;", ">": "&gt;", "&": "&amp;"}
_MD_INLINE = set("\\`*_[]|~$#")
_MD_BLOCK_START = re.compile(r"[-+=]|[0-9]+[.)]")


def markdown(text: str) -> str:
    """Text in a Markdown paragraph, heading or table cell: one line (so no heading, list,
    quote or fence can start on a line of its own), every markup character literal (a ``|``
    cannot split a cell), no HTML."""
    out = "".join(_MD_ENTITIES[c] if c in _MD_ENTITIES else "\\" + c if c in _MD_INLINE else c
                  for c in one_line(text))
    start = _MD_BLOCK_START.match(out)
    return out[:start.end() - 1] + "\\" + out[start.end() - 1:] if start else out


def markdown_code_block(text: str) -> list[str]:
    """Lines of a fenced code block holding ``text`` verbatim: the fence longer than any run of
    backticks in it, so no line of the text can close it."""
    longest, run = 0, 0
    for c in text:
        run = run + 1 if c == "`" else 0
        longest = max(longest, run)
    fence = "`" * max(3, longest + 1)
    return [fence] + [_visible_line(line) for line in text.split("\n")] + [fence]


def _visible_line(line: str) -> str:
    return "".join(c if c == "\t" else _visible(c) for c in line)


def html_text(text: str) -> str:
    """Text in HTML content or a quoted attribute (and plotly's titles, which read a subset of
    HTML): <, >, &, " and ' as entities, unprintable characters as escapes."""
    return html.escape("".join(_visible(c) for c in str(text)), quote=True)


_TEX = {"\\": r"\textbackslash{}", "_": r"\_", "&": r"\&", "%": r"\%", "#": r"\#", "$": r"\$",
        "{": r"\{", "}": r"\}", "^": r"\textasciicircum{}", "~": r"\textasciitilde{}", "−": "$-$",
        "±": r"$\pm$", "µ": r"$\mu$", "<": r"\textless{}", ">": r"\textgreater{}", "|": r"\textbar{}"}


def latex(text: str) -> str:
    """Text in a LaTeX paragraph or tabular cell: one line (a blank line would end the
    paragraph), every special character as its command, characters outside printable ASCII
    and Latin-1 letters (which pdfLaTeX may not have a glyph for) as \\texttt{U+HHHH}."""
    out = []
    for c in one_line(text):
        if c in _TEX:
            out.append(_TEX[c])
        elif " " <= c <= "~" or ("\u00c0" <= c <= "\u00ff" and c not in "\u00d7\u00f7"):
            out.append(c)
        else:
            out.append(rf"\texttt{{U+{ord(c):04X}}}")
    return "".join(out)


def latex_verbatim(text: str) -> str:
    """Lines for a verbatim environment, which ends at the first \\end{verbatim} whatever
    precedes it: that sequence broken by a space, unprintable characters as escapes."""
    return "\n".join(_visible_line(line) for line in text.split("\n")).replace(r"\end{verbatim}", r"\end {verbatim}")


def yaml_scalar(text: str) -> str:
    """A YAML double-quoted scalar that yaml.safe_load reads back as ``text``: printable ASCII
    as itself, " and \\ escaped, everything else by \\x, \\u or \\U."""
    out = []
    for c in str(text):
        out.append("\\" + c if c in '"\\' else c if " " <= c <= "~" else _code(c))
    return '"' + "".join(out) + '"'


_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_text(text: str) -> str:
    """A CSV cell (RFC 4180) holding free text: quoted when it holds a comma, a quote or a line
    break; a leading = + - @ (a spreadsheet formula) made literal by a leading apostrophe
    (OWASP's CSV injection rule). Numbers are written as numbers, not through this."""
    text = str(text)
    if text.startswith(_FORMULA_START):
        text = "'" + text
    if any(c in text for c in ',"\n\r'):
        text = '"' + text.replace('"', '""') + '"'
    return text


def gcode_comment(text: str) -> str:
    """Text inside a G-code comment, ``( ... )`` (LinuxCNC, RS274/NGC) or after ``;`` (Marlin,
    Klipper, RepRapFirmware): printable ASCII on one line, parentheses (which cannot nest in
    LinuxCNC) as brackets, everything else as ``?``."""
    line = " ".join(str(text).split())
    return "".join("[" if c == "(" else "]" if c == ")" else c if " " <= c <= "~" else "?" for c in line)
