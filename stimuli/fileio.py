"""Writing files so that a crash or Ctrl-C never leaves a half-written output behind."""

from __future__ import annotations

import csv
import io
import os
import tempfile
from pathlib import Path


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
