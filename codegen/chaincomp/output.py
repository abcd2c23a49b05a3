"""The one writer of every file chaincomp writes (design §11): a file appears whole or not at
all, and nothing but the named path changes.

- A regular file (or a name not there yet) is written to a temporary file created exclusively
  (``tempfile.mkstemp``: O_EXCL, an unpredictable name, never through a planted link) in the
  target's folder, flushed to disk, then renamed over the target: a full disk, a failed check
  or a program that fails leaves the old file whole, and a reader never sees half a file. The
  old file's permissions are kept; a new file gets ``mode`` less the umask, as open() would.
- Through a symbolic link the link is resolved once and the file it names is replaced: the link
  stays a link.
- A target that is not a regular file (``/dev/stdout``, a named pipe, a device) is written into:
  a rename would replace the node itself (as root, ``-o /dev/full`` became a regular file). Its
  temporary copy is made outside its folder (/dev takes no files), so a check can still refuse it.
- A failure is one ChaincompError naming the path: ``PATH: cannot write: No space left on device``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile

from .errors import ChaincompError


def write_file(path: str, data: str | bytes, check=None, mode: int = 0o666) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` once ``check(tmp)``, if given, accepts the
    complete temporary file (it raises to refuse)."""
    write_files({path: data}, check=check, mode=mode)


def write_files(files: dict[str, str | bytes], folder: str | None = None, check=None, mode: int = 0o666) -> None:
    """Write each path's data, all of them complete (and checked) before any is put in place.
    With ``folder``, the files' folder is created first (with its missing parents) and removed
    again if nothing could be written into it."""
    created = _make_folder(folder) if folder else None
    try:
        with staged(*files, mode=mode) as tmps:
            for path, tmp, data in zip(files, tmps, files.values()):
                try:
                    with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_NOFOLLOW), "wb") as f:
                        f.write(data.encode("utf-8") if isinstance(data, str) else data)
                except OSError as exc:
                    raise _error(exc, path) from None
                if check is not None:
                    check(tmp)
    except BaseException:
        if created:
            _remove_empty(folder, created)
        raise


@contextlib.contextmanager
def staged(*paths: str, mode: int = 0o666):
    """Temporary files for ``paths`` for the block to fill (a program that writes a named file:
    liblcm, the compiler, chaincomp_replay); when the block ends without an exception each is
    put in place, as write_files does, else they are removed."""
    outputs = []
    try:
        for path in paths:
            outputs.append(_Output(path, mode))
        yield [o.tmp for o in outputs]
        # a pipe or device can refuse its data (ENOSPC, EPIPE): those first, then the renames
        for o in sorted(outputs, key=lambda o: not o.special):
            o.commit()
    finally:
        for o in outputs:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(o.tmp)


class _Output:
    """One output path: where its data goes and the temporary file that holds it until then."""

    def __init__(self, path: str, mode: int):
        self.path = path
        try:
            st = os.stat(path)   # through links
        except FileNotFoundError:
            st = None            # nothing there, or a link to nothing: created where it points
        except OSError as exc:
            raise _error(exc, path) from None
        self.special = st is not None and not stat.S_ISREG(st.st_mode)
        self.target = path if self.special else os.path.realpath(path)
        self.mode = stat.S_IMODE(st.st_mode) if st is not None and not self.special else mode & ~_umask()
        try:
            fd, self.tmp = tempfile.mkstemp(dir=None if self.special else os.path.dirname(self.target),
                                            prefix="." + os.path.basename(self.target) + ".", suffix=".tmp")
        except OSError as exc:
            raise _error(exc, path) from None
        os.close(fd)

    def commit(self) -> None:
        try:
            if self.special:
                with open(self.tmp, "rb") as src, open(self.path, "wb") as dst:
                    shutil.copyfileobj(src, dst)
                return
            fd = os.open(self.tmp, os.O_RDONLY | os.O_NOFOLLOW)   # a program may have replaced it: never a link
            try:
                os.fchmod(fd, self.mode)
                os.fsync(fd)   # on disk before the rename: a crash leaves the old file, not an empty one
            finally:
                os.close(fd)
            os.replace(self.tmp, self.target)
        except OSError as exc:
            raise _error(exc, self.path) from None


def _error(exc: OSError, path: str) -> ChaincompError:
    return ChaincompError(f"cannot write: {exc.strerror or exc}", path)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _make_folder(folder: str) -> str | None:
    """Creates ``folder`` and its missing parents; returns the topmost one it created, if any."""
    top, parent = None, os.path.abspath(folder)
    while parent and not os.path.lexists(parent):
        top, parent = parent, os.path.dirname(parent)
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise ChaincompError(f"cannot create output folder: {exc.strerror or exc}", folder) from None
    return top


def _remove_empty(folder: str, top: str) -> None:
    """Removes the folders created for a write that failed, from ``folder`` up to ``top``."""
    path = os.path.abspath(folder)
    with contextlib.suppress(OSError):   # not empty (someone else's file): left as it is
        while True:
            os.rmdir(path)
            if path == top:
                break
            path = os.path.dirname(path)
