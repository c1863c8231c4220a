"""Writing files so that a crash or Ctrl-C never leaves a half-written output behind."""

from __future__ import annotations

import argparse
import csv
import io
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from stimuli.errors import StimuliError


def csv_text(rows: list[dict[str, object]]) -> str:
    """Rows (dicts with the same keys, in column order) as CSV text with a header and '\\n' line ends."""
    buffer = io.StringIO()
    if rows:
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return buffer.getvalue()


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write to a temporary file next to ``path`` and rename it into place."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
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


def write_all_or_nothing(out_dir: str | Path, files: dict[str, str]) -> list[Path]:
    """Write several text files: all contents are ready before the first is written, each atomically."""
    out_dir = Path(out_dir)
    written = []
    for name, text in files.items():
        atomic_write_text(out_dir / name, text)
        written.append(out_dir / name)
    return written


def output_path(text: str) -> Path:
    """An ``argparse`` type for output paths: ``Path("")`` is ``.``, so an empty ``--out ""`` (an unset
    shell variable) wrote into the current folder; it is refused instead (argparse: exit 2).

    >>> output_path("out/design")
    PosixPath('out/design')
    """
    if not text.strip():
        raise argparse.ArgumentTypeError(f"an empty path ({text!r}) would write into the current folder; "
                                         "give a file or folder name (. for the current folder)")
    return Path(text)


def check_output_file(path: str | Path | None, option: str = "--out") -> Path | None:
    """Fail before any work when ``path`` cannot become a file: it is a folder, or a file stands where
    one of its folders should be, or that folder is read-only. ``None`` (option not given) passes.

    Checked up front so that a command never computes for minutes and then fails on writing, nor
    writes one output and fails on the next.

    >>> check_output_file("out/clip.mp4")
    PosixPath('out/clip.mp4')
    """
    if path is None:
        return None
    path = Path(path)
    if path.is_dir():
        raise StimuliError(f"{option} {path}: is a folder; expected a file name")
    _check_parent_folder(path, option)
    return path


def check_output_dir(path: str | Path | None, option: str = "--out") -> Path | None:
    """Fail before any work when ``path`` cannot become (or be) a folder of outputs (see
    :func:`check_output_file`). ``None`` passes."""
    if path is None:
        return None
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise StimuliError(f"{option} {path}: is a file; expected a folder")
    if path.is_dir():
        if not os.access(path, os.W_OK | os.X_OK):
            raise StimuliError(f"{option} {path}: the folder is not writable")
        return path
    _check_parent_folder(path, option)
    return path


def _check_parent_folder(path: Path, option: str) -> None:
    """The nearest existing ancestor of ``path`` must be a writable folder (missing ones are made)."""
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise StimuliError(f"{option} {path}: {parent} is a file, not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise StimuliError(f"{option} {path}: the folder {parent} is not writable")
            return


# Matplotlib stamps the time into SVG (dc:date), PDF (CreationDate) and PNG (Software) files and draws
# SVG element ids at random: without these the same figure gave different bytes on every run.
FIGURE_METADATA = {".png": {"Software": None}, ".svg": {"Date": None}, ".pdf": {"CreationDate": None}}


def save_figure(fig, path: str | Path, dpi: float = 110) -> Path:
    """Write a matplotlib figure so that the same figure gives the same bytes (no dates, fixed SVG ids)."""
    import matplotlib

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with matplotlib.rc_context({"svg.hashsalt": "shapemotion"}):
        fig.savefig(path, dpi=dpi, metadata=FIGURE_METADATA.get(path.suffix.lower()))
    return path


@contextmanager
def folder_lock(folder: str | Path, busy: str | None = None):
    """Hold an exclusive ``flock`` on a folder (on the folder itself, so no lock file is left behind,
    and the kernel drops it however the process ends).

    Without ``busy``, wait for another process's lock; with it, do not wait: a folder another process
    holds raises ``StimuliError(busy)``. Where ``flock`` does not exist (Windows) nothing is locked.
    """
    try:
        import fcntl
    except ImportError:
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (fcntl.LOCK_NB if busy else 0))
        except BlockingIOError:
            raise StimuliError(busy) from None
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


def source_digest(*folders: str, suffixes: tuple[str, ...] = (".py", ".json", ".bvh", ".vert", ".frag")) -> str:
    """SHA-256 of the files (of ``suffixes``) in these folders of the ``stimuli`` package.

    Caches key their results with it, so that a change to the code that makes them is never
    answered with a result made by the old code (a hand-bumped version string was forgotten).
    """
    import hashlib

    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for folder in folders:
        for path in sorted((root / folder).glob("*")):
            if path.suffix in suffixes:
                digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()
