"""Every output of every verb, found by walking the command line's parser, written by the one
writer (chaincomp.output; issue #38 item 2) with -o (or --plot, --html, --csv) naming

(a) a named pipe: written into (a reader drains it), never replaced by a regular file;
(b) a symbolic link to a regular file: the link stays a link, the file it names gets the
    content; links planted at the temporary names writers used to predict (".NAME.PID~",
    ".NAME.PID.0.tmp", "NAME.PID.tmp") are not followed;
(c) a full device (a node like /dev/full, 1:7, made here as root; else a link to /dev/full):
    exit 2 "No space left on device", the node untouched;
(d) a read-only folder, run as the user nobody (setpriv; as root only): exit 2, one line naming
    the path.

In each case a snapshot of the test's folder shows that nothing but the named path changed (a
folder verb's other files may appear in its folder, except on a failure: then none). The truth
is POSIX's: a rename replaces a link or a pipe by a regular file, and /dev/full refuses every
write with ENOSPC.

Verbs run in this process (cli.main.main); `build` with its compile replaced by a file standing
for the library (its copy to -o DIR is what is tested here; emit/test_build.py compiles)."""

from __future__ import annotations

import argparse
import json
import os
import pwd
import shutil
import stat
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass

import pytest

import ur_description
from helpers import PARAMS, ROOT, RUNS, URDF, VMC, cli, machine_path

FIVE = machine_path("five_axis_ac")
NUTATING = machine_path("nutating_bc45")
SPHERE = ["--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2"]
VMC_PARAMS = os.path.join(PARAMS, "vmc_xyz-demo.yaml")
VMC_THERMAL = os.path.join(ROOT, "configs", "thermal", "vmc_xyz-true.yaml")
LCM_MAGIC = bytes.fromhex("EDA1DA01")   # every lcm-logger event starts with it (lcm/eventlog.c)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"        # PNG's signature (RFC 2083 §3.1)


@dataclass
class Case:
    id: str
    verb: str                 # as the parser names it: "thermal fit"
    option: str               # the output option's long name
    argv: callable            # inputs -> the command line without the output
    name: str = "out.txt"     # the output's file name (a folder verb: the file inside it that is tested)
    folder: bool = False      # the option names a folder
    kind: str = "text"        # what a whole output looks like: text (ends with a line end), png, html, lcm, bytes


CASES = [
    Case("generate", "generate", "--output", lambda i: ["generate", VMC, "--order", "1"], "vmc_xyz.hpp", True),
    Case("testvectors", "testvectors", "--output", lambda i: ["testvectors", VMC, "--count", "2"]),
    Case("protocol", "protocol", "--output", lambda i: ["protocol", VMC, "--poses", "12"], "poses.csv"),
    Case("identify", "identify", "--output", lambda i: ["identify", VMC, i["meas"]], "p.yaml"),
    Case("identify-report", "identify", "--report", lambda i: ["identify", VMC, i["meas"]], "r.html", kind="html"),
    Case("simulate-measurements", "simulate-measurements", "--output",
         lambda i: ["simulate-measurements", VMC, "--setups", "random:5"], "meas.csv"),
    Case("simulate-log", "simulate-log", "--output", lambda i: ["simulate-log", VMC, "--seconds", "0.01"],
         "a.lcmlog", kind="lcm"),
    Case("replay-o", "replay", "--output", lambda i: ["replay", VMC, i["log"], "--params", VMC_PARAMS],
         "b.lcmlog", kind="lcm"),
    Case("replay-csv", "replay", "--csv", lambda i: ["replay", VMC, i["log"], "--params", VMC_PARAMS], "b.csv"),
    Case("plot-o", "plot", "--output", lambda i: ["plot", VMC, "--set", "EXX=1", "--grid", "3"], "p.png",
         kind="png"),
    Case("plot-html", "plot", "--html", lambda i: ["plot", VMC, "--set", "EXX=1", "--grid", "3"], "p.html",
         kind="html"),
    Case("report", "report", "--output", lambda i: ["report", VMC], "r.md"),
    Case("budget", "budget", "--plot", lambda i: ["budget", VMC, "--set", "EXX=1", "--grid", "2"], "b.png",
         kind="png"),
    Case("simulate-calibration", "simulate-calibration", "--output",
         lambda i: ["simulate-calibration", FIVE, "--knots", "3"], "cal.yaml"),
    Case("build", "build", "--output", lambda i: ["build", VMC], "vmc_xyz.so", True, kind="bytes"),
    Case("iso230-2", "iso230-2", "--plot", lambda i: ["iso230-2", RUNS], "iso.png", kind="png"),
    Case("laser-to-params", "laser-to-params", "--output",
         lambda i: ["laser-to-params", FIVE, RUNS, "--error", "EXX"], "l.yaml"),
    Case("import-urdf", "import-urdf", "--output", lambda i: ["import-urdf", i["urdf"], "--base", "base", "--tip", "tip"],
         "u.yaml"),
    Case("export-urdf", "export-urdf", "--output",
         lambda i: ["export-urdf", i["urdf_machine"], i["urdf"], "--base", "base", "--tip", "tip",
                    "--params", i["urdf_params"]], "c.urdf"),
    Case("import-ur-calibration", "import-ur-calibration", "--output",
         lambda i: ["import-ur-calibration", i["ur_machine"], i["ur_urdf"], i["ur_calibration"], "--base", "base_link",
                    "--tip", "tool0"], "ur-params.yaml"),
    Case("ballbar-o", "ballbar", "--output",
         lambda i: ["ballbar", VMC, "--set", "EXX=1", "--plane", "XY", "--radius", "10"], "trace.csv"),
    Case("ballbar-fit-o", "ballbar", "--output", lambda i: ["ballbar", VMC, "--fit", i["trace"]], "fit.yaml"),
    Case("ballbar-plot", "ballbar", "--plot",
         lambda i: ["ballbar", VMC, "--set", "EXX=1", "--plane", "XY", "--radius", "10"], "bb.png", kind="png"),
    Case("export-klipper", "export", "--output",
         lambda i: ["export", VMC, "--params", VMC_PARAMS, "--controller", "klipper"], "k.cfg"),
    Case("export-linuxcnc-comp", "export", "--output",
         lambda i: ["export", VMC, "--params", VMC_PARAMS, "--controller", "linuxcnc-comp"], "compensation.ini", True),
    Case("export-isg-volcomp", "export", "--output",
         lambda i: ["export", VMC, "--params", VMC_PARAMS, "--controller", "isg-volcomp"], "volcomp.lis", True),
    Case("simulate-thermal", "simulate-thermal", "--output",
         lambda i: ["simulate-thermal", VMC, "--truth", VMC_THERMAL, "--rate", "0.01"], "th.csv"),
    Case("thermal-fit", "thermal fit", "--output", lambda i: ["thermal", "fit", VMC, i["thermal_log"]], "fit.yaml"),
    Case("thermal-stream", "thermal stream", "--output",
         lambda i: ["thermal", "stream", VMC, VMC_THERMAL, i["thermal_log"], "--controller", "isg"], "s.csv"),
    Case("probe-plan-gcode", "probe plan", "--gcode", lambda i: ["probe", "plan", NUTATING, *SPHERE], "p.ngc"),
    Case("probe-plan-csv", "probe plan", "--csv", lambda i: ["probe", "plan", NUTATING, *SPHERE], "p.csv"),
    Case("probe-simulate", "probe simulate", "--output",
         lambda i: ["probe", "simulate", NUTATING, i["probe_plan"], *SPHERE], "probe.txt"),
    Case("probe-fit", "probe fit", "--output", lambda i: ["probe", "fit", NUTATING, i["probe_log"], *SPHERE],
         "fit.yaml"),
    Case("probe-fit-report", "probe fit", "--report", lambda i: ["probe", "fit", NUTATING, i["probe_log"], *SPHERE],
         "r.html", kind="html"),
]
IDS = [c.id for c in CASES]
OUTPUT_OPTIONS = ("--output", "--plot", "--html", "--csv")


def _writing_options() -> set[tuple[str, str]]:
    """(verb, option) of every option that names a file or folder to write, by walking the parser:
    an option named as the outputs are, or whose value is named OUT..."""
    from chaincomp.cli.main import build_parser
    found = set()

    def walk(parser, verb):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    if sub.prog.split()[-1] == name:   # not an alias
                        walk(sub, f"{verb} {name}".strip())
            elif action.option_strings:
                long = max(action.option_strings, key=len)
                if long in OUTPUT_OPTIONS or str(action.metavar or "").startswith("OUT"):
                    found.add((verb, long))
    walk(build_parser(), "")
    return found


def test_every_output_option_of_every_verb_has_a_case_here():
    assert _writing_options() == {(c.verb, c.option) for c in CASES}


# ----------------------------------------------------------------------------- inputs and snapshots

@pytest.fixture(scope="module")
def base():
    """A folder everyone may enter (pytest's own is root's alone): the user nobody reads the
    inputs here and is refused the read-only folders."""
    path = tempfile.mkdtemp(prefix="chaincomp-outputs-")
    os.chmod(path, 0o755)
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope="module")
def inputs(base):
    d = os.path.join(base, "inputs")
    os.mkdir(d)
    i = {"meas": f"{d}/meas.csv", "log": f"{d}/a.lcmlog", "trace": f"{d}/trace.csv", "thermal_log": f"{d}/th.csv",
         "urdf": f"{d}/r.urdf", "library": f"{d}/vmc_xyz.so", "urdf_machine": f"{d}/u.yaml",
         "urdf_params": f"{d}/u-params.yaml", "ur_urdf": f"{d}/ur5e.urdf", "ur_machine": f"{d}/ur5e.yaml",
         "ur_calibration": f"{d}/ur5e-calibration.yaml", "probe_plan": f"{d}/plan.csv", "probe_log": f"{d}/probe.txt"}
    cli("probe", "plan", NUTATING, *SPHERE, "--csv", i["probe_plan"])
    cli("probe", "simulate", NUTATING, i["probe_plan"], *SPHERE, "-o", i["probe_log"])
    cli("simulate-measurements", VMC, "--setups", "random:20", "-o", i["meas"])
    cli("simulate-log", VMC, "--seconds", "0.01", "-o", i["log"])
    cli("ballbar", VMC, "--set", "EXX=1", "--plane", "XY", "--radius", "10", "-o", i["trace"])
    cli("simulate-thermal", VMC, "--truth", VMC_THERMAL, "--rate", "0.01", "-o", i["thermal_log"])
    with open(i["urdf"], "w") as f:
        f.write(URDF)
    cli("import-urdf", i["urdf"], "--base", "base", "--tip", "tip", "--errors", "all", "-o", i["urdf_machine"])
    from chaincomp.model.machine import load_machine
    m = load_machine(i["urdf_machine"])
    with open(i["urdf_params"], "w") as f:
        f.write(f"machine: {m.name}\nvalues:\n" + "".join(f"  {e.name}: 3 {e.unit.name}\n" for e in m.errors))
    with open(i["ur_urdf"], "w") as f:
        f.write(ur_description.urdf_text(ur_description.UR5E))
    with open(i["ur_calibration"], "w") as f:
        f.write(ur_description.calibration_text(ur_description.UR5E))
    cli("import-urdf", i["ur_urdf"], "--base", "base_link", "--tip", "tool0", "--errors", "origins", "-o",
        i["ur_machine"])
    with open(i["library"], "wb") as f:
        f.write(b"\x7fELF stands for the library chaincomp build compiles\n")
    for p in i.values():
        os.chmod(p, 0o644)
    return i


@pytest.fixture
def no_compile(monkeypatch, inputs):
    import chaincomp.cli.build as build_verb
    monkeypatch.setattr(build_verb, "build", lambda machine: (inputs["library"], True))


def _snapshot(folder: str) -> dict:
    """Every entry under folder: its type, mode, content (a regular file), target (a link) or
    device number (a node)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for n in dirs + files:
            p = os.path.join(root, n)
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                out[p] = ("link", os.readlink(p))
            elif stat.S_ISREG(st.st_mode):
                with open(p, "rb") as f:
                    out[p] = ("file", stat.S_IMODE(st.st_mode), f.read())
            else:
                out[p] = (stat.S_IFMT(st.st_mode), stat.S_IMODE(st.st_mode), st.st_rdev)
    return out


def _changes(before: dict, after: dict) -> set[str]:
    return {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}


def _whole(data: bytes, kind: str) -> bool:
    if kind == "png":
        return data.startswith(PNG_MAGIC) and data.endswith(b"IEND\xaeB`\x82")   # the IEND chunk closes a PNG
    if kind == "html":
        return data.startswith((b"<html>", b"<!DOCTYPE html>")) and data.rstrip().endswith(b"</html>")
    if kind == "lcm":
        return data.startswith(LCM_MAGIC)
    if kind == "bytes":   # the file standing for the library, copied whole
        return data.startswith(b"\x7fELF") and data.endswith(b"\n")
    return len(data) > 20 and data.endswith(b"\n") and b"\0" not in data


class _Setup:
    """The test's folder: out/ (the output folder), a file outside it a link may name, and a
    victim planted links point at."""

    def __init__(self, base: str, case: Case, scenario: str):
        self.work = os.path.join(base, f"{case.id}-{scenario}")
        self.out = os.path.join(self.work, "out")
        os.makedirs(self.out)
        os.chmod(self.work, 0o755)
        self.target = os.path.join(self.out, case.name)          # the path the scenario makes special
        self.arg = self.out if case.folder else self.target      # what -o names
        self.case = case

    def argv(self, inputs):
        return [*self.case.argv(inputs), self.case.option, self.arg]

    def snapshot(self):
        return _snapshot(self.work)

    def check_only(self, before, allowed=()):
        """Nothing changed but ``allowed``, and the regular files a folder verb adds to its folder."""
        after = self.snapshot()
        changed = _changes(before, after) - set(allowed)
        if self.case.folder:
            changed -= {p for p in changed if p not in before and os.path.dirname(p) == self.out
                        and after[p][0] == "file" and not os.path.basename(p).startswith(".")}
        assert not changed, sorted(changed)


# ----------------------------------------------------------------------------- (a) a named pipe

@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_a_named_pipe_is_written_into(base, inputs, no_compile, case):
    s = _Setup(base, case, "fifo")
    os.mkfifo(s.target)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(s.target, "rb").read()), daemon=True)
    reader.start()
    before = s.snapshot()
    proc = cli(*s.argv(inputs), check=False)
    reader.join(1)
    if reader.is_alive():   # never opened for writing: release the reader
        try:
            os.close(os.open(s.target, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:     # ENXIO: no reader any more, it has just read to the end
            pass
    reader.join(10)
    assert proc.returncode == 0, proc.stderr
    assert stat.S_ISFIFO(os.lstat(s.target).st_mode), "the pipe was replaced"
    assert got and _whole(got[0], case.kind), got[:1]
    s.check_only(before)


# ----------------------------------------------------------------------------- (b) a link, and planted links

@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_a_link_stays_a_link_and_planted_links_are_not_followed(base, inputs, no_compile, case):
    s = _Setup(base, case, "link")
    real = os.path.join(s.work, "real.dat")
    with open(real, "wb") as f:
        f.write(b"old\n")
    os.symlink(os.path.join("..", "real.dat"), s.target)    # relative: resolved from the link's folder
    victim = os.path.join(s.work, "victim.dat")
    with open(victim, "wb") as f:
        f.write(b"victim\n")
    pid, name = os.getpid(), os.path.basename(real)
    for folder in (s.out, s.work):                             # beside the link and beside the file it names
        for fake in (f".{name}.{pid}~", f".{name}.{pid}.0.tmp", f"{name}.{pid}.tmp",
                     f".{case.name}.{pid}~", f".{case.name}.{pid}.0.tmp", f"{case.name}.{pid}.tmp"):
            if not os.path.lexists(os.path.join(folder, fake)):
                os.symlink(victim, os.path.join(folder, fake))
    before = s.snapshot()
    proc = cli(*s.argv(inputs), check=False)
    assert proc.returncode == 0, proc.stderr
    assert os.path.islink(s.target) and os.readlink(s.target) == os.path.join("..", "real.dat")
    with open(real, "rb") as f:
        assert _whole(f.read(), case.kind)
    s.check_only(before, allowed={real})


# ----------------------------------------------------------------------------- (c) a full device

@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_a_full_device_is_exit_2_and_stays_a_device(base, inputs, no_compile, case):
    s = _Setup(base, case, "full")
    if os.geteuid() == 0:   # a node of its own (1:7 is /dev/full): a regression never touches the system's
        os.mknod(s.target, 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    else:
        os.symlink("/dev/full", s.target)
    before = s.snapshot()
    proc = cli(*s.argv(inputs), check=False)
    assert proc.returncode == 2, proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith(f"chaincomp {case.verb}: error: {s.target}: cannot write: No space left on device"), line
    if os.geteuid() == 0:
        st = os.lstat(s.target)
        assert stat.S_ISCHR(st.st_mode) and st.st_rdev == os.makedev(1, 7)
    s.check_only(before)   # also: none of a folder verb's other files


# ----------------------------------------------------------------------------- (d) a read-only folder

RUNNER = """
import contextlib, io, json, sys
import chaincomp.cli.build as build_verb
job = json.load(sys.stdin)
build_verb.build = lambda machine: (job["library"], True)   # the copy is tested, not the compiler
from chaincomp.cli.main import main
results = {}
for key, argv in job["argv"].items():
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    results[key] = [code, err.getvalue()]
print(json.dumps(results))
"""


def _nobody():
    if os.geteuid() != 0:
        return None, "a folder's permissions hold for a user other than root; the test drops to nobody as root only"
    if shutil.which("setpriv") is None:
        return None, "setpriv (util-linux) is not installed"
    try:
        return pwd.getpwnam("nobody"), None
    except KeyError:
        return None, "no user nobody"


@pytest.fixture(scope="module")
def read_only_runs(base, inputs):
    """Every case run once, as nobody, in one process, with -o in a read-only folder: the
    setups and each case's (exit code, stderr)."""
    user, reason = _nobody()
    if user is None:
        pytest.skip(reason)
    setups = {}
    for case in CASES:
        s = _Setup(base, case, "readonly")
        os.chmod(s.out, 0o555)
        setups[case.id] = (s, s.snapshot())
    mpl = os.path.join(base, "mplconfig")   # matplotlib's cache, which nobody may write
    os.makedirs(mpl, exist_ok=True)
    os.chmod(mpl, 0o777)
    job = {"library": inputs["library"], "argv": {k: s.argv(inputs) for k, (s, _) in setups.items()}}
    proc = subprocess.run(["setpriv", f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--clear-groups",
                           sys.executable, "-c", RUNNER], input=json.dumps(job), capture_output=True, text=True,
                          cwd=ROOT, env=dict(os.environ, MPLCONFIGDIR=mpl, HOME=base), timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return setups, json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_a_read_only_folder_is_exit_2_naming_the_path(read_only_runs, case):
    setups, results = read_only_runs
    s, before = setups[case.id]
    code, err = results[case.id]
    assert code == 2, err
    line = err.strip().splitlines()[-1]
    assert line.startswith(f"chaincomp {case.verb}: error: ") and s.out in line, err
    assert "Traceback" not in err and "internal error" not in err
    s.check_only(before, allowed=())
    assert os.listdir(s.out) == []
