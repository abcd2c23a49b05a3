"""chaincomp report: the output's suffix picks the format, whatever its case."""

from __future__ import annotations

from helpers import M4, cli, write_file


def test_report_to_an_upper_case_tex_file_is_latex(tmp_path):
    machine = write_file(tmp_path, "m.yaml", M4)
    out = tmp_path / "R.TEX"
    proc = cli("report", machine, "-o", str(out))
    assert "(latex, m4, order 1)" in proc.stdout + proc.stderr
    assert "\\begin" in out.read_text() or "\\section" in out.read_text()
