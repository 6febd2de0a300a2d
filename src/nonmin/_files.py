"""Durable file output and confined output names.

Every file nonmin writes (trajectories, CSV, figures, animations, reports) goes through
:func:`atomic_write` or :func:`atomic_path`: the content is written to a temporary file with a
unique name in the target's own folder, flushed and ``fsync``'d, then renamed over the target
with :func:`os.replace` (atomic on POSIX and Windows within one file system), and the folder is
``fsync``'d. A kill, a full disk or a file-size limit in mid-write leaves the previous file as
it was (and no temporary behind, except after a hard kill: ``.<name>.*.tmp`` files are debris
of interrupted writes and may be deleted). Two writers of one target never see a mixture:
each writes its own temporary and the last complete rename wins.

:func:`confined` resolves an output name given by a data file (a scenario's ``[output]``
table) inside the output folder and refuses anything that would leave it.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from .errors import InputError, OutputError, ScenarioError

__all__ = ["as_path", "atomic_path", "atomic_write", "confined", "write_text"]


def _fsync_dir(folder: Path) -> None:
    """Persist a rename: fsync the folder (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # e.g. Windows
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def as_path(path: Any, what: str = "path") -> Path:
    """``Path(path)``, or an :class:`~nonmin.errors.InputError` naming ``what``."""
    try:
        p = Path(os.fspath(path))
    except TypeError:
        raise InputError(f"{what} must be a file path (str or os.PathLike), got {type(path).__name__}") from None
    if not str(p) or "\x00" in str(p):
        raise InputError(f"{what} must be a non-empty file path without NUL characters, got {str(p)!r}")
    return p


def _umask() -> int:
    """The process's umask (read from /proc where it can be, without changing it)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    old = os.umask(0o022)
    os.umask(old)
    return old


def _file_mode(target: Path) -> int:
    """The permission bits a target gets: those of the file it replaces, else 0666 & ~umask
    (what ``open(target, "w")`` would give; ``mkstemp`` makes its temporaries 0600)."""
    try:
        return stat.S_IMODE(target.stat().st_mode)
    except OSError:
        return 0o666 & ~_umask()


def _temp_in(target: Path, suffix: str) -> tuple[int, Path]:
    folder = target.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=folder)
    except OSError as exc:
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from exc
    try:
        if hasattr(os, "fchmod"):
            os.fchmod(fd, _file_mode(target))
    except OSError:
        pass  # a file system without permission bits: keep mkstemp's
    return fd, Path(name)


def _commit(tmp: Path, target: Path) -> None:
    try:
        if target.is_dir():
            raise IsADirectoryError(21, "is a directory", str(target))
        os.replace(tmp, target)
    except OSError as exc:
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from exc
    _fsync_dir(target.parent)


def _discard(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        tmp.unlink()


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "wb", **open_kw: Any) -> Iterator[IO[Any]]:
    """Open a temporary file next to ``path``; on success fsync it and rename it over ``path``.

    Parameters
    ----------
    path : str or path-like
        The target file. Its folder is created when missing.
    mode : {"wb", "w"}
        Binary or text.
    **open_kw
        Passed to :func:`os.fdopen` (e.g. ``encoding="utf-8"``).

    Raises
    ------
    OutputError
        The folder or file cannot be written (permissions, full disk, file-size limit, ...):
        the message names the target; the previous file at ``path`` is unchanged.
    """
    if mode not in ("wb", "w"):
        raise InputError(f"mode must be 'wb' or 'w', got {mode!r}")
    target = as_path(path)
    fd, tmp = _temp_in(target, ".tmp")
    ok = False
    try:
        with os.fdopen(fd, mode, **open_kw) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        _commit(tmp, target)
        ok = True
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from exc
    finally:
        if not ok:
            _discard(tmp)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path with ``path``'s suffix, in ``path``'s folder, renamed over it on success.

    For writers that take a file name (Matplotlib's ``savefig``, animation writers, ffmpeg):
    they write the temporary; on a clean exit it is fsync'd and renamed over ``path``. On any
    exception the temporary is removed and ``path`` is untouched.

    Raises
    ------
    OutputError
        As :func:`atomic_write`.
    """
    target = as_path(path)
    fd, tmp = _temp_in(target, ".tmp" + target.suffix)
    os.close(fd)
    ok = False
    try:
        yield tmp
        try:
            fd = os.open(tmp, os.O_RDONLY)
        except OSError as exc:
            raise OutputError(f"cannot write {str(target)!r}: the writer produced no file ({exc})") from exc
        try:
            os.fsync(fd)
        except OSError:
            pass
        finally:
            os.close(fd)
        _commit(tmp, target)
        ok = True
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from exc
    finally:
        if not ok:
            _discard(tmp)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) durably to ``path`` (see :func:`atomic_write`)."""
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return Path(path)


def confined(folder: str | os.PathLike[str], name: str, *, file: str | os.PathLike[str], key: str,
             suffixes: tuple[str, ...] = ()) -> Path:
    """Resolve an output name from a data file inside ``folder``; refuse anything that leaves it.

    Parameters
    ----------
    folder : path
        The output folder.
    name : str
        A relative file name (sub-folders allowed) from the data file.
    file, key : str
        The data file and its key, named in the error.
    suffixes : tuple of str
        Accepted file name endings (lower case, with the dot); empty: any.

    Raises
    ------
    ScenarioError
        ``name`` is empty, absolute, climbs out with ``..``, resolves (through a symbolic link)
        outside ``folder``, or has the wrong suffix.
    """
    if not isinstance(name, str) or not name.strip() or "\x00" in name:
        raise ScenarioError(f"{file}: key {key!r}: expected a file name, got {name!r}")
    rel = Path(name)
    if rel.is_absolute() or rel.drive or rel.anchor:
        raise ScenarioError(
            f"{file}: key {key!r}: output names are relative to the output folder, got the "
            f"absolute path {name!r}"
        )
    if ".." in rel.parts:
        raise ScenarioError(
            f"{file}: key {key!r}: output names must stay inside the output folder, got {name!r}"
        )
    if suffixes and rel.suffix.lower() not in suffixes:
        raise ScenarioError(
            f"{file}: key {key!r}: expected a file name ending in {' or '.join(suffixes)}, got {name!r}"
        )
    base = Path(folder).resolve()
    target = (base / rel).resolve()
    if target != base and base not in target.parents:
        raise ScenarioError(
            f"{file}: key {key!r}: {name!r} resolves to {str(target)!r}, outside the output "
            f"folder {str(base)!r} (symbolic link?)"
        )
    return base / rel
