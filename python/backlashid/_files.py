"""Writing output files atomically: into a temporary file beside the target, renamed onto it
only once complete, so an interrupted write (Ctrl-C, an exception, a full disk) leaves the old
file or none, never a truncated one."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


def _temporary(path: Path) -> tuple[int, Path]:
    """Create a new file beside ``path`` (same folder, so the rename stays on one file system)
    with the permissions a plain ``open(path, "w")`` would give; return its descriptor and path.

    Its name holds the writer's process id: the temporary files of ``path`` that a killed
    writer left (SIGKILL, a power cut: no handler runs) are removed here, the next time."""
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder: give a file name inside it", str(path))
    _remove_orphans(path)
    try:
        kept: int | None = path.stat().st_mode & 0o7777  # replacing a file keeps its permissions
    except OSError:
        kept = None
    while True:
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask applies, as for open()
        except FileExistsError:  # pragma: no cover - a name collision of 48 random bits
            continue
        if kept is not None:
            os.chmod(tmp, kept)
        return fd, tmp


def _remove_orphans(path: Path) -> None:
    """Remove the temporary files of ``path`` whose writing process no longer runs."""
    pattern = re.compile(rf"\.{re.escape(path.name)}\.(\d+)\.[0-9a-f]{{12}}\.tmp\Z")
    with contextlib.suppress(OSError):
        for sibling in path.parent.iterdir():
            found = pattern.match(sibling.name)
            if found and not _running(int(found.group(1))):
                with contextlib.suppress(OSError):
                    sibling.unlink()


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists (on this machine)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):  # exists but another user's, or no way to tell: keep its file
        return True
    return True


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w", **open_kwargs: Any) -> Iterator[IO[Any]]:
    """Open ``path`` for writing through a temporary file that replaces it on success.

    Parameters
    ----------
    path : str or PathLike
        The file to write; its folder must exist.
    mode : str, default "w"
        ``"w"`` (text) or ``"wb"`` (bytes).
    **open_kwargs
        Passed to :func:`os.fdopen` (``encoding``, ``newline``, ...).

    Yields
    ------
    file object
        The temporary file; when the block ends without an exception it is flushed to disk and
        renamed onto ``path`` (``os.replace``); on any exception, ``KeyboardInterrupt``
        included, it is removed and ``path`` is left as it was.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write writes whole files: mode 'w' or 'wb', not {mode!r}")
    target = Path(path)
    fd, tmp = _temporary(target)
    try:
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`atomic_write`)."""
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(text)


def save_figure(fig: Any, path: Any, **kwargs: Any) -> None:
    """``fig.savefig(path, **kwargs)``, atomically when ``path`` is a file name.

    The format comes from ``kwargs["format"]``, else from the file's extension (matplotlib's
    default format when it has none); a file object is written directly.
    """
    if not isinstance(path, (str, os.PathLike)):
        fig.savefig(path, **kwargs)
        return
    suffix = Path(path).suffix.lstrip(".").lower()
    if suffix and "format" not in kwargs:
        kwargs["format"] = suffix
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, **kwargs)
