"""Write files so that they appear complete or not at all; write and read JSON documents that way, with
one-line errors naming the file."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
from collections.abc import Iterator, Sequence

#: Characters of the target's name kept in the temporary name: with the token, ".partial" and the
#: extension it stays under the 255 bytes a file name may hold (4 bytes a character at most in UTF-8).
STEM_CHARS = 40


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, suffix: str | None = None) -> Iterator[str]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds.

    On any exception the temporary file is removed and ``path`` is left untouched, so an
    interrupted or failed write never leaves a half-written output. An OSError names ``path``,
    never the hidden temporary name: a folder at ``path``, and a folder that cannot be written,
    are refused before the block runs, with their real cause.

    A device or pipe at ``path`` (``/dev/stdout``, ``/dev/null``) is written in place: renaming
    onto it would replace the device itself.

    Args:
        path: the output file.
        suffix: how the temporary name ends (default: ``path``'s extension), for writers that
            append their own extension to any other name (ezc3d adds ".c3d" unless the name ends
            so, as ``x.C3D`` does not). Such a writer names its own file, so it cannot write to a
            device or pipe: that is refused.

    Raises:
        OSError: naming ``path``.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise IsADirectoryError(errno.EISDIR, "is a folder; give a file name", path)
    if os.path.exists(path) and not os.path.isfile(path):
        if suffix is not None:
            raise OSError(errno.EINVAL, "is not a regular file (a device or pipe); give a file name", path)
        try:
            yield path
        except OSError as exc:
            _name(exc, path, path)
            raise
        return
    tmp = _probed(path, suffix)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        if isinstance(exc, OSError):
            _name(exc, path, tmp)
        raise


def _probed(path: str, suffix: str | None = None) -> str:
    """A free temporary name beside ``path`` (ending as ``path`` or in ``suffix``), its folder made
    and proven writable: the name is created and removed at once, so that a folder that cannot be
    written fails here with its real cause (a writer may say something confusing, and ezc3d says
    nothing at all). Not left in place: writers such as Blender back up an existing target as
    ``.blend1``."""
    folder = os.path.dirname(os.path.abspath(path))
    stem, ext = os.path.splitext(os.path.basename(path))
    ending = ext if suffix is None else suffix
    tmp = os.path.join(folder, f".{stem[:STEM_CHARS]}.{secrets.token_hex(4)}.partial{ending}")
    try:
        os.makedirs(folder, exist_ok=True)
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        os.remove(tmp)
    except OSError as exc:
        raise type(exc)(exc.errno, f"cannot write in {folder} ({exc.strerror})", path) from None
    return tmp


def check_outputs(outputs: Sequence[str | os.PathLike | None], inputs: Sequence[str | os.PathLike] = ()) -> None:
    """Refuse, before any work, every output a command would fail to write at its end: a folder, a
    folder that cannot be written, one of the ``inputs`` (the raw take would be overwritten), or
    the same file named for two outputs. Then a failed output never leaves the others written.

    Raises:
        OSError: naming the first output refused.
    """
    seen: set[str] = set()
    read = {os.path.realpath(os.fspath(p)) for p in inputs}
    for given in outputs:
        if given is None:
            continue
        path = os.fspath(given)
        real = os.path.realpath(path)
        if os.path.isdir(path):
            raise IsADirectoryError(errno.EISDIR, "is a folder; give a file name", path)
        if os.path.exists(path) and not os.path.isfile(path):  # a device or pipe (/dev/null) is written in place
            continue
        if real in read:
            raise OSError(errno.EEXIST, "is an input of this command; give another file name for the output", path)
        if real in seen:
            raise OSError(errno.EEXIST, "is given for two outputs; give each its own file name", path)
        seen.add(real)
        folder = os.path.dirname(os.path.abspath(path))
        if os.path.isdir(folder):
            _probed(path)
            continue
        above = folder  # made by the writer at the end: nothing is made before the work succeeds
        while not os.path.exists(above):
            above = os.path.dirname(above)
        if not os.path.isdir(above):
            raise NotADirectoryError(errno.ENOTDIR, f"cannot write in {folder} ({above} is a file)", path)
        if not os.access(above, os.W_OK | os.X_OK):
            raise PermissionError(errno.EACCES, f"cannot write in {folder} ({above} cannot be written)", path)


def _name(exc: OSError, path: str, tmp: str) -> None:
    """``exc`` naming ``path`` where it named ``tmp`` or no file (a failed write() names none): the
    user's output, not the hidden temporary name nor the input the caller was reading."""
    if exc.filename is None or exc.filename == tmp:
        exc.filename, exc.filename2 = path, None


def write_json(path: str | os.PathLike, data) -> None:
    """``data`` as indented JSON at ``path``, atomically."""
    with atomic_output(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
        f.write("\n")


def read_json(path: str | os.PathLike, what: str):
    """The JSON document at ``path``; a missing or unreadable file is one :class:`.errors.MocapInputError`
    naming it and ``what`` it should be (``"calibration"``, ``"bone map"``)."""
    from .errors import MocapInputError

    where = os.fspath(path)
    try:
        with open(where, encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError:
        raise MocapInputError(where, f"{what} file not found") from None
    except (OSError, ValueError) as exc:
        raise MocapInputError(where, f"not a readable {what} JSON ({exc})") from None
