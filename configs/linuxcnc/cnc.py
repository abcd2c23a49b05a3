"""Runs chaincomp's LinuxCNC configurations headless and reads what the simulated machine did
(used by tests/python/runtime/test_linuxcnc.py and tools/linuxcnc-demo).

run() copies a configuration (configs/linuxcnc/NAME/) to a fresh work folder, writes the NML
file without its TCP socket, picks the route (off | rt | bridge | comp | matrixkins), and runs LinuxCNC once as an
unprivileged user (it refuses root), one instance at a time (a lock: LinuxCNC's shared memory
keys are fixed). Its driver (drive.py) records every servo period with halsampler: the joint
commands and the correction the drives actually got (drive - command).

The simulated *true machine* is the machine file's exact model with a params file: the
actual tool pose at the drive positions, against the nominal pose at the commands (what the
program asked for). tool_errors() evaluates it on every recorded period.
"""

from __future__ import annotations

import fcntl
import glob
import json
import os
import pwd
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
USER = os.environ.get("CHAINCOMP_LINUXCNC_USER", "chaincomp-cnc")
LOCK = os.path.join(tempfile.gettempdir(), "chaincomp-linuxcnc.lock")
NML = "/usr/share/linuxcnc/linuxcnc.nml"
ROUTES = ("off", "rt", "bridge", "comp", "matrixkins")
MODULES = "/usr/lib/linuxcnc/modules"
# sampler.0 columns after halsampler's tag: 5 commands and 5 observed corrections (drive -
# command), both in nm and udeg, then the bridge's age-ms or chaincomp_rt's cost-ns, stale, fault
N_JOINTS = 5
COL_CMD, COL_OBS, COL_AGE, COL_STALE, COL_FAULT = 1, 6, 11, 12, 13
COL_COST = COL_AGE
COL_MC_CLOCKS, COL_RT_CLOCKS = 14, 15  # five_axis_ac's rt route: motion-controller.time, chaincomp-rt.update.time
COL_CART = 14  # trunnion_ac: axis.L.pos-cmd * 1e6, L = x y z a c
COL_POS_CMD = 16  # five_axis_ac: joint.N.pos-cmd * 1e6, before LinuxCNC's own compensation (comp route)


def unavailable() -> str | None:
    """Why LinuxCNC cannot run here, or None."""
    if shutil.which("linuxcnc") is None or not os.path.exists(NML):
        return "LinuxCNC is not installed (tools/setup-linuxcnc installs linuxcnc-uspace)"
    if os.geteuid() == 0:
        try:
            pwd.getpwnam(USER)
        except KeyError:
            return f"no user {USER!r} to run LinuxCNC as (it refuses root): run tools/setup-linuxcnc"
    if shutil.which("halsampler") is None:
        return "halsampler is missing (linuxcnc-uspace)"
    return None


def matrixkins_unavailable() -> str | None:
    """Why the matrixkins route cannot run here, or None: the kinematics module came with
    LinuxCNC 2.10 (src/hal/components/matrixkins.comp); Debian's 2.9 has none."""
    if not os.path.exists(os.path.join(MODULES, "matrixkins.so")):
        return f"this LinuxCNC has no matrixkins ({MODULES}/matrixkins.so: it came with LinuxCNC 2.10, Debian has 2.9)"
    return None


WORD = r"\s*([+-]?\s*(?:\d+\.?\d*|\.\d+))"   # an RS274NGC word's number (spaces allowed)


def without_c_moves(program: str) -> str:
    """The program with C held at 0: matrixkins passes joint 4 through as B, not C, so on this
    XYZAC configuration only a program that leaves C at 0 means the same thing."""
    def code(line: str) -> str:   # the words before a comment
        head, paren, rest = line.partition("(")
        return re.sub(r"(?i)C" + WORD, "C0", head) + paren + rest
    return "\n".join(code(line) for line in program.split("\n"))


def program_points(program: str, letters: str = "XYZAC") -> np.ndarray:
    """The points a program's G0/G1 moves go to, one row per move (mm, deg): where its dwells are."""
    rows = []
    for line in program.splitlines():
        if re.match(r"(?i)\s*G\s*0?[01](?!\d)", line):
            rows.append([float(re.search(rf"(?i){c}" + WORD, line).group(1).replace(" ", "")) for c in letters])
    return np.array(rows, float)


def matrixkins_at_dwells(run, machine, params, values, c, program: str) -> tuple[float, float]:
    """A matrixkins run against chaincomp's replay of its C, at each of the program's dwells:
    the largest |joints - C . point| (mm; the G-code's own points, not read back from
    LinuxCNC) and |measured - predicted| tool error (mm: the true machine at the drives,
    against the exact model at C . point)."""
    from chaincomp.analysis import export as X

    exact, lin, points = X.ExactModel(machine), machine.axes[:3], program_points(program)
    joints_off = tool_off = 0.0
    for s, point in zip(dwells(run.pos_commands)[-len(points):], points):
        joints = run.drives[s]
        joints_off = max(joints_off, float(np.abs(joints[:, :3] - c @ point[:3]).max()),
                         float(np.abs(joints[:, 3:] - point[3:]).max()))
        programmed = np.broadcast_to(point, joints.shape)
        measured, _ = tool_errors(machine, params, programmed, joints)
        q = to_internal(machine, programmed)
        predicted = X.tool_error(exact, values, q, X.apply_matrix(lin, c, q)).T
        tool_off = max(tool_off, float(np.abs(measured - predicted).max()))
    return joints_off, tool_off


@dataclass
class Run:
    work: str            # the work folder (kept: logs, samples, events)
    samples: np.ndarray  # one row per servo period (see COL_*)
    events: list         # the driver's timeline
    log: str             # LinuxCNC's output
    returncode: int
    route: str = ""

    @property
    def commands(self) -> np.ndarray:
        """joint.N.motor-pos-cmd, LinuxCNC units (mm, deg)."""
        return self.samples[:, COL_CMD:COL_CMD + N_JOINTS] * 1e-6

    @property
    def pos_commands(self) -> np.ndarray:
        """joint.N.pos-cmd (five_axis_ac): the commands before LinuxCNC's own compensation
        ([JOINT_n]COMP_FILE), which motor-pos-cmd (commands) includes."""
        return self.samples[:, COL_POS_CMD:COL_POS_CMD + N_JOINTS] * 1e-6

    @property
    def corrections(self) -> np.ndarray:
        """drive - command per joint, LinuxCNC units (mm, deg)."""
        return self.samples[:, COL_OBS:COL_OBS + N_JOINTS] * 1e-6

    @property
    def drives(self) -> np.ndarray:
        return self.commands + self.corrections

    @property
    def lag_ms(self) -> np.ndarray:
        """The bridge's lag at every period: the age of the applied target. Its age-ms pin is
        written when the bridge's loop runs; while the loop stalls the pin stands still and
        the real age grows by a period a row."""
        age = self.samples[:, COL_AGE]
        rows = np.arange(len(age))
        changed = np.r_[True, np.diff(age) != 0]
        return age + (rows - np.maximum.accumulate(np.where(changed, rows, 0)))


def run(route: str, config: str = "five_axis_ac", env: dict | None = None, timeout: float = 120.0,
        work: str | None = None, params: str | None = None, stale_ms: float = 50.0,
        program: str | None = None, comp: dict[int, str] | None = None, matrixkins: str | None = None,
        route_hal: str = "", after_hal: str = "") -> Run:
    """One run of the configuration's program. `env`: the driver's settings (drive.py);
    `params`: the bridge's chaincompd params (default the machine's demo params); `stale_ms`:
    the bridge's stale age; `program`: G-code text in place of the configuration's program.ngc;
    `comp` (route comp): joint number -> its COMP_FILE (type 1, chaincomp export's);
    `matrixkins` (route matrixkins): chaincomp export's HAL file of C_xx..C_zz, sourced after
    route-off.hal, with KINEMATICS = matrixkins in place of trivkins; `route_hal`: HAL text added to
    the route's file (its functions run before the drives are computed); `after_hal`: HAL text
    run last (after record.hal: its functions see each period's drive positions)."""
    if route not in ROUTES:
        raise ValueError(f"route {route!r}: expected one of {', '.join(ROUTES)}")
    if (route == "comp") != bool(comp):
        raise ValueError("the comp route takes comp files (comp={joint: file}), and only it")
    if (route == "matrixkins") != bool(matrixkins):
        raise ValueError("the matrixkins route takes the exporter's HAL file (matrixkins=path), and only it")
    src = os.path.join(HERE, config)
    work = work or tempfile.mkdtemp(prefix=f"chaincomp-cnc-{config}-{route}-")
    for f in glob.glob(os.path.join(src, "*")) + [os.path.join(HERE, "drive.py")]:
        shutil.copy(f, work)
    shutil.copy(os.path.join(src, f"route-{'off' if route == 'matrixkins' else route}.hal"),
                os.path.join(work, "route.hal"))
    if matrixkins:
        with open(matrixkins) as f, open(os.path.join(work, "route.hal"), "a") as out:
            out.write("\n" + f.read())
        ini = os.path.join(work, f"{config}.ini")
        with open(ini) as f:
            text = f.read()
        text, n = re.subn(r"(?m)^KINEMATICS = .*$", "KINEMATICS = matrixkins", text)
        if n != 1:
            raise ValueError(f"{ini}: expected one KINEMATICS line, found {n}")
        with open(ini, "w") as f:
            f.write(text)
    with open(os.path.join(work, "route.hal"), "a") as f:
        f.write("\n" + route_hal)
    if after_hal:
        with open(os.path.join(work, "after.hal"), "w") as f:
            f.write(after_hal)
        _add_halfile(os.path.join(work, f"{config}.ini"), "after.hal")
    if program is not None:
        with open(os.path.join(work, "program.ngc"), "w") as f:
            f.write(program)
    params = os.path.abspath(params or os.path.join(ROOT, "configs", "params", f"{config}-demo.yaml"))
    if comp:
        _add_comp_files(os.path.join(work, f"{config}.ini"), comp, work)
    with open(os.path.join(work, f"{config}.ini"), "a") as f:  # what the HAL files read as [CHAINCOMP]KEY
        f.write(f"\n[CHAINCOMP]\nROOT = {ROOT}\nPARAMS = {params}\nSTALE_MS = {stale_ms!r}\n")
    with open(NML) as f:
        nml = f.read().replace(" TCP=5005", "")  # no socket at all
    with open(os.path.join(work, "linuxcnc.nml"), "w") as f:
        f.write(nml)
    # HOME: LinuxCNC writes linuxcnc_print.txt and linuxcnc_debug.txt there
    cmd = ["env", "-u", "DISPLAY", f"HOME={work}", *(f"{k}={v}" for k, v in (env or {}).items()), "linuxcnc",
           os.path.join(work, f"{config}.ini")]
    if os.geteuid() == 0:
        pw = pwd.getpwnam(USER)
        # the HAL components run from this checkout as that user
        probe = subprocess.run(["runuser", "-u", USER, "--", "test", "-x", os.path.join(ROOT, ".venv", "bin", "python"),
                                "-a", "-r", os.path.join(HERE, "drive.py")], capture_output=True)
        if probe.returncode != 0:
            raise RuntimeError(f"user {USER!r} cannot read this checkout ({ROOT}) and its .venv: LinuxCNC's HAL "
                               "components run from it as that user; give others read and search access along "
                               "the path (chmod o+rx)")
        for dirpath, _, files in os.walk(work):
            os.chown(dirpath, pw.pw_uid, pw.pw_gid)
            for name in files:
                os.chown(os.path.join(dirpath, name), pw.pw_uid, pw.pw_gid)
        cmd = ["runuser", "-u", USER, "--", *cmd]
    with open(LOCK, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one LinuxCNC at a time
        proc = subprocess.run(cmd, cwd=work, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              timeout=timeout)
    log = proc.stdout + proc.stderr
    try:  # LinuxCNC's own output goes to ~/linuxcnc_print.txt
        with open(os.path.join(work, "linuxcnc_print.txt"), errors="replace") as f:
            log += f.read()
    except OSError:
        pass
    samples_path = os.path.join(work, "samples.txt")
    rows = np.loadtxt(samples_path, ndmin=2) if os.path.exists(samples_path) and os.path.getsize(samples_path) \
        else np.zeros((0, COL_CART + 5))
    events = []
    if os.path.exists(os.path.join(work, "events.txt")):
        with open(os.path.join(work, "events.txt")) as f:
            events = [json.loads(line) for line in f if line.strip()]
    return Run(work, rows, events, log, proc.returncode, route)


def _add_halfile(ini: str, name: str) -> None:
    """One more [HAL]HALFILE, after the last one."""
    with open(ini) as f:
        lines = f.read().splitlines()
    last = max(i for i, line in enumerate(lines) if line.startswith("HALFILE ="))
    lines.insert(last + 1, f"HALFILE = {name}")
    with open(ini, "w") as f:
        f.write("\n".join(lines) + "\n")


def _add_comp_files(ini: str, comp: dict[int, str], work: str) -> None:
    """[JOINT_n]COMP_FILE and COMP_FILE_TYPE = 1 into the INI's joint sections (a second
    section of the same name would not be read), each file copied into the work folder."""
    with open(ini) as f:
        lines = f.read().splitlines()
    out = []
    for line in lines:
        out.append(line)
        for n, path in comp.items():
            if line.strip() == f"[JOINT_{n}]":
                name = f"joint{n}.comp"
                shutil.copy(path, os.path.join(work, name))
                out += [f"COMP_FILE = {name}", "COMP_FILE_TYPE = 1"]
    with open(ini, "w") as f:
        f.write("\n".join(out) + "\n")


def to_internal(machine, joints: np.ndarray) -> dict:
    """LinuxCNC joint values (mm, deg; columns in the machine's axis order) as the exact
    model's inputs (mm, rad)."""
    out = {}
    for i, a in enumerate(machine.axes):
        out[a.name] = joints[:, i] * (np.pi / 180.0 if a.unit.kind == "angle" else 1.0)
    return out


def tool_errors(machine, params: dict, commands: np.ndarray, drives: np.ndarray):
    """The true machine on every row: actual tool point (the exact model with `params` at the
    drive positions) minus the programmed one (the nominal model at the commands), mm, and
    the same for the tool direction (rad), as arrays (rows, 3)."""
    from chaincomp import ExactModel

    exact = ExactModel(machine)
    p_act, d_act = exact.pose({**params, **to_internal(machine, drives)})
    p_nom, d_nom = exact.pose(to_internal(machine, commands))
    point = np.stack([np.asarray(a) - np.asarray(b) for a, b in zip(p_act, p_nom)], axis=1)
    direction = np.stack([np.asarray(a) - np.asarray(b) for a, b in zip(d_act, d_nom)], axis=1) if d_act else None
    return point, direction


def dwells(commands: np.ndarray, min_rows: int = 300, skip: int = 30, tail: int = 0) -> list[slice]:
    """Stretches where every joint command stands still for at least `min_rows` periods (the
    program's G4 dwells and the end), without their first `skip` rows (the bridge's
    correction catches up there) and their last `tail`."""
    still = np.r_[False, np.all(np.abs(np.diff(commands, axis=0)) < 1e-9, axis=1)]
    out, start = [], None
    for i, s in enumerate(np.r_[still, False]):
        if s and start is None:
            start = i
        elif not s and start is not None:
            if i - start >= min_rows:
                out.append(slice(start + skip, i - tail))
            start = None
    return out
