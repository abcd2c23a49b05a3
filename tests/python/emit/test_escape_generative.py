"""Free text of a machine file cannot reach any output as code or markup (issue #38 item 1,
design §11): each escaping function of chaincomp.escape against its language's own reader,
then machines whose every free-text field holds arbitrary Unicode (every kind of line break,
backslashes, comment ends, quotes, NUL, bidi marks): the generated C++ compiles, and outside
comments its tokens are those of the same machine with plain text; the Markdown report, the
LaTeX report and the plot page hold none of the text's markup."""

import csv
import html.parser
import io
import json
import os
import re
import subprocess

import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from chaincomp import escape
from chaincomp.analysis import report
from chaincomp.emit.cpp import generate, library
from chaincomp.model.machine import load_machine
from chaincomp.symbolic.derive import derive
from helpers import ROOT, cli

# Characters that have broken outputs: every line break C++, YAML and Unicode know, the
# splice, comment and string ends, markup of each language, NUL and other controls, bidi.
HOSTILE = list("\n\r\v\f\x85\u2028\u2029\\\"'`*/?()|<>&#$%^_~{}[];=+-@!\x00\x01\x1b\t \u202e\u200f\u00e9\u03bc") + [
    "*/", "??/", "</script>", "\\end{verbatim}", "```", "\r\n"]
TEXT = st.lists(st.sampled_from(HOSTILE) | st.characters(blacklist_categories=("Cs",)), max_size=30).map("".join)
SETTINGS = dict(derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ----------------------------------------------------------------------------- the functions

_ESCAPE = re.compile(r"\\x([0-9a-f]{2})|\\u([0-9a-f]{4})|\\U([0-9a-f]{8})")


def _unescape(text: str) -> str:
    return _ESCAPE.sub(lambda m: chr(int(next(g for g in m.groups() if g), 16)), text)


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_cpp_comment_is_one_ascii_line_without_splice_or_end(text):
    c = escape.cpp_comment(text)
    assert all(" " <= ch <= "~" for ch in c)                      # no line break of any kind
    assert not c.endswith("\\") and "??" not in c and "*/" not in c   # no splice, trigraph or end
    assert _unescape(c) == text                                   # nothing lost: each escape decodes


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_terminal_text_holds_no_control_and_loses_nothing(text):
    """Bus text on a terminal (issue #39 item 5): no character the Unicode database classes as a
    control (C0, DEL, C1: ECMA-48's control functions), a format or bidi mark, or a line or
    paragraph separator; every other character kept, and each escape decodes to the original."""
    import unicodedata
    t = escape.terminal(text)
    assert not any(unicodedata.category(ch) in ("Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn") for ch in t)
    assert _unescape(t) == text


@settings(max_examples=3, **SETTINGS)
@given(st.lists(st.binary(max_size=40) | TEXT.map(lambda t: t.encode("utf-8")), min_size=20, max_size=20))
def test_cpp_string_is_the_bytes_to_the_compiler(tmp_path_factory, strings):
    """Each literal, compiled, holds its bytes and only them (checked by static_assert)."""
    lines = []
    for i, data in enumerate(strings):
        lines.append(f"constexpr char s{i}[] = {escape.cpp_string(data)};")
        lines.append(f"static_assert(sizeof(s{i}) == {len(data) + 1}, \"size\");")
        lines += [f"static_assert(s{i}[{k}] == static_cast<char>({b}), \"byte\");" for k, b in enumerate(data)]
    path = tmp_path_factory.mktemp("literal") / "literal.cpp"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    proc = subprocess.run(["g++", "-std=c++17", "-fsyntax-only", "-Werror", "-Wall", "-Wextra", "-Wpedantic",
                           "-trigraphs", str(path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_yaml_scalar_reads_back_and_a_comment_line_writes_no_value(text):
    assert yaml.safe_load(f"k: {escape.yaml_scalar(text)}\n") == {"k": text}
    assert yaml.safe_load(f"a: 1   # {escape.one_line(text)}\nb: 2\n") == {"a": 1, "b": 2}
    assert len(escape.one_line(text).splitlines()) <= 1


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_markdown_text_renders_as_itself_in_a_paragraph_and_a_cell(text):
    from markdown_it import MarkdownIt
    md = MarkdownIt("commonmark").enable("table")   # raw HTML on, as CommonMark has it
    shown = escape.one_line(text)
    tokens = md.parse("before\n\n" + escape.markdown(text) + "\n")
    assert [t.type for t in tokens] == ["paragraph_open", "inline", "paragraph_close"] * (1 + bool(shown))
    if shown:
        assert _rendered(tokens[4]) == shown
    rows = _table_rows(md.parse("| a | b | c |\n|---|---|---|\n| 1 | " + escape.markdown(text) + " | 3 |\n"))
    assert rows == [["a", "b", "c"], ["1", shown, "3"]]


def _rendered(inline) -> str:
    """The text an inline token renders to, asserting it is text alone (no emphasis, code,
    link, image or HTML)."""
    assert all(c.type == "text" for c in inline.children), [c.type for c in inline.children]
    return "".join(c.content for c in inline.children)


def _table_rows(tokens) -> list[list[str]]:
    """The rendered cells of each row of the first table."""
    rows, row = [], None
    for t in tokens:
        if t.type == "tr_open":
            row = []
        elif t.type == "inline" and row is not None:
            row.append(_rendered(t))
        elif t.type == "tr_close":
            rows.append(row)
            row = None
        elif t.type == "table_close":
            break
    return rows


class _Tags(html.parser.HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.tags, self.data = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)

    def handle_endtag(self, tag):
        self.tags.append("/" + tag)

    def handle_data(self, data):
        self.data.append(data)


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_html_text_is_data_and_reads_back(text):
    p = _Tags()
    p.feed(f'<p title="{escape.html_text(text)}">{escape.html_text(text)}</p>')
    p.close()
    assert p.tags == ["p", "/p"]
    if "\\" not in text:   # the text back, its unprintable characters shown as escapes
        assert _unescape("".join(p.data)) == text


# LaTeX: what escape.latex writes besides plain characters; anything else special is markup.
_TEX_COMMANDS = re.compile(r"\\(?:textbackslash|textasciicircum|textasciitilde|textless|textgreater|textbar)\{\}"
                           r"|\\[_&%#${}]|\$-\$|\$\\pm\$|\$\\mu\$|\\texttt\{U\+[0-9A-F]{4,6}\}")


def _tex_plain(line: str) -> bool:
    rest = _TEX_COMMANDS.sub("", line)
    return not any(c in rest for c in "\\{}$&#%^_~") and "\n" not in rest


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_latex_text_holds_no_special(text):
    assert _tex_plain(escape.latex(text))
    assert r"\end{verbatim}" not in escape.latex_verbatim(text)


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_csv_cell_reads_back_as_text_never_a_formula(text):
    row = next(csv.reader(io.StringIO(escape.csv_text(text) + ",1\r\n", newline="")))
    assert len(row) == 2 and row[1] == "1"
    assert row[0] == text or row[0] == "'" + text and text.startswith(("=", "+", "-", "@", "\t", "\r"))


@settings(max_examples=200, **SETTINGS)
@given(TEXT)
def test_gcode_comment_cannot_close_or_break(text):
    c = escape.gcode_comment(text)
    assert all(" " <= ch <= "~" for ch in c) and "(" not in c and ")" not in c


# ----------------------------------------------------------------------------- whole machines

def _machine_doc(name: str, texts: list[str]) -> dict:
    """A two-axis machine whose description, five meanings and three labels are texts[0..8]."""
    symbols = [("X", "axis", "mm", {"limits": [-100, 100]}), ("C", "axis", "deg", {"limits": [-180, 180]}),
               ("L", "constant", "mm", {"nominal": 50}), ("EXX", "error", "um", {}), ("ECX", "error", "arcsec", {})]
    return {"name": name, "description": texts[0], "rotation_sense": "right_hand",
            "symbols": [{"name": n, "role": r, "unit": u, "meaning": texts[1 + i], **extra}
                        for i, (n, r, u, extra) in enumerate(symbols)],
            "chain": [{"translate": ["X + EXX", 0, 0], "label": texts[6]},
                      {"rotate": "z", "angle": "C + ECX", "label": texts[7]},
                      {"translate": ["L", 0, "-L"], "label": texts[8]}],
            "tool": {"point": [0, 0, 0]}}


def _write(folder, doc: dict) -> str:
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "m.yaml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(yaml.safe_dump(doc, allow_unicode=False))   # every non-ASCII and control as an escape
    return path


def _tokens(text: str) -> list[str]:
    """The C++ source without its comments, by the compiler's own preprocessor (a splice or a
    broken comment changes what it keeps), whitespace-normalised; the source hash (of the
    file's text) set aside."""
    proc = subprocess.run(["g++", "-x", "c++", "-std=c++17", "-fpreprocessed", "-E", "-P", "-"], input=text,
                          capture_output=True, text=True, check=True)
    out = re.sub(r"0x[0-9a-f]{16}ull", "HASH", proc.stdout)
    return out.split()


def _generated(tmp_path, name: str, texts: list[str]) -> tuple[dict, dict]:
    hostile = load_machine(_write(tmp_path / name / "hostile", _machine_doc(name, texts)))
    plain = load_machine(_write(tmp_path / name / "plain", _machine_doc(name, ["plain text"] * 9)))
    return generate(hostile), generate(plain)


HOSTILE_TEXTS = st.lists(TEXT, min_size=9, max_size=9)


@settings(max_examples=25, **SETTINGS)
@given(texts=HOSTILE_TEXTS)
def test_generated_cpp_has_the_plain_machines_tokens(tmp_path_factory, texts):
    tmp = tmp_path_factory.mktemp("tokens")
    hostile, plain = _generated(tmp, "m0", texts)
    for fname in hostile:
        assert _tokens(hostile[fname]) == _tokens(plain[fname]), fname


@pytest.mark.slow
@settings(max_examples=2, **SETTINGS)
@given(batch=st.lists(HOSTILE_TEXTS, min_size=3, max_size=3))
def test_generated_cpp_of_hostile_machines_compiles(tmp_path_factory, batch):
    """Three machines and one run-time library in one translation unit, with the flags of the
    models' build."""
    tmp = tmp_path_factory.mktemp("compile")
    flags = json.load(open(os.path.join(ROOT, "build", "model_build.json")))
    unit = []
    for k, texts in enumerate(batch):
        hostile, _ = _generated(tmp, f"m{k}", texts)
        for fname, text in hostile.items():
            (tmp / fname).write_text(text, encoding="utf-8")
        unit.append(f'#include "m{k}.cpp"')
    path = _write(tmp / "m0" / "hostile", _machine_doc("m0", batch[0]))
    (tmp / "library.cpp").write_text(library(load_machine(path), open(path, "rb").read(), "toolchain \"?\\\n"),
                                     encoding="utf-8")
    unit.append('#include "library.cpp"')
    (tmp / "unit.cpp").write_text("\n".join(unit) + "\n", encoding="utf-8")
    proc = subprocess.run([flags["compiler"], *[f for f in flags["flags"] if not f.startswith("-O")], "-fsyntax-only",
                           "-Werror", "-DCHAINCOMP_PREBUILT_CORE",
                           *[f"-I{d}" for d in flags["include_dirs"]], f"-I{tmp}", str(tmp / "unit.cpp")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]


@settings(max_examples=25, **SETTINGS)
@given(texts=HOSTILE_TEXTS)
def test_reports_hold_none_of_the_texts_markup(tmp_path_factory, texts):
    from markdown_it import MarkdownIt
    tmp = tmp_path_factory.mktemp("report")
    docs = {}
    plain = ["plain text" if escape.one_line(t) else "" for t in texts]   # an empty text writes no line
    for which, t in (("hostile", texts), ("plain", plain)):
        m = load_machine(_write(tmp, _machine_doc("m0", t)))   # one path: the reports name it
        d = derive(m, 1)
        docs[which] = (m, report.markdown(d), report.latex(d))
    md = MarkdownIt("commonmark").enable("table")
    shape = {w: [t.type for t in md.parse(text)] for w, (_, text, _) in docs.items()}
    assert shape["hostile"] == shape["plain"]          # no heading, list, HTML block or row added
    tokens = md.parse(docs["hostile"][1])
    assert not any(c.type.startswith("html") for t in tokens for c in [t] + (t.children or []))
    m = docs["hostile"][0]
    rows = _table_rows(tokens)   # the symbol table: the text of each Definition cell, as written
    assert [len(r) for r in rows] == [5] * (1 + len(m.symbols))
    for s, row in zip(m.symbols, rows[1:]):
        assert row[0] == s.name and row[4].startswith(escape.one_line(s.meaning))
    if escape.one_line(m.description):
        assert _rendered(tokens[4]) == escape.one_line(m.description)
    hostile_tex, plain_tex = docs["hostile"][2].splitlines(), docs["plain"][2].splitlines()
    assert len(hostile_tex) == len(plain_tex)
    for h, p in zip(hostile_tex, plain_tex):
        if h != p:   # a line with the text: the plain line's cells, the text's own as plain characters
            cells, plain_cells = re.split(r"(?<!\\)&", h), re.split(r"(?<!\\)&", p)
            assert len(cells) == len(plain_cells), h
            assert _tex_plain(cells[-1].removesuffix(r" \\")), h


@settings(max_examples=3, **SETTINGS)
@given(name=TEXT.map(lambda t: t.replace("/", "").replace("\x00", "").encode("utf-8")[:200]
                     .decode("utf-8", "ignore")).filter(lambda t: t not in ("", ".", "..")))
def test_plot_page_titles_hold_no_markup_of_a_file_name(tmp_path_factory, name):
    """The plot page's titles carry the params file's name; plotly reads them as HTML."""
    tmp = tmp_path_factory.mktemp("plot")
    machine = _write(tmp, _machine_doc("m0", ["plain"] * 9))
    params = tmp / (name + ".yaml")
    params.write_text("machine: m0\nvalues:\n  EXX: 5 um\n", encoding="utf-8")
    page = tmp / "p.html"
    res = cli("plot", machine, "--params", str(params), "--grid", "5", "--html", str(page), check=False)
    assert res.returncode == 0, res.stderr
    text = page.read_text(encoding="utf-8")
    titles = [json.loads(f'"{s}"') for s in re.findall(r'"text":"((?:[^"\\]|\\.)*)"', text)]
    shown = [t for t in titles if "params" in t]
    assert len(shown) == 2   # the two views' titles
    for t in shown:
        p = _Tags()
        p.feed(t)
        p.close()
        assert set(p.tags) <= {"br"}, t


def test_a_dollar_in_a_file_name_is_drawn_not_read_as_mathtext(tmp_path):
    """matplotlib reads text between two $ as mathtext: a params file named so stopped plot
    with an internal error (exit 3) instead of drawing its name."""
    machine = _write(tmp_path, _machine_doc("m0", ["plain"] * 9))
    params = tmp_path / "$\\frac{a$.yaml"
    params.write_text("machine: m0\nvalues:\n  EXX: 5 um\n", encoding="utf-8")
    res = cli("plot", machine, "--params", str(params), "--grid", "5", "-o", str(tmp_path / "p.png"), check=False)
    assert res.returncode == 0 and (tmp_path / "p.png").stat().st_size > 0, res.stderr


def test_a_meaning_cannot_write_a_value_into_a_params_file(tmp_path):
    """Written params files carry each error's meaning in a comment: its line breaks (YAML's
    U+2028 among them) used to end the comment, and the rest was read as an entry."""
    from helpers import RUNS, machine_path
    doc = yaml.safe_load(open(machine_path("five_axis_ac"), encoding="utf-8"))
    for s in doc["symbols"]:
        s["meaning"] = "x\n  EZX: 999 um\n\u2028  EYZ: 5 um #"
    machine = _write(tmp_path, doc)
    out = tmp_path / "laser.yaml"
    res = cli("laser-to-params", machine, RUNS, "--error", "EXX", "-o", str(out), check=False)
    assert res.returncode == 0, res.stderr
    assert list(yaml.safe_load(out.read_text(encoding="utf-8"))["values"]) == ["EXX"]
    out = tmp_path / "calibration.yaml"
    res = cli("simulate-calibration", machine, "--knots", "3", "-o", str(out), check=False)
    assert res.returncode == 0, res.stderr
    values = yaml.safe_load(out.read_text(encoding="utf-8"))["values"]
    assert "999" not in str(values.get("EZX")) and "5 um" != values.get("EYZ")
