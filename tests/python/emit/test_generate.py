"""chaincomp generate: determinism and its command line."""

import os
import subprocess
import sys

import pytest

from helpers import BUNDLED, ROOT, machine_path, run_cli


def _generate(out_dir, hash_seed):
    env = dict(os.environ, PYTHONHASHSEED=str(hash_seed))
    subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "generate",
                    *[machine_path(n) for n in BUNDLED], "-o", str(out_dir), "--registry"],
                   check=True, capture_output=True, cwd=ROOT, env=env)
    return {f: (out_dir / f).read_bytes() for f in sorted(os.listdir(out_dir))}


@pytest.mark.slow
def test_generate_is_byte_identical_across_runs(tmp_path):
    # Different hash seeds change set and dict iteration orders that could leak into output.
    first = _generate(tmp_path / "a", 1)
    second = _generate(tmp_path / "b", 12345)
    assert sorted(first) == sorted([f"{n}.{ext}" for n in BUNDLED for ext in ("hpp", "cpp")] + ["registry.cpp", "solvers.cpp"])
    for name in first:
        assert first[name] == second[name], name


@pytest.mark.slow
def test_generated_header_names_its_source_and_hash(tmp_path):
    from chaincomp.emit.cpp import fnv1a64
    run_cli("generate", machine_path("me220_xz"), "-o", str(tmp_path))
    text = (tmp_path / "me220_xz.hpp").read_text()
    with open(machine_path("me220_xz"), "rb") as f:
        want = fnv1a64(f.read())
    # FNV-1a 64 reference value of the empty input and of "a" (published test vectors)
    assert fnv1a64(b"") == 0xCBF29CE484222325 and fnv1a64(b"a") == 0xAF63DC4C8601EC8C
    assert "Do not edit" in text.splitlines()[0] and "me220_xz.yaml" in text.splitlines()[0]
    assert f"0x{want:016x}ull" in text


@pytest.mark.slow
def test_generate_bad_input(tmp_path):
    proc = run_cli("generate", machine_path("me220_xz"), "-o", str(tmp_path), "--order", "0", check=False)
    assert proc.returncode == 2 and "--order: must be between 1 and 4, got 0" in proc.stderr
    blocker = tmp_path / "file"
    blocker.write_text("")
    proc = run_cli("generate", machine_path("me220_xz"), "-o", str(blocker / "sub"), check=False)
    assert proc.returncode == 2 and "cannot create output folder" in proc.stderr
    proc = run_cli("generate", machine_path("me220_xz"), machine_path("me220_xz"), "-o", str(tmp_path),
                   check=False)
    assert proc.returncode == 2 and "share the name 'me220_xz'" in proc.stderr


def test_bundled_machine_names_match_file_names():
    # the build generates NAME.hpp per configs/machines/NAME.yaml
    from chaincomp import load_machine
    for name in BUNDLED:
        assert load_machine(machine_path(name)).name == name


@pytest.mark.slow
def test_long_chain_straight_line_code_is_byte_identical_across_runs(tmp_path):
    """The benchmark UR5 (past the expansion limit: the straight-line emitter) under two hash seeds."""
    outs = []
    for seed in (1, 4242):
        out = tmp_path / str(seed)
        env = dict(os.environ, PYTHONHASHSEED=str(seed))
        subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "generate",
                        os.path.join(ROOT, "tools", "bench_machines", "ur5.yaml"), "-o", str(out)],
                       check=True, capture_output=True, cwd=ROOT, env=env)
        outs.append({f: (out / f).read_bytes() for f in sorted(os.listdir(out))})
    assert outs[0] == outs[1] and sorted(outs[0]) == ["ur5.cpp", "ur5.hpp"]


@pytest.mark.slow
def test_a_write_that_fails_midway_leaves_the_old_header_whole(tmp_path):
    """A file size limit of 3 kB (RLIMIT_FSIZE, as a full disk would): before, generate exited 2
    but left the first 3000 bytes of the header, which a build then read as the model."""
    import resource
    import signal

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (3000, 3000))
    out = tmp_path / "gen"
    out.mkdir()
    (out / "me220_xz.hpp").write_text("old\n")
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "generate", machine_path("me220_xz"), "-o",
                           str(out)], capture_output=True, text=True, cwd=ROOT, preexec_fn=limit)
    assert proc.returncode == 2 and "cannot write" in proc.stderr and "File too large" in proc.stderr, proc.stderr
    assert (out / "me220_xz.hpp").read_text() == "old\n"
    assert not [f for f in os.listdir(out) if f.startswith(".")]   # no temporary file left
    new = tmp_path / "new" / "gen"   # folders it created for a write that failed: removed again
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "generate", machine_path("me220_xz"), "-o",
                           str(new)], capture_output=True, text=True, cwd=ROOT, preexec_fn=limit)
    assert proc.returncode == 2 and "File too large" in proc.stderr, proc.stderr
    assert not (tmp_path / "new").exists()
