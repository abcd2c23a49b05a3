"""chaincomp_replay run directly writes its --out log and --csv by the one writer's rules
(runtime/include/chaincomp/output_file.hpp, the same as chaincomp.output's; issue #38 item 2):

(a) a named pipe is written into (a reader drains it), never replaced by a regular file;
(b) through a symbolic link the file it names gets the content and the link stays a link;
(c) a full device (a node like /dev/full, 1:7, made here as root; else a link to /dev/full):
    exit 2 "No space left on device", the node untouched, nothing else written;
(d) a read-only folder, run as the user nobody (setpriv; as root only): exit 2, one line naming
    the path, nothing left in the folder;
(e) a failure leaves the old file whole: no temporary file, no half-written output.

The truth is POSIX's: a rename replaces a link or a pipe by a regular file, /dev/full refuses
every write with ENOSPC, and a folder without write permission refuses a new file with EACCES.
Every event of a log starts with lcm-logger's sync word (lcm/eventlog.c), and the CSV's header
is the replay's documented one (docs/guide/daemon.md)."""

from __future__ import annotations

import os
import pwd
import shutil
import stat
import subprocess
import tempfile
import threading

import pytest

from helpers import PARAMS, ROOT, machine_path, run_cli

REPLAY = os.path.join(ROOT, "build", "bin", "chaincomp_replay")
FIVE = machine_path("five_axis_ac")
FIVE_PARAMS = os.path.join(PARAMS, "five_axis_ac-demo.yaml")
LCM_MAGIC = bytes.fromhex("EDA1DA01")

pytestmark = pytest.mark.skipif(not os.path.exists(REPLAY), reason="build/bin/chaincomp_replay not built")


@pytest.fixture(scope="module")
def work():
    """A folder everyone may enter (pytest's own is root's alone), with a log of commands."""
    path = tempfile.mkdtemp(prefix="chaincomp-replay-writes-")
    os.chmod(path, 0o755)
    log = os.path.join(path, "in.lcmlog")
    run_cli("simulate-log", FIVE, "-o", log, "--seconds", "0.01")
    os.chmod(log, 0o644)
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def out(work, request):
    """An empty folder for one test's outputs, inside work."""
    path = os.path.join(work, request.node.name.replace("[", "-").replace("]", ""))
    os.mkdir(path)
    os.chmod(path, 0o755)
    return path


def replay(work, *outputs, user=None):
    argv = [REPLAY, "--machine", FIVE, "--params", FIVE_PARAMS, "--in", os.path.join(work, "in.lcmlog"), "--quiet",
            *outputs]
    if user is not None:
        argv = ["setpriv", f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--clear-groups", *argv]
    return subprocess.run(argv, capture_output=True, timeout=120)


def snapshot(folder: str) -> dict:
    out = {}
    for n in os.listdir(folder):
        p = os.path.join(folder, n)
        st = os.lstat(p)
        if stat.S_ISLNK(st.st_mode):
            out[n] = ("link", os.readlink(p))
        elif stat.S_ISREG(st.st_mode):
            with open(p, "rb") as f:
                out[n] = ("file", stat.S_IMODE(st.st_mode), f.read())
        else:
            out[n] = (stat.S_IFMT(st.st_mode), st.st_rdev)
    return out


def one_error(proc, path, words):
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.decode().strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("chaincomp replay: error: "), lines
    assert path in lines[0] and words in lines[0], lines[0]


def whole_csv(data: bytes) -> bool:
    text = data.decode()
    return text.startswith("event,utime,seq,result,commanded_X_mm") and text.endswith("\n") and text.count("\n") > 5


def whole_log(data: bytes) -> bool:
    return data.startswith(LCM_MAGIC) and data.count(LCM_MAGIC) > 5


@pytest.mark.parametrize("option,whole", [("--csv", whole_csv), ("--out", whole_log)])
def test_a_pipe_is_written_into(work, out, option, whole):
    fifo = os.path.join(out, "pipe")
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    proc = replay(work, option, fifo)
    reader.join(timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert whole(got[0])
    assert sorted(os.listdir(out)) == ["pipe"]


@pytest.mark.parametrize("option,whole", [("--csv", whole_csv), ("--out", whole_log)])
def test_a_link_stays_a_link_and_its_file_gets_the_content(work, out, option, whole):
    real = os.path.join(out, "real")
    with open(real, "wb") as f:
        f.write(b"old")
    os.chmod(real, 0o640)
    os.symlink("real", os.path.join(out, "link"))
    proc = replay(work, option, os.path.join(out, "link"))
    assert proc.returncode == 0, proc.stderr
    assert os.readlink(os.path.join(out, "link")) == "real"
    with open(real, "rb") as f:
        assert whole(f.read())
    assert stat.S_IMODE(os.stat(real).st_mode) == 0o640   # the old file's permissions kept
    assert sorted(os.listdir(out)) == ["link", "real"]


def full_device(out: str) -> str:
    path = os.path.join(out, "full")
    if os.geteuid() == 0:
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    else:
        os.symlink("/dev/full", path)
    return path


@pytest.mark.parametrize("option", ["--csv", "--out"])
def test_a_full_device_is_exit_2_and_stays(work, out, option):
    full = full_device(out)
    other = os.path.join(out, "other")
    with open(other, "wb") as f:
        f.write(b"old")
    before = snapshot(out)
    proc = replay(work, option, full, "--out" if option == "--csv" else "--csv", other)
    one_error(proc, full, "No space left on device")
    assert snapshot(out) == before   # the device, and the other output left whole: nothing in place


def test_a_new_file_appears_whole_with_the_umask_mode(work, out):
    proc = replay(work, "--csv", os.path.join(out, "a.csv"), "--out", os.path.join(out, "a.lcmlog"))
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(out)) == ["a.csv", "a.lcmlog"]
    mask = os.umask(0)
    os.umask(mask)
    for name in ("a.csv", "a.lcmlog"):
        assert stat.S_IMODE(os.stat(os.path.join(out, name)).st_mode) == 0o666 & ~mask


def test_a_read_only_folder_is_exit_2_naming_the_path(work, out):
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("a folder's permissions hold for a user other than root; the test drops to nobody as root only")
    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        pytest.skip("no user nobody")
    with open(os.path.join(out, "old.csv"), "wb") as f:
        f.write(b"old")
    os.chmod(os.path.join(out, "old.csv"), 0o666)   # nobody may write the file, not the folder
    os.chmod(out, 0o555)
    try:
        before = snapshot(out)
        for option, name in (("--csv", "new.csv"), ("--out", "new.lcmlog"), ("--csv", "old.csv")):
            path = os.path.join(out, name)
            proc = replay(work, option, path, user=nobody)
            one_error(proc, path, "Permission denied")
            assert snapshot(out) == before
    finally:
        os.chmod(out, 0o755)
