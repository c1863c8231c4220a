"""Write output files atomically (a temporary name in the same folder, renamed at the end); read input files
only when they are regular files of a bounded size.

A failure (or Ctrl-C) never leaves a half-written response file or report behind, and an input that is a
device (``/dev/zero``), a FIFO or a socket is refused before it is opened (reading one never ends).

>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "x.csv"
>>> atomic_write_text(p, "a,b\\n1,2\\n"); p.read_text()
'a,b\\n1,2\\n'
"""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
from pathlib import Path

from analysis.errors import AnalysisError

# Largest input file read (bytes): a response export of 1,000 respondents × 500 questions, or a jsPsych file of
# 100,000 trials, is well under it; the text, its parsed cells and the tables built from it need ~20× in memory.
MAX_INPUT_BYTES = 256 * 1024 * 1024

_NOT_REGULAR = ((stat.S_ISFIFO, "a FIFO, a named pipe"), (stat.S_ISCHR, "a character device"),
                (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def read_input_bytes(path: str | Path, what: str = "input file") -> bytes:
    """The bytes of ``path``, refusing (before opening it) anything but a regular file of at most
    :data:`MAX_INPUT_BYTES` bytes; ``what`` names the file in messages.

    Opening a FIFO blocks until a writer comes and ``/dev/zero`` never ends, so the kind of file is checked
    first; the read itself stops one byte past the limit, as a file may grow after it was checked.

    >>> read_input_bytes("/dev/zero", "response file")   # doctest: +ELLIPSIS
    Traceback (most recent call last):
    analysis.errors.AnalysisError: /dev/zero: not a regular file (a character device); expected a response file ...
    """
    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise AnalysisError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise AnalysisError(f"{path}: cannot be read ({exc.strerror})") from None
    if stat.S_ISDIR(info.st_mode):
        raise AnalysisError(f"{path}: is a directory; expected one {what}")
    if not stat.S_ISREG(info.st_mode):
        kind = next((name for test, name in _NOT_REGULAR if test(info.st_mode)), "not a plain file")
        raise AnalysisError(f"{path}: not a regular file ({kind}); expected a {what} saved as a file")
    limit = MAX_INPUT_BYTES
    if info.st_size > limit:
        raise AnalysisError(_too_large(path, info.st_size, limit, what))
    try:
        with open(path, "rb") as handle:
            data = handle.read(limit + 1)
    except OSError as exc:
        raise AnalysisError(f"{path}: cannot be read ({exc.strerror})") from None
    if len(data) > limit:
        raise AnalysisError(_too_large(path, len(data), limit, what, grew=True))
    return data


def _too_large(path: Path, size: int, limit: int, what: str, grew: bool = False) -> str:
    size_text = f"grew past {limit:,} bytes while it was read" if grew else f"is {size:,} bytes"
    return (f"{path}: {size_text}, over the limit of {limit:,} bytes for a {what}; split it into several "
            f"files (a folder of response files is read as one data set)")


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same directory."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs are shared files
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    current = os.umask(0)
    os.umask(current)
    return current


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def check_output_file(path: str | Path, option: str, inputs: list[str | Path] = ()) -> Path:
    """Refuse an output file path that cannot be written, before any work is done.

    Checked up front so that a long simulation does not end in a traceback: the path must not be a
    folder, no existing part of its parent path may be a file, and it must not be one of ``inputs``
    (writing the result over the data it came from).

    >>> import tempfile, pathlib
    >>> check_output_file(pathlib.Path(tempfile.mkdtemp()), "--out")   # doctest: +ELLIPSIS
    Traceback (most recent call last):
    analysis.errors.AnalysisError: --out ...: is a folder; expected a file name
    """
    path = Path(path)
    if path.is_dir():
        raise AnalysisError(f"{option} {path}: is a folder; expected a file name")
    _check_parents(path, option)
    for given in inputs:
        if given is not None and Path(given).resolve() == path.resolve():
            raise AnalysisError(f"{option} {path}: is the input {given}; choose another file name")
    return path


def check_output_folder(path: str | Path, option: str, inputs: list[str | Path] = ()) -> Path:
    """Refuse an output folder that would replace a file, or an input, before any work is done.

    The report folder replaces an existing folder of the same name as a whole, so ``path`` must not be
    (or contain) one of ``inputs`` and must not be a file.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise AnalysisError(f"{option} {path}: exists and is not a folder; expected a folder for the report")
    _check_parents(path, option)
    target = path.resolve()
    for given in inputs:
        source = Path(given).resolve()
        if source == target or target in source.parents:
            raise AnalysisError(f"{option} {path}: would replace the input {given}; choose another folder")
    return path


def _check_parents(path: Path, option: str) -> None:
    """The nearest existing ancestor of ``path`` must be a writable folder (else writing fails at the end).

    The stimuli side has its own copy (``stimuli.fileio``): analysis never imports stimuli.
    """
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise AnalysisError(f"{option} {path}: {parent} is a file, not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise AnalysisError(f"{option} {path}: the folder {parent} is not writable")
            return


def replace_directory(staging: Path, target: Path) -> None:
    """Move a fully written staging directory into place (the old one, if any, is removed first)."""
    os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes 0700
    if target.exists():
        backup = target.with_name(f".{target.name}.old")
        shutil.rmtree(backup, ignore_errors=True)
        os.replace(target, backup)
        os.replace(staging, target)
        shutil.rmtree(backup, ignore_errors=True)
    else:
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging, target)
