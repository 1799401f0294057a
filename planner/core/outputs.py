"""Output paths of the commands: checked before any work, written whole or not at all.

A command that writes a file or a folder checks its path first (:func:`check_file`,
:func:`check_folder`): not a folder where a file is meant (nor a device), no file on the way,
a name the file system takes, a folder this process can write into (tried with a probe
file, since root passes every permission test, yet not on ``/proc`` or a read-only disk)
and the free space the output needs where the file system says. So a bad ``--out`` is a
one-line :class:`~planner.core.errors.InputError` before minutes of planning, not a
traceback after them. :func:`write_atomic` writes a file under a temporary name in its
folder and renames it, so an interruption leaves the old file or the new one, never half of
one; if the write fails all the same (the disk filled up meanwhile), the result is written
to the temporary folder instead and an :class:`~planner.core.errors.OutputError` says where.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

from planner.core.errors import InputError, OutputError

__all__ = [
    "MIN_FREE_B",
    "ROBOT_HELP",
    "check_file",
    "check_folder",
    "free_bytes",
    "write_atomic",
]

# help of the commands' --robot option, which reads a plan file whose robot has moved
ROBOT_HELP = "URDF of the plan's robot, if the path the plan file names is gone (moved)"

MIN_FREE_B = 1 << 20  # an output folder needs at least this much free space [bytes]
_TMP_CHARS = 24  # write_atomic's temporary name: ".NAME." + 8 random + ".tmp"
_PATH_MAX = 4000  # bytes of an absolute path (Linux: 4096 with the final NUL)


def _size(n: float) -> str:
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} bytes"


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def free_bytes(folder: str | Path) -> int | None:
    """Bytes this process may still write in ``folder``'s file system (None: unknown)."""
    try:
        st = os.statvfs(folder)
    except (OSError, ValueError):
        return None
    return int(st.f_bavail) * int(st.f_frsize)


def _mode(path: Path) -> int | None:
    """``st_mode`` of ``path`` (symlinks followed), None if it cannot be reached."""
    try:
        return os.stat(path).st_mode
    except (OSError, ValueError):
        return None


def _nearest_existing(path: Path) -> Path:
    """``path`` itself or its nearest ancestor that exists."""
    for p in (path, *path.parents):
        if _mode(p) is not None:
            return p
    return Path(".")


def _basic(path: str | Path, option: str, what: str) -> Path:
    text = str(path)
    if text.strip() == "":
        raise InputError(f"{option}: empty path; give {what}")
    if "\0" in text:
        raise InputError(f"{option} {text!r}: contains a NUL character; give {what}")
    if len(os.fsencode(os.path.abspath(text))) >= _PATH_MAX:
        raise InputError(f"{option} {text[:40]}...: path too long; choose a shorter one")
    path = Path(text)
    for parent in path.parents:
        mode = _mode(parent)
        if mode is not None and not stat.S_ISDIR(mode):
            raise InputError(
                f"{option} {path}: {parent} is a file, not a folder; choose another path"
            )
    return path


def _writable(path: Path, option: str, size_b: float, file: bool) -> None:
    """InputError unless ``path`` can be written as ``option`` asks.

    The names still to create fit, the nearest existing folder takes a probe file, and its
    disk has ``size_b`` bytes free (at least :data:`MIN_FREE_B`).
    """
    folder = _nearest_existing(path.parent if file else path)
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    new = path.relative_to(folder).parts if folder != path else ()
    for i, part in enumerate(new):
        extra = _TMP_CHARS if file and i == len(new) - 1 else 0
        if len(os.fsencode(part)) + extra > name_max:
            raise InputError(
                f"{option} {path}: the name {part[:20]}... is too long for its file system "
                f"(at most {name_max - extra} bytes); choose a shorter name"
            )
    try:
        fd, probe = tempfile.mkstemp(prefix=".stratawalk-probe-", dir=folder)
    except OSError as exc:
        raise InputError(
            f"{option} {path}: cannot write into {folder} ({_reason(exc)}); choose a "
            "writable folder"
        ) from None
    os.close(fd)
    os.unlink(probe)
    free, need = free_bytes(folder), max(float(size_b), MIN_FREE_B)
    if free is not None and free < need:
        raise InputError(
            f"{option} {path}: only {_size(free)} free on its disk, and it needs about "
            f"{_size(need)}; free some space or choose another disk"
        )


def check_file(
    path: str | Path, option: str = "--out", suffixes: tuple[str, ...] = (), size_b: float = 0
) -> Path:
    """``path`` as a Path to write a file of about ``size_b`` bytes to.

    InputError if it is empty, a folder or a device, lies under a file, has another suffix
    than ``suffixes`` (if given), has a name too long, or its folder (the nearest that
    exists) cannot be written into or lacks the space.
    """
    path = _basic(path, option, "a file name")
    mode = _mode(path)
    if mode is not None and stat.S_ISDIR(mode):
        example = path / f"out{suffixes[0] if suffixes else ''}"
        raise InputError(f"{option} {path}: is a folder; give a file name like {example}")
    if mode is not None and not stat.S_ISREG(mode):
        raise InputError(f"{option} {path}: not a regular file (a device, pipe or socket); "
                         "give a file name")  # fmt: skip
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{option} {path}: give a file name ending in {' or '.join(suffixes)}")
    _writable(path, option, size_b, file=True)
    return path


def check_folder(path: str | Path, option: str = "--out", size_b: float = 0) -> Path:
    """``path`` as a Path to write about ``size_b`` bytes into.

    InputError if it is empty, a file, lies under a file, or cannot be written into (or
    the nearest folder above it that exists cannot) or lacks the space.
    """
    path = _basic(path, option, "a folder")
    mode = _mode(path)
    if mode is not None and not stat.S_ISDIR(mode):
        raise InputError(f"{option} {path}: is a file, not a folder; give a folder to write into")
    _writable(path, option, size_b, file=False)
    return path


def _write(path: Path, write: Callable[[Path], object], mode: int) -> Path:
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, mode & ~umask)
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _keep(path: Path, write: Callable[[Path], object]) -> Path | None:
    """Write to a new file in the temporary folder, home or here; its path, or None."""
    for folder in (tempfile.gettempdir(), Path.home(), Path.cwd()):
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(prefix="stratawalk-kept-", suffix=f"-{path.name}",
                                       dir=folder)  # fmt: skip
            os.close(fd)
            write(Path(tmp))
            return Path(tmp)
        except OSError:
            if tmp is not None:
                Path(tmp).unlink(missing_ok=True)
    return None


def write_atomic(
    path: str | Path, write: Callable[[Path], object], mode: int = 0o666, option: str = "--out"
) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it to ``path``.

    The folder is created; the file gets ``mode`` less the umask (as ``open`` would make it,
    not ``mkstemp``'s 0600). On any error or interruption the temporary file is removed.

    Raises
    ------
    OutputError
        The file could not be written (its folder became a file, the disk filled up): the
        result went to a file in the temporary folder (else home, else here), whose path
        the one-line message names (``kept``).

    """
    path = Path(path)
    try:
        now = None if "\0" in str(path) else _mode(path)
        if str(path).strip() == "" or "\0" in str(path) or (now and stat.S_ISDIR(now)):
            raise OSError(errno.EINVAL, "not a file name")
        return _write(path, write, mode)
    except OSError as exc:
        reason = _reason(exc)
        kept = _keep(path, write)
        where = f"the result is kept in {kept}" if kept else "nor could a copy be kept elsewhere"
        raise OutputError(f"{option} {path}: cannot write it ({reason}); {where}", kept) from None
