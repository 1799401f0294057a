"""Output paths of the commands: checked before any work, written whole or not at all.

A command that writes a file or a folder checks its path first (:func:`check_file`,
:func:`check_folder`), so a bad ``--out`` is a one-line :class:`~planner.core.errors.InputError`
before minutes of planning, not a traceback after them; :func:`write_atomic` writes a file
under a temporary name in its folder and renames it, so an interruption leaves the old file
or the new one, never half of one.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from planner.core.errors import InputError

__all__ = ["ROBOT_HELP", "check_file", "check_folder", "write_atomic"]

# help of the commands' --robot option, which reads a plan file whose robot has moved
ROBOT_HELP = "URDF of the plan's robot, if the path the plan file names is gone (moved)"


def _parents_are_folders(path: Path, option: str) -> None:
    for parent in path.parents:
        if parent.exists() and not parent.is_dir():
            raise InputError(
                f"{option} {path}: {parent} is a file, not a folder; choose another path"
            )


def check_file(path: str | Path, option: str = "--out", suffixes: tuple[str, ...] = ()) -> Path:
    """``path`` as a Path to write a file to.

    InputError if it is empty or a folder, lies under a file, or (given ``suffixes``) has
    another suffix.
    """
    if str(path).strip() == "":
        raise InputError(f"{option}: empty path; give a file name")
    path = Path(path)
    if path.is_dir():
        example = path / f"out{suffixes[0] if suffixes else ''}"
        raise InputError(f"{option} {path}: is a folder; give a file name like {example}")
    _parents_are_folders(path, option)
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{option} {path}: give a file name ending in {' or '.join(suffixes)}")
    return path


def check_folder(path: str | Path, option: str = "--out") -> Path:
    """``path`` as a Path to write into; InputError if it is a file or lies under one."""
    if str(path).strip() == "":
        raise InputError(f"{option}: empty path; give a folder")
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"{option} {path}: is a file, not a folder; give a folder to write into")
    _parents_are_folders(path, option)
    return path


def write_atomic(path: str | Path, write: Callable[[Path], object], mode: int = 0o666) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it to ``path``.

    The folder is created; the file gets ``mode`` less the umask (as ``open`` would make it,
    not ``mkstemp``'s 0600). On any error or interruption the temporary file is removed.
    """
    path = Path(path)
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
