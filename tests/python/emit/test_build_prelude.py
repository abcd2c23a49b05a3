"""chaincomp build's precompiled headers (build.py's prelude): GCC takes them for a model's
compile (by GCC's own account: `-H` marks a precompiled header it used with "!", one it
refused with "x"), a model compiled with them computes what one compiled without computes, a
prelude.hpp.gch altered since it was built is made again, and a compiler that reads no .gch
(clang) compiles without one."""

import dataclasses
import os
import struct
import subprocess

from chaincomp.emit import build
from test_build import chaincomp, variant


def test_gcc_takes_the_precompiled_headers_and_the_model_is_the_same(tmp_path):
    tc = build.toolchain()
    header = build.prelude(tc, str(tmp_path / "cache"), "test")
    assert header is not None and os.path.isfile(header + ".gch")
    machine = variant(str(tmp_path), "prelude_trunnion")
    gen = tmp_path / "gen"
    assert chaincomp(os.environ, "generate", machine, "-o", str(gen)).returncode == 0
    base = [tc.compiler, *tc.flags, "-DCHAINCOMP_PREBUILT_CORE", *(f"-I{d}" for d in tc.include_dirs), f"-I{gen}"]
    cpp = str(gen / "prelude_trunnion.cpp")
    used = subprocess.run([*base, *build.prelude_flags(header), "-H", "-fsyntax-only", cpp],
                          capture_output=True, text=True)
    assert used.returncode == 0, used.stderr
    assert f"! {header}.gch" in used.stderr, used.stderr[:2000]

    # the same code: the objects compiled with and without hold the same machine code
    texts = []
    for flags in (build.prelude_flags(header), []):
        obj = tmp_path / "model.o"
        subprocess.run([*base, *flags, "-c", cpp, "-o", str(obj)], check=True)
        texts.append(_text(obj.read_bytes()))
    assert texts[0] == texts[1] and len(texts[0]) > 1000


def _text(elf: bytes) -> bytes:
    """The .text section's bytes of an ELF64 object (the ELF64 layout: section headers at e_shoff,
    their names in section e_shstrndx): its machine code."""
    shoff, = struct.unpack_from("<Q", elf, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", elf, 0x3A)
    sections = [struct.unpack_from("<IIQQQQ", elf, shoff + i * shentsize) for i in range(shnum)]
    names_off = sections[shstrndx][4]
    for name, _, _, _, off, size in sections:
        end = elf.index(b"\0", names_off + name)
        if elf[names_off + name:end] == b".text":
            return elf[off:off + size]
    raise AssertionError("no .text")


def test_an_altered_precompiled_header_is_made_again(tmp_path):
    tc = build.toolchain()
    root = str(tmp_path / "cache")
    header = build.prelude(tc, root, "test")
    gch = header + ".gch"
    with open(gch, "r+b") as f:
        f.seek(1000)
        f.write(b"\xff" * 16)
    assert build.prelude(tc, root, "test") == header
    assert build.intact(gch)


def test_a_compiler_that_reads_no_gch_compiles_without(tmp_path):
    tc = dataclasses.replace(build.toolchain(), version="Debian clang version 14.0.6")
    assert build.prelude(tc, str(tmp_path), "test") is None
    assert build.prelude_flags(None) == []
    assert not os.listdir(tmp_path)
