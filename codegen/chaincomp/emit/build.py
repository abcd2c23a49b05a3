"""Models built at run time (design §10): a machine's generated C++ compiled into a shared
library with one C entry point (``chaincomp_model_library``, runtime's model_library.hpp),
cached by content hash for chaincompd and replay to ``dlopen``.

The compiler, flags and ABI come from the C++ build's ``model_build.json`` (written by
runtime/CMakeLists.txt, which also compiles them into the loader), so this module and the
loader compute the same cache key: the machine file's content, the ABI version, the
compiler's ``--version`` line, the flags and a digest of the code generator and the runtime
headers.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass

from ..errors import ChaincompError
from ..escape import cpp_string, one_line
from ..model.machine import load_machine
from ..output import staged, write_file, write_files
from .buildtree import build_dir
from .cpp import fnv1a64, generate, library, solver_shape, solvers


@dataclass(frozen=True)
class Toolchain:
    compiler: str
    version: str            # first line of `compiler --version`
    flags: list[str]
    link_flags: list[str]
    include_dirs: list[str]
    abi: int
    sources: str  # the digest of the code generator and runtime headers (runtime/CMakeLists.txt)

    def key(self) -> str:
        """The text the loader's model_toolchain() builds (open_model.cpp), line for line."""
        return f"chaincomp model abi {self.abi}\n{self.version}\n{' '.join(self.flags)}\nsources {self.sources}"


def toolchain() -> Toolchain:
    path = os.path.join(build_dir(), "model_build.json")
    try:
        with open(path, encoding="utf-8") as f:
            cfg = json.load(f)
    except OSError:
        raise ChaincompError(f"{path} is missing: configure the C++ build first (tools/setup)") from None
    compiler = cfg["compiler"]
    if not os.access(compiler, os.X_OK):
        raise ChaincompError(f"no C++ compiler ({compiler} is missing): install the Debian package g++ "
                             f"(apt-get install g++)")
    proc = subprocess.run([compiler, "--version"], capture_output=True, text=True)
    if proc.returncode != 0 or not proc.stdout.strip():
        raise ChaincompError(f"{compiler} --version failed: reinstall the Debian package g++")
    if "sources" not in cfg:
        raise ChaincompError(f"{path} is from an older chaincomp: re-configure the C++ build (tools/setup)")
    return Toolchain(compiler, proc.stdout.splitlines()[0].rstrip("\r"), list(cfg["flags"]),
                     list(cfg["link_flags"]), list(cfg["include_dirs"]), int(cfg["abi"]), str(cfg["sources"]))


def cache_root() -> str:
    """$XDG_CACHE_HOME/chaincomp (a relative XDG_CACHE_HOME is ignored, as XDG says), else
    ~/.cache/chaincomp."""
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if xdg.startswith("/"):
        return os.path.join(xdg, "chaincomp")
    home = os.environ.get("HOME", "")
    if not home:
        raise ChaincompError("neither XDG_CACHE_HOME nor HOME is set: no cache folder for built models")
    return os.path.join(home, ".cache", "chaincomp")


def cache_path(root: str, name: str, source: bytes, key: str) -> str:
    """ROOT/NAME-HASH-TOOLCHAINHASH/NAME.so, as the loader's model_cache_path()."""
    return os.path.join(root, f"{name}-{fnv1a64(source):016x}-{fnv1a64(key.encode('utf-8')):016x}", f"{name}.so")


def _say(text: str) -> None:
    print(one_line(f"chaincomp build: {text}"), file=sys.stderr, flush=True)


def build(machine_path: str) -> tuple[str, bool]:
    """The cached library of the machine file at ``machine_path``, built first when the
    cache has none. Returns its path and whether it was cached. Concurrent builds of one
    machine are safe: one compiles (under a lock), the others wait and reuse its result,
    and a result appears only whole (built in a temporary folder, then renamed)."""
    try:
        with open(machine_path, "rb") as f:
            source = f.read()
    except OSError as exc:
        raise ChaincompError(f"{machine_path}: cannot read file ({exc.strerror})") from None
    machine = load_machine(machine_path)
    if fnv1a64(machine.source_text.encode("utf-8")) != fnv1a64(source):
        raise ChaincompError(f"{machine_path}: changed while it was read")
    tc = toolchain()
    root = cache_root()
    path = cache_path(root, machine.name, source, tc.key())
    if intact(path):
        return path, True
    with _exclusive(os.path.dirname(path) + ".lock", root,
                    f"{machine.name}: another build of this model is running; waiting for it"):
        if intact(path):
            return path, True
        if os.path.lexists(path):
            _say(f"{machine.name}: the cached {path} is not the library built there (its SHA-256 is not the one "
                 f"recorded in {os.path.basename(path)}.sha256): building it again")
        folder = os.path.dirname(path)
        try:
            tmp = tempfile.mkdtemp(dir=root, prefix="." + os.path.basename(folder) + "-")
        except OSError as exc:
            raise ChaincompError(f"cannot write the model cache {root}: {exc.strerror}") from None
        try:
            _compile(machine, source, tc, tmp)
            shutil.rmtree(folder, ignore_errors=True)  # a folder whose library was deleted by hand
            os.rename(tmp, folder)  # atomic: the folder appears complete
        except OSError as exc:
            raise ChaincompError(f"cannot write the model cache {root}: {exc.strerror}") from None
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return path, False


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _record_digest(path: str) -> None:
    """PATH.sha256 beside a file just built, in sha256sum's format (`sha256sum -c` checks it):
    what the cache's readers check before trusting it."""
    write_file(path + ".sha256", f"{_sha256(path)}  {os.path.basename(path)}\n")


def intact(path: str) -> bool:
    """Whether the cached file at ``path`` is the one built there: its SHA-256 is the one
    recorded beside it at build. A library truncated or overwritten since (a full disk, a copy,
    an editor) is no longer trusted: loaded, it crashed every daemon start (SIGBUS, SIGILL).
    chaincompd and replay check the same (open_model.cpp)."""
    try:
        with open(path + ".sha256", "rb") as f:
            recorded = f.read(200)
        return recorded == f"{_sha256(path)}  {os.path.basename(path)}\n".encode()
    except OSError:
        return False


@contextlib.contextmanager
def _exclusive(lock_path: str, root: str, waiting: str):
    """Holds the lock file at ``lock_path`` (its folder created) for the block: concurrent
    builds of one thing, one builds and the others wait (saying ``waiting``) and then find
    its result."""
    try:
        os.makedirs(os.path.dirname(lock_path), exist_ok=True)
        # never through a link planted at the lock's name (open(.., "w") would empty the file it names)
        lock = os.fdopen(os.open(lock_path, os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o666), "w")
    except OSError as exc:
        raise ChaincompError(f"cannot write the model cache {root}: {exc.strerror}") from None
    with lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            _say(waiting)
            fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def _runtime_include(tc: Toolchain) -> str:
    """The include folder of chaincomp's runtime headers among the toolchain's."""
    include = next((d for d in tc.include_dirs if os.path.isfile(os.path.join(d, "chaincomp", "compensate.hpp"))),
                   None)
    if include is None:
        raise ChaincompError(f"no chaincomp/compensate.hpp under the include folders of "
                             f"{os.path.join(build_dir(), 'model_build.json')} ({', '.join(tc.include_dirs)}): "
                             f"re-configure the C++ build (tools/setup)")
    return include


def _headers_key(tc: Toolchain, text: str) -> bytes:
    """A cache key of ``text`` compiled with the toolchain and the headers it includes: every
    runtime header and Eigen's version header (an update of either makes a new object)."""
    key = tc.key().encode("utf-8") + b"\0" + text.encode("utf-8")
    headers = os.path.join(_runtime_include(tc), "chaincomp")
    for fname in sorted(os.listdir(headers)):
        if not fname.endswith(".hpp") or not os.path.isfile(os.path.join(headers, fname)):
            continue  # an editor's backup or a folder is no header the solver includes
        with open(os.path.join(headers, fname), "rb") as f:
            key += b"\0" + fname.encode("utf-8") + b"\0" + f.read()
    for d in tc.include_dirs:
        macros = os.path.join(d, "Eigen", "src", "Core", "util", "Macros.h")
        if os.path.isfile(macros):
            with open(macros, "rb") as f:
                key += b"\0Eigen\0" + f.read()
            break
    return key


# What every generated model's code includes before its own header: compiled once per toolchain
# and headers into a precompiled header (GCC's .gch) that each model's compile loads instead of
# parsing Eigen and the solver's templates again (about 0.6 s of a 6-axis arm's 2 s).
PRELUDE = """// The headers every generated model includes (chaincomp build precompiles them once).
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <new>
#include "chaincomp/compensate.hpp"
#include "chaincomp/model_info.hpp"
"""


def prelude(tc: Toolchain, root: str, who: str) -> str | None:
    """ROOT/prelude-HASH/prelude.hpp with its precompiled prelude.hpp.gch beside it, made on
    first use: what a model's compile takes with ``-include``. None where the compiler is no
    GCC (clang reads no .gch) or the precompile failed: models then compile without it, the
    same code, a little slower."""
    if not tc.version.startswith(("c++ ", "g++ ", "gcc ")) and "(GCC)" not in tc.version:
        return None
    flags = [*tc.flags, "-DCHAINCOMP_PREBUILT_CORE"]   # the macros of a model's compile, as GCC requires
    folder = os.path.join(root, f"prelude-{fnv1a64(_headers_key(tc, PRELUDE)):016x}")
    header = os.path.join(folder, "prelude.hpp")
    gch = header + ".gch"
    if intact(gch) and intact(header):
        return header
    with _exclusive(gch + ".lock", root, f"{who}: another build is precompiling the model headers; waiting for it"):
        if intact(gch) and intact(header):
            return header
        start = time.monotonic()
        _say(f"{who}: precompiling the headers every model includes (Eigen, the solver's), once for this "
             "toolchain")
        write_file(header, PRELUDE)
        _record_digest(header)
        try:
            with staged(gch) as (tmp,):   # nothing put in place when the compiler fails
                proc = subprocess.run([tc.compiler, *flags, *(f"-I{d}" for d in tc.include_dirs), "-x",
                                       "c++-header", header, "-o", tmp], capture_output=True, text=True)
                if proc.returncode != 0:
                    raise ChaincompError(_first_error(proc))
        except ChaincompError as exc:
            _say(f"{who}: precompiling the headers failed ({exc}); compiling without")
            return None
        _record_digest(gch)
        _say(f"{who}: headers precompiled in {time.monotonic() - start:.1f} s")
    return header


def prelude_flags(header: str | None) -> list[str]:
    """The flags a model's compile takes for ``prelude()``'s header: -include it (GCC then loads
    the .gch beside it; -Winvalid-pch says why, should it not). GCC keeps no `#pragma GCC
    diagnostic` in a precompiled header, so Eigen's own silencing of -Wignored-attributes
    (DisableStupidWarnings.h) is said again here."""
    return [] if header is None else ["-include", header, "-Winvalid-pch", "-Wno-ignored-attributes"]


def _solver_object(machine, tc: Toolchain, root: str) -> str:
    """The compensation solver of the machine's shape, compiled once per shape, toolchain and
    runtime headers (ROOT/solvers-HASH/core_N_A_P_R_O.o) and linked into every model of that
    shape: a model's own compile leaves it out (CHAINCOMP_PREBUILT_CORE). Built under a
    lock and renamed into place, as the models."""
    shape = solver_shape(machine)
    text = solvers([shape])
    # the key: the toolchain, the solver's source and every runtime header (a header changed
    # by an update compiles a new solver; the old one stays for the models linked with it)
    key = _headers_key(tc, text)
    folder = os.path.join(root, f"solvers-{fnv1a64(key):016x}")
    n, a, p, r, o = shape
    path = os.path.join(folder, f"core_{n}_{a}_{p}_{r}_{int(o)}.o")
    if intact(path):
        return path
    with _exclusive(path + ".lock", root,
                    f"{machine.name}: another build is making the compensation solver of this shape; waiting for it"):
        if intact(path):
            return path
        start = time.monotonic()
        _say(f"{machine.name}: compiling the compensation solver for its shape ({n} axes, {bin(a).count('1')} "
             f"rotary, pose {p}, {r} rows), once for every model of that shape")
        source = path[:-2] + ".cpp"
        write_file(source, text)
        # a temporary file of its own: a compiler left running by a build killed before (its lock
        # released) cannot write into this one's object, and a failed compile leaves no half object
        with staged(path) as (tmp,):
            proc = subprocess.run([tc.compiler, *tc.flags, *(f"-I{d}" for d in tc.include_dirs), "-c", source,
                                   "-o", tmp], capture_output=True, text=True)
            if proc.returncode != 0:
                raise ChaincompError(f"{tc.compiler} failed on the compensation solver ({source}): "
                                     f"{_first_error(proc)}")
        _record_digest(path)
        _say(f"{machine.name}: solver built in {time.monotonic() - start:.1f} s")
    return path


def _first_error(proc) -> str:
    """The compiler's first line naming an error, else its first line, else how it ended."""
    lines = proc.stderr.splitlines()
    first = next((ln for ln in lines if "error" in ln), lines[0] if lines else None)
    if first is not None:
        return first
    if proc.returncode < 0:
        return f"killed by signal {-proc.returncode}, no message"
    return f"exit status {proc.returncode}, no message"


def _compile(machine, source: bytes, tc: Toolchain, folder: str) -> None:
    name = machine.name
    _say(f"{name}: no cached model for {os.path.basename(machine.file)} (hash {fnv1a64(source):016x}): "
         f"generating its C++")
    start = time.monotonic()
    files = generate(machine)  # order 2, as the compiled-in models
    files["library.cpp"] = library(machine, source, tc.key())
    for fname, text in files.items():
        with open(os.path.join(folder, fname), "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
    _say(f"{name}: generated in {time.monotonic() - start:.1f} s")
    solver = _solver_object(machine, tc, os.path.dirname(folder))
    header = prelude(tc, os.path.dirname(folder), name)
    start = time.monotonic()
    _say(f"{name}: compiling with {tc.compiler} {' '.join(tc.flags)}")
    cmd = [tc.compiler, *tc.flags, "-DCHAINCOMP_PREBUILT_CORE", *(f"-I{d}" for d in tc.include_dirs), f"-I{folder}",
           *prelude_flags(header), f"{name}.cpp", "library.cpp", solver, *tc.link_flags, "-o", f"{name}.so"]
    proc = subprocess.run(cmd, cwd=folder, capture_output=True, text=True)
    if proc.returncode != 0:
        raise ChaincompError(f"{tc.compiler} failed on the generated code of {name}: {_first_error(proc)}")
    _record_digest(os.path.join(folder, f"{name}.so"))
    _say(f"{name}: compiled in {time.monotonic() - start:.1f} s")


def copy_to(path: str, folder: str) -> str:
    """A copy of the library at ``path`` in ``folder`` (for --model on another computer) with
    its digest beside it (NAME.so.sha256, which --model checks before loading), by the one
    writer: a reader never sees half of either."""
    target = os.path.join(folder, os.path.basename(path))
    with open(path, "rb") as f:
        data = f.read()
    digest = f"{hashlib.sha256(data).hexdigest()}  {os.path.basename(path)}\n"
    write_files({target: data, target + ".sha256": digest}, folder=folder, mode=0o777)
    return target


def _copy_into(path: str, folder: str, mode: int, create: bool = False) -> str:
    """folder/basename(path) (the folder created when ``create``); new files get ``mode``."""
    target = os.path.join(folder, os.path.basename(path))
    with open(path, "rb") as f:
        data = f.read()
    write_files({target: data}, folder=folder if create else None, mode=mode)
    return target


# --- chaincomp_rt: the realtime HAL component of one machine (LinuxCNC) -------------------

MODINC = "/usr/share/linuxcnc/Makefile.modinc"
RT_MODULE = "chaincomp_rt"
_HAL_SOURCES = ("chaincomp_rt.c", "chaincomp_rt.h", "chaincomp_rt_core.cpp", "Makefile")
# chaincompd's defaults (configs/runtime/default.yaml, daemon_config.cpp), axis units:
# max_step, max_correction, max_correction_step.
_RT_LIMITS = {"length": (10.0, 0.5, 0.001), "angle": (5.0, 0.5, 0.001)}
_RT_RAMP_TIME = 0.5


def _runtime_dir() -> str:
    return os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "..", "runtime"))


def rt_model_header(machine, values: dict, params_file: str) -> str:
    """chaincomp_rt_model.hpp: the machine's model namespace, its parameters in kParams order
    (internal units: constants at their nominal unless given, errors zero unless given) and
    chaincompd's default limits per axis, as C++ constants."""
    params = [s for s in machine.symbols if s.role != "axis"]
    vals = [values.get(s.name, s.to_internal(s.nominal) if s.role == "constant" else 0.0) for s in params]
    limits = []
    for a in machine.axes:
        step, size, rate = _RT_LIMITS["angle" if a.unit.kind == "angle" else "length"]
        limits.append(f"    {{{a.limits[0]!r}, {a.limits[1]!r}, {step!r}, {size!r}, {rate!r}}},  // {a.name} [{a.unit.name}]")
    params_literal = cpp_string(params_file.encode("utf-8", "surrogateescape"))
    return "\n".join([
        f"// Generated by chaincomp build --linuxcnc for machine {machine.name}. Do not edit.",
        "#pragma once", "", f"#include \"{machine.name}.hpp\"", "#include \"chaincomp/compensator.hpp\"", "",
        f"namespace ccrt_model = chaincomp::models::{machine.name};", "",
        "namespace ccrt_params {", "",
        f"inline constexpr const char* kParamsFile = {params_literal};",
        "// Every constant and error, kParams order, internal units (mm, rad, 1).",
        f"inline constexpr double kValues[{max(len(vals), 1)}] = {{",
        *[f"    {v!r},  // {s.name}" for s, v in zip(params, vals)], "};",
        "// lower, upper (the machine file's limits), max_step, max_correction, max_correction_step: axis units",
        f"inline constexpr chaincomp::AxisLimits kLimits[{len(limits)}] = {{", *limits, "};",
        f"inline constexpr double kRampTime = {_RT_RAMP_TIME!r};  // s",
        "inline constexpr bool kClampOutOfLimits = false;", "",
        "}  // namespace ccrt_params", ""])


def build_linuxcnc(machine_path: str, params_path: str | None, module: str = RT_MODULE) -> tuple[str, bool]:
    """MODULE.so (default chaincomp_rt.so) for the machine file with its params baked in
    (loaded by prepare() at module load), built with LinuxCNC's Makefile.modinc and cached
    like the model libraries (ROOT/linuxcnc/NAME-HASH/MODULE.so, the hash over machine,
    params, module name, sources and toolchain). Returns its path and whether it was cached."""
    from ..model.params import load_params
    from ..model.varying import Varying

    if not re.fullmatch(r"[a-z][a-z0-9_]{0,39}", module):
        raise ChaincompError(f"--name {module!r}: a module name is a lower-case letter, then up to 39 lower-case "
                             "letters, digits or _ (loadrt takes it as is; its pins are named with - for _)")

    if not os.path.exists(MODINC):
        raise ChaincompError(f"{MODINC} is missing: install LinuxCNC's development files "
                             "(tools/setup-linuxcnc, or apt-get install linuxcnc-uspace-dev)")
    try:
        with open(machine_path, "rb") as f:
            source = f.read()
        params_source = b""
        if params_path:
            with open(params_path, "rb") as f:
                params_source = f.read()
    except OSError as exc:
        raise ChaincompError(f"{exc.filename}: cannot read file ({exc.strerror})") from None
    machine = load_machine(machine_path)
    values = load_params(params_path, machine) if params_path else {}
    for name, v in values.items():
        if isinstance(v, Varying):
            raise ChaincompError(f"{params_path}: {name} is a table or polynomial; chaincomp_rt takes constant "
                                 "errors only (use chaincompd through the bridge for varying errors)")
    for s in machine.errors:   # its error pins: PREFIX.error.NAME, within HAL's names
        pin = f"{module.replace('_', '-')}.error.{s.name}"
        if len(pin) > 47:
            raise ChaincompError(f"error {s.name}: its HAL pin {pin} is longer than HAL's 47 characters (HAL_NAME_LEN): "
                                 "give a shorter --name", machine.file)
    tc = toolchain()
    hal = os.path.join(_runtime_dir(), "hal")
    sources = b"".join(open(os.path.join(hal, n), "rb").read() for n in _HAL_SOURCES)
    # and what the module's code comes from: the runtime headers, the compensator, the emitter
    here = os.path.dirname(os.path.abspath(__file__))
    inputs = [os.path.join(_runtime_dir(), "src", "compensator.cpp"), os.path.join(_runtime_dir(), "src", "params_update.cpp"),
              os.path.join(here, "cpp.py"),
              os.path.join(here, "..", "symbolic", "jets.py")]
    include_dir = os.path.join(_runtime_dir(), "include", "chaincomp")
    inputs += sorted(os.path.join(include_dir, n) for n in os.listdir(include_dir) if n.endswith(".hpp"))
    for name in inputs:
        with open(name, "rb") as f:
            sources += f.read()
    key = fnv1a64(source + b"\0" + params_source + b"\0" + module.encode() + b"\0" + sources + tc.key().encode())
    root = os.path.join(cache_root(), "linuxcnc")
    folder = os.path.join(root, f"{machine.name}-{key:016x}")
    path = os.path.join(folder, module + ".so")
    if intact(path):
        return path, True
    with _exclusive(folder + ".lock", root, f"{machine.name}: another build of {module} is running; waiting for it"):
        if intact(path):
            return path, True
        _compile_rt(machine, values, params_path, tc, root, folder, module)
    return path, False


def _compile_rt(machine, values: dict, params_path: str | None, tc: Toolchain, root: str, folder: str,
                module: str) -> None:
    hal = os.path.join(_runtime_dir(), "hal")
    try:
        tmp = tempfile.mkdtemp(dir=root, prefix="." + os.path.basename(folder) + "-")
    except OSError as exc:
        raise ChaincompError(f"cannot write the model cache {root}: {exc.strerror}") from None
    try:
        start = time.monotonic()
        _say(f"{machine.name}: generating its C++ for {module}")
        files = generate(machine)
        files["chaincomp_rt_model.hpp"] = rt_model_header(machine, values, os.path.abspath(params_path)
                                                          if params_path else "(none: every error zero)")
        files["chaincomp_rt_name.h"] = (f"/* Generated by chaincomp build --linuxcnc. Do not edit. */\n"
                                        f"#define CCRT_MODULE \"{module}\"\n"
                                        f"#define CCRT_PREFIX \"{module.replace('_', '-')}\"\n")
        for fname, text in files.items():
            with open(os.path.join(tmp, fname), "w", encoding="utf-8", newline="\n") as f:
                f.write(text)
        for n in _HAL_SOURCES:
            shutil.copy(os.path.join(hal, n), tmp)
        _say(f"{machine.name}: generated in {time.monotonic() - start:.1f} s; compiling {module}.so "
             f"(Makefile.modinc, -fno-exceptions -fno-rtti)")
        include = _runtime_include(tc)
        eigen = next((d for d in tc.include_dirs if "eigen" in d), "/usr/include/eigen3")
        proc = subprocess.run(["make", "-s", f"MODEL={machine.name}", f"MODULE={module}", f"CHAINCOMP_INCLUDE={include}",
                               f"EIGEN_INCLUDE={eigen}", f"CHAINCOMP_SRC={os.path.join(_runtime_dir(), 'src')}",
                               f"CXX={tc.compiler}", "modules"], cwd=tmp, capture_output=True, text=True)
        if proc.returncode != 0:
            lines = (proc.stderr or proc.stdout).splitlines()
            first = next((ln for ln in lines if "error" in ln), lines[-1] if lines else "no message")
            raise ChaincompError(f"building {module} for {machine.name} failed: {first}")
        _record_digest(os.path.join(tmp, module + ".so"))
        shutil.rmtree(folder, ignore_errors=True)  # a folder whose module was deleted by hand
        os.rename(tmp, folder)  # atomic: the folder appears complete
        _say(f"{machine.name}: {module}.so built in {time.monotonic() - start:.1f} s")
    except OSError as exc:
        raise ChaincompError(f"cannot write the model cache {root}: {exc.strerror}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def linuxcnc_module_dir() -> str:
    """Where LinuxCNC's loadrt looks for modules (it takes names only, never paths)."""
    return "/usr/lib/linuxcnc/modules"


def install_rt(path: str) -> str:
    """Copies the module (MODULE.so) into LinuxCNC's module folder (root only), atomically."""
    folder = linuxcnc_module_dir()
    try:
        return _copy_into(path, folder, 0o644)
    except ChaincompError as exc:
        raise ChaincompError(f"--install: {exc}: run as root (sudo), or copy {path} there yourself") from None
