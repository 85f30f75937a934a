"""Output files that never destroy data: the one way every command writes a file.

- An existing file is refused unless the caller allows overwriting (``--overwrite``).
- A file that is one of the inputs is refused always: compared by device and inode, so a hard
  link or a symbolic link to an input is caught, not only the same path.
- Only regular files are replaced: a folder, a device (``/dev/null``), a FIFO is refused.
- Writes are atomic: a new temporary file beside the target (created exclusively, never
  through a link), flushed and fsynced, then renamed over the target; a new file is linked
  into place, so a file that appeared meanwhile is not replaced either. A failed or
  interrupted write leaves the old file as it was and no temporary file.
- One writer per file: a lock (``fcntl.flock`` on ``.NAME.lock`` beside the target, taken
  without waiting) refuses a second writer with a message instead of letting two interleave.

:func:`write_output` writes bytes or text; :func:`output_file` gives a binary file object;
:func:`output_path` gives the temporary path for writers that open files by name (Qt's PDF
writer). :class:`OutputLock` is the lock alone (the recording writer holds it while it
records). Refusals raise :class:`OutputRefused`, whose message is one line for the user.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import signal
import stat
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

try:
    import fcntl
except ImportError:  # Windows: no advisory locks here; the atomic rename still protects data
    fcntl = None  # type: ignore[assignment]

PathLike = str | os.PathLike[str]


class OutputRefused(OSError):
    """An output that would destroy data or collide with another writer; says why, in one line."""

    def __str__(self) -> str:
        return self.strerror or super().__str__()


def _describe(option: str, path: Path) -> str:
    return f"{option} {path}" if option else str(path)


def _identity(path: PathLike) -> tuple[int, int] | None:
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return None
    return info.st_dev, info.st_ino


def write_error_message(exc: OSError, path: PathLike, option: str = "") -> str:
    """One line for a failed output: the refusal, or the system's reason (a full disk)."""
    if isinstance(exc, OutputRefused):
        return str(exc)
    return (f"{_describe(option, Path(path))}: {exc.strerror or exc}; nothing was written "
            "(a file already there is unchanged)")


def same_file_as_input(path: PathLike, inputs: Iterable[PathLike | None]) -> PathLike | None:
    """The input that ``path`` is (same device and inode: hard links too), or None."""
    target = _identity(path)
    if target is None:
        return None
    for item in inputs:
        if item is not None and _identity(item) == target:
            return item
    return None


def check_output(path: PathLike, *, inputs: Iterable[PathLike | None] = (),
                 overwrite: bool = False, option: str = "", input_name: str = "input") -> Path:
    """Raise :class:`OutputRefused` when writing ``path`` would destroy data; returns it.

    ``option`` names the command-line option in the message (``"--out"``), ``input_name``
    what the inputs are (``"recording"``).
    """
    path = Path(path)
    where = _describe(option, path)
    parent = path.parent
    if not parent.is_dir():
        raise OutputRefused(errno.ENOENT, f"{where}: no such directory {parent}")
    same = same_file_as_input(path, inputs)
    if same is not None:
        raise OutputRefused(errno.EEXIST, f"{where} would overwrite the {input_name} itself "
                                          f"({same}: the same file); choose another output")
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise OutputRefused(exc.errno or errno.EIO,
                            f"{where}: cannot check it ({exc.strerror or exc})") from None
    if stat.S_ISLNK(info.st_mode):
        if not overwrite:
            raise OutputRefused(errno.EEXIST, f"{where} exists (a link); pass --overwrite to "
                                              "replace the link with a file")
        return path
    if not stat.S_ISREG(info.st_mode):
        raise OutputRefused(errno.EEXIST, f"{where} exists and is not a regular file; "
                                          "choose a file name")
    if not overwrite:
        raise OutputRefused(errno.EEXIST, f"{where} exists; pass --overwrite to replace it")
    return path


class OutputLock:
    """An exclusive, non-blocking lock on writing ``path`` (``.NAME.lock`` beside it).

    A second :meth:`acquire` (another process, or another lock object here) raises
    :class:`OutputRefused`. The lock file is removed on :meth:`release`.
    """

    def __init__(self, path: PathLike, option: str = "") -> None:
        self.path = Path(path)
        self.lock_path = self.path.with_name(f".{self.path.name}.lock")
        self._option = option
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> OutputLock:
        if self._fd is not None or fcntl is None:
            return self
        where = _describe(self._option, self.path)
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        for _ in range(20):  # the holder may remove the file between our open and our lock
            try:
                fd = os.open(self.lock_path, flags, 0o600)
            except OSError as exc:
                raise OutputRefused(exc.errno or errno.EIO,
                                    f"{where}: cannot write in {self.path.parent} "
                                    f"({exc.strerror or exc})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputRefused(
                        errno.EBUSY, f"{where} is being written by another inclinometer "
                                     f"command (it holds {self.lock_path.name}); wait for it "
                                     "or choose another file") from None
                raise OutputRefused(exc.errno or errno.EIO,
                                    f"{where}: cannot lock it ({exc.strerror or exc})") from None
            held, now = os.fstat(fd), _identity_nofollow(self.lock_path)
            if now == (held.st_dev, held.st_ino):
                self._fd = fd
                return self
            os.close(fd)  # we locked a lock file its holder had just removed: try again
        raise OutputRefused(errno.EBUSY, f"{where}: its lock file keeps changing")

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.lock_path)  # while still holding it (see acquire)
        os.close(fd)

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def _identity_nofollow(path: Path) -> tuple[int, int] | None:
    try:
        info = os.lstat(path)
    except OSError:
        return None
    return info.st_dev, info.st_ino


def _fsync_folder(folder: Path) -> None:
    with contextlib.suppress(OSError, AttributeError):
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def create_exclusive(folder: Path, stem: str, mode: int = 0o666,
                     suffix: str = "") -> tuple[int, Path]:
    """A new file in ``folder`` named ``.STEM.<random>.tmp`` (then ``suffix``), opened for
    writing: created exclusively, never through a link (O_EXCL | O_NOFOLLOW). Returns
    (fd, path)."""
    flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
             | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0))
    for _ in range(100):
        path = folder / f".{stem}.{secrets.token_hex(4)}.tmp{suffix}"
        try:
            return os.open(path, flags, mode), path
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temporary name in {folder}")


def _commit(temporary: Path, path: Path, *, inputs: Iterable[PathLike | None],
            overwrite: bool, option: str) -> None:
    """Put the finished temporary file in place (re-checking, as the target may have come)."""
    if not overwrite:
        try:
            os.link(temporary, path)  # fails if the target appeared meanwhile: never replaces
        except FileExistsError:
            raise OutputRefused(errno.EEXIST, f"{_describe(option, path)} appeared while it "
                                              "was written; it was left alone") from None
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV,
                                 errno.EMLINK):
                raise
            check_output(path, inputs=inputs, overwrite=False, option=option)
            os.replace(temporary, path)  # a file system without hard links
        else:
            os.unlink(temporary)
    else:
        check_output(path, inputs=inputs, overwrite=True, option=option)
        with contextlib.suppress(OSError):  # keep the permissions of the file replaced
            info = os.stat(path, follow_symlinks=False)
            if stat.S_ISREG(info.st_mode):
                os.chmod(temporary, stat.S_IMODE(info.st_mode))
        os.replace(temporary, path)
    _fsync_folder(path.parent)


@contextlib.contextmanager
def output_path(path: PathLike, *, inputs: Iterable[PathLike | None] = (),
                overwrite: bool = False, option: str = "",
                keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a new, empty temporary path beside ``path`` for a writer that opens files by
    name; when the block ends it is fsynced and put in place (see the module docstring).
    ``keep_suffix``: the temporary name ends like ``path`` (for writers that choose the format
    by the suffix)."""
    path = Path(path)
    inputs = list(inputs)
    check_output(path, inputs=inputs, overwrite=overwrite, option=option)
    with OutputLock(path, option):
        try:
            fd, temporary = create_exclusive(path.parent, path.name,
                                             suffix=path.suffix if keep_suffix else "")
        except OSError as exc:
            raise OutputRefused(exc.errno or errno.EIO,
                                f"{_describe(option, path)}: cannot write in {path.parent} "
                                f"({exc.strerror or exc})") from None
        os.close(fd)
        try:
            yield temporary
            fd = os.open(temporary, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            _commit(temporary, path, inputs=inputs, overwrite=overwrite, option=option)
        finally:
            with contextlib.suppress(OSError):
                os.unlink(temporary)


@contextlib.contextmanager
def output_file(path: PathLike, *, inputs: Iterable[PathLike | None] = (),
                overwrite: bool = False, option: str = "") -> Iterator[BinaryIO]:
    """Yield a binary file to write; it becomes ``path`` when the block ends without error."""
    with output_path(path, inputs=inputs, overwrite=overwrite, option=option) as temporary:
        flags = os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
        with os.fdopen(os.open(temporary, flags), "wb") as handle:
            yield handle
            handle.flush()


def write_output(path: PathLike, data: bytes | str, *, inputs: Iterable[PathLike | None] = (),
                 overwrite: bool = False, option: str = "") -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` safely; returns the path."""
    payload = data.encode("utf-8") if isinstance(data, str) else data
    with output_file(path, inputs=inputs, overwrite=overwrite, option=option) as handle:
        handle.write(payload)
    return Path(path)


@contextlib.contextmanager
def interrupts_held(on_held: Callable[[], None] | None = None) -> Iterator[list[int]]:
    """Hold Ctrl-C (SIGINT) and SIGTERM back while the block runs (a final rewrite that must
    finish); yields a list that collects the signals that came. In another thread than the
    main one (where handlers cannot be set) it does nothing."""
    held: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield held
        return

    def hold(signum: int, _frame: Any) -> None:
        held.append(signum)
        if on_held is not None:
            on_held()

    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError, OSError):
            previous[signum] = signal.signal(signum, hold)
    try:
        yield held
    finally:
        for signum, handler in previous.items():
            with contextlib.suppress(ValueError, OSError):
                signal.signal(signum, handler)
