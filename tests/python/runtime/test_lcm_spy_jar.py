"""build/java/chaincomp_lcmtypes.jar: lcm-spy's own type database (lcm.spy.LCMTypeDatabase, which
finds LCM types on the CLASSPATH by fingerprint) finds chaincomp's types in it, and they decode
messages the Python bindings encoded, field for field, and encode them back byte for byte.
A tiny Java program is compiled here against the jar and the lcm wheel's lcm.jar."""

import os
import shutil
import subprocess
import struct

import pytest

from helpers import ROOT

JAR = os.path.join(ROOT, "build", "java", "chaincomp_lcmtypes.jar")
SHARE = os.path.join(ROOT, ".venv", "lib", "python3.11", "site-packages", "share", "java")
LCM_JAR = os.path.join(SHARE, "lcm.jar")
SPY = os.path.join(ROOT, "tools", "lcm-spy")

pytestmark = [
    pytest.mark.skipif(not (shutil.which("javac") and shutil.which("java")), reason="no JDK (javac, java)"),
    pytest.mark.skipif(not os.path.isfile(JAR), reason=f"{JAR} not built (cmake --build build --target "
                                                         "chaincomp_lcmtypes_jar)"),
    pytest.mark.skipif(not os.path.isfile(LCM_JAR), reason=f"no {LCM_JAR} (the lcm wheel)"),
]

DECODE = r"""
import java.io.*;
import java.lang.reflect.Field;
import java.nio.file.*;

public class Decode {
    // As lcm-spy does: the type from the fingerprint through its type database, then the
    // constructor from a DataInput; print every public field, and encode it back.
    public static void main(String[] args) throws Exception {
        lcm.spy.LCMTypeDatabase db = new lcm.spy.LCMTypeDatabase();
        for (String path : args) {
            byte[] data = Files.readAllBytes(Paths.get(path));
            long fingerprint = new DataInputStream(new ByteArrayInputStream(data)).readLong();
            Class<?> cls = db.getClassByFingerprint(fingerprint);
            System.out.println("type=" + (cls == null ? "none" : cls.getName()));
            if (cls == null) continue;
            Object msg = cls.getConstructor(DataInput.class).newInstance(
                new DataInputStream(new ByteArrayInputStream(data)));
            for (Field f : cls.getFields()) {
                if (java.lang.reflect.Modifier.isStatic(f.getModifiers())) continue;
                Object v = f.get(msg);
                String text = v instanceof double[] ? java.util.Arrays.toString((double[]) v)
                            : v instanceof long[] ? java.util.Arrays.toString((long[]) v) : String.valueOf(v);
                System.out.println(f.getName() + "=" + text);
            }
            ByteArrayOutputStream out = new ByteArrayOutputStream();
            ((lcm.lcm.LCMEncodable) msg).encode(new DataOutputStream(out));
            System.out.println("same_bytes=" + java.util.Arrays.equals(out.toByteArray(), data));
        }
    }
}
"""


@pytest.fixture(scope="module")
def decoder(tmp_path_factory):
    d = tmp_path_factory.mktemp("java")
    (d / "Decode.java").write_text(DECODE)
    # lcm-spy's class path: lcm.jar and the chart libraries beside it (its type scan loads them)
    cp = ":".join([JAR] + sorted(os.path.join(SHARE, f) for f in os.listdir(SHARE)
                                 if f.endswith(".jar") and f != "lcm-sources.jar"))
    subprocess.run(["javac", "-nowarn", "-cp", cp, "-d", str(d), str(d / "Decode.java")], check=True,
                   capture_output=True, text=True)

    def run(*paths):
        proc = subprocess.run(["java", "-Djava.awt.headless=true", "-cp", f"{d}:{cp}", "Decode", *map(str, paths)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        blocks, cur = [], None
        for line in proc.stdout.splitlines():
            key, _, value = line.partition("=")
            if cur is None and key != "type":
                continue            # anything the type scan prints before
            if key == "type":
                cur = {}
                blocks.append(cur)
            cur[key] = value
        return blocks
    return run


def _doubles(text):
    return [float(v) for v in text.strip("[]").split(",")]


@pytest.mark.slow
def test_jar_decodes_a_corrected_target_and_a_status(decoder, tmp_path):
    from chaincomp.emit.buildtree import import_lcmtypes
    T = import_lcmtypes()
    t = T.lcmt_corrected_target()
    t.utime, t.seq, t.num_axes = 1_700_000_000_123_456, 42, 5
    t.axes = [100.25, -3.5e-3, 1e-300, 45.0, -179.999, 0.0, 0.0, 7.0]
    t.correction = [1.5e-3, -2.25e-4, 0.0, 3e-5, 0.0, 0.0, 0.0, -0.0]
    t.residual_point, t.residual_direction = 2.5e-7, 1.25e-9
    t.flags = T.lcmt_corrected_target.FLAG_COMPENSATING | T.lcmt_corrected_target.FLAG_CLAMPED
    t.status, t.compute_ns, t.instance_id, t.machine = 1, 12_345, -987_654_321_012, "five_axis_ac"
    s = T.lcmt_chaincomp_status()
    s.received, s.rejected, s.final, s.machine = 1000, [0, 1, 2, 3, 4, 5, 6, 7, 8], True, "vmc_xyz"
    s.targets_partial, s.objective_before, s.direction_weight = 7, 2.5e-5, 100.0
    s.queue_dropped, s.control_queue_dropped, s.targets_queue_dropped, s.oversized = 40, 5, 3, 4
    s.lcm_queue_capacity, s.lcm_queue_full = 100000, 2
    (tmp_path / "t.bin").write_bytes(t.encode())
    (tmp_path / "s.bin").write_bytes(s.encode())
    got_t, got_s = decoder(tmp_path / "t.bin", tmp_path / "s.bin")
    assert got_t["type"] == "chaincomp_lcm.lcmt_corrected_target"
    assert int(got_t["utime"]) == t.utime and int(got_t["seq"]) == 42 and int(got_t["num_axes"]) == 5
    assert _doubles(got_t["axes"]) == t.axes            # Java prints the shortest round-trip digits
    assert _doubles(got_t["correction"]) == t.correction
    assert float(got_t["residual_point"]) == t.residual_point
    assert float(got_t["residual_direction"]) == t.residual_direction
    assert int(got_t["flags"]) == 5 and int(got_t["status"]) == 1
    assert int(got_t["compute_ns"]) == 12_345 and int(got_t["instance_id"]) == t.instance_id
    assert got_t["machine"] == "five_axis_ac"
    assert got_t["same_bytes"] == "true"
    # lcmt_chaincomp_status's field 'final' is a Java keyword: final_ in the jar, same wire format
    assert got_s["type"] == "chaincomp_lcm.lcmt_chaincomp_status"
    assert got_s["final_"] == "true" and int(got_s["received"]) == 1000
    assert got_s["rejected"] == "[0, 1, 2, 3, 4, 5, 6, 7, 8]" and got_s["machine"] == "vmc_xyz"
    assert int(got_s["targets_partial"]) == 7 and float(got_s["objective_before"]) == 2.5e-5
    assert float(got_s["direction_weight"]) == 100.0
    assert [int(got_s[k]) for k in ("queue_dropped", "control_queue_dropped", "targets_queue_dropped", "oversized",
                                    "lcm_queue_capacity", "lcm_queue_full")] == [40, 5, 3, 4, 100000, 2]
    assert got_s["same_bytes"] == "true"


@pytest.mark.slow
def test_a_message_of_another_type_is_not_taken_for_ours(decoder, tmp_path):
    from chaincomp.emit.buildtree import import_lcmtypes
    data = bytearray(import_lcmtypes().lcmt_corrected_target().encode())
    data[:8] = struct.pack(">q", 0x0123456789ABCDEF)     # a fingerprint no type of ours has
    (tmp_path / "x.bin").write_bytes(bytes(data))
    assert decoder(tmp_path / "x.bin") == [{"type": "none"}]


@pytest.mark.parametrize("args,match", [
    ([], "--url URL is needed"),
    (["--url", "memq://"], "memq:// is in-process"),
    (["--lcm-url=udpm://239.255.76.67:7667"], "give the URL with --url"),
])
def test_lcm_spy_script_refuses_without_a_usable_url(args, match):
    proc = subprocess.run([SPY, *args], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2 and match in proc.stderr, proc.stderr


@pytest.mark.slow
def test_lcm_spy_finds_every_type_of_ours():
    """The wheel's own lcm-spy with the jar on its CLASSPATH (as tools/lcm-spy starts it) reports
    the types it found before it opens its window; without a display it stops there, before it
    creates its LCM (lcm.spy.Spy builds the window first), so nothing is ever sent."""
    import glob
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["CLASSPATH"] = JAR
    proc = subprocess.run([os.path.join(ROOT, ".venv", "bin", "lcm-spy"), "--lcm-url=memq://"], env=env,
                          capture_output=True, text=True, timeout=120)
    types = len(glob.glob(os.path.join(ROOT, "runtime", "lcmtypes", "*.lcm")))
    assert f"Found {types} LCM types" in proc.stdout, proc.stdout[-2000:]


def test_lcm_spy_script_needs_a_display():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run([SPY, "--url", "udpm://239.255.76.67:7667?ttl=0"], env=env, capture_output=True,
                          text=True, timeout=30)
    assert proc.returncode == 2 and "no display" in proc.stderr, proc.stderr


def test_lcm_spy_script_help():
    proc = subprocess.run([SPY, "--help"], capture_output=True, text=True, timeout=30)
    text = " ".join(proc.stdout.split())
    assert proc.returncode == 0 and "--url" in text and "inside the daemon's network namespace" in text
