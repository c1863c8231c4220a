"""Anny as the body backend: one model per process, its cache under the project's cache folder.

Everything that touches the ``anny`` package lives here (plus ``frame.py`` for the axes), so a
new Anny release is checked in one module. Importing this module does not import torch; the
first call to :func:`model` does (about 2 s), and the first model build ever writes Anny's
cache (about 1 min, 0.8 GB), later loads take well under a second.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# Anny's own density (kg/m³) in anny.Anthropometry: mass = volume × density.
ANNY_DENSITY = 980.0
LOAD_SECONDS: dict[str, float] = {}


def project_cache_root() -> Path:
    """``$SHAPEMOTION_CACHE`` or the project's ``.cache`` folder (the checkout holding ``stimuli/``)."""
    configured = os.environ.get("SHAPEMOTION_CACHE")
    if configured:
        return Path(configured).expanduser()
    project = Path(__file__).resolve().parents[2]
    if (project / "pyproject.toml").exists():
        return project / ".cache"
    return Path.cwd() / ".cache"


def anny_cache_dir() -> Path:
    """``ANNY_CACHE_DIR`` when the user set it, else ``<project cache>/anny`` (never the home folder)."""
    configured = os.environ.get("ANNY_CACHE_DIR")
    return Path(configured).expanduser() if configured else project_cache_root() / "anny"


@functools.cache
def code_digest() -> str:
    """SHA-256 (first 16 hex digits) of this package's code, part of every body cache key.

    A change to the fitter, the measurements or the rig makes other bodies, so bodies cached by
    older code must not be reused: they were, under an unchanged version string, and a cached run
    then reported BMIs that a fresh fit no longer gives (up to 0.01 apart), physics results with them.
    """
    from stimuli.fileio import source_digest

    return source_digest("bodies", suffixes=(".py",))[:16]


def anny_version() -> str:
    """Installed Anny version (part of every body cache key)."""
    try:
        return importlib.metadata.version("anny")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


# Warp's native library says this on stderr at start-up on every machine without an NVIDIA GPU, twice
# per render (one per worker): Anny's skinning runs on the CPU, so it tells the user nothing.
NO_CUDA_DRIVER = "Could not find or load the NVIDIA CUDA driver"


@contextlib.contextmanager
def _native_stderr_without(benign: str):
    """Hold back one known line that native code writes to file descriptor 2; pass every other line on."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            for line in held.read().decode(errors="replace").splitlines():
                if benign not in line:
                    print(line, file=sys.stderr)


def drop_damaged_safetensors(folder: Path) -> list[Path]:
    """Remove the ``.safetensors`` files under ``folder`` whose header or data do not read (a file
    cut short); return them. Files that read are kept.

    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "cut.safetensors").write_bytes(b"\\x10\\x00\\x00\\x00\\x00\\x00\\x00\\x00{")
    >>> [p.name for p in drop_damaged_safetensors(folder)], list(folder.iterdir())
    (['cut.safetensors'], [])
    """
    from safetensors import safe_open

    damaged = []
    for path in sorted(Path(folder).rglob("*.safetensors")):
        try:
            with safe_open(str(path), "numpy") as handle:
                handle.keys()
        except Exception:
            path.unlink(missing_ok=True)
            damaged.append(path)
    return damaged


@functools.lru_cache(maxsize=1)
def model():
    """The Anny full-body model (default rig and topology), loaded once per process.

    ``extrapolate_phenotypes=True`` only matters outside [0, 1], which the fitter allows a little
    for weight/muscle to reach BMI 40 for women; inside [0, 1] results are identical.
    """
    # Warp (Anny's CPU skinning kernels) compiles into the home folder unless told otherwise.
    os.environ.setdefault("WARP_CACHE_PATH", str(project_cache_root() / "warp"))
    start = time.perf_counter()
    import torch  # noqa: F401  (timed with the model: it is the bulk of a cold start)
    import warp

    warp.config.log_level = warp.LOG_WARNING  # its start-up banner would repeat in every render worker's output
    with _native_stderr_without(NO_CUDA_DRIVER):
        warp.init()
    import anny
    from anny.paths import set_anny_cache_path

    from stimuli.fileio import folder_lock

    LOAD_SECONDS["import"] = time.perf_counter() - start
    cache = anny_cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    set_anny_cache_path(cache)
    start = time.perf_counter()
    # Anny writes its cache files in place, so a process starting while another still writes an
    # empty cache (two test, render or Dask workers on a fresh clone) could read a file cut short and
    # remove it as damaged under the writer: one process builds or loads at a time, the next waits.
    with folder_lock(cache):
        try:
            built = anny.Anny(extrapolate_phenotypes=True)
        except Exception:
            # Anny writes its cache in place: a write cut short (a full disk) leaves a file that every
            # later start fails on. Remove only the files that do not read, and build them again.
            damaged = drop_damaged_safetensors(cache)
            if not damaged:
                raise
            print(f"Anny's model cache {cache}: {len(damaged)} damaged file(s) (a write cut short) removed; "
                  "building them again (about a minute)", file=sys.stderr)
            built = anny.Anny(extrapolate_phenotypes=True)
    built.eval()
    LOAD_SECONDS["model"] = time.perf_counter() - start
    return built


def evaluate(phenotypes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Rest-pose bodies for a batch of phenotype vectors (Anny frame, float64 numpy).

    Returns ``rest_vertices`` (B, V, 3), ``rest_bone_heads`` (B, J, 3),
    ``rest_bone_poses`` (B, J, 4, 4), and Anny's own ``height``, ``volume``, ``waist`` (B,).
    """
    import torch

    m = model()
    batch = max(np.size(v) for v in phenotypes.values())
    kwargs = {
        k: torch.as_tensor(np.broadcast_to(np.asarray(v, float), (batch,)).copy(), dtype=m.dtype)
        for k, v in phenotypes.items()
    }
    with torch.no_grad():
        rest = m(phenotype_kwargs=kwargs)
        vertices = rest["rest_vertices"]
        anthro = _anthropometry()
        # Anny's own definitions, each computed once (its __call__ recomputes the volume three times).
        measured = {"height": anthro.height(vertices), "volume": anthro.volume(vertices),
                    "waist": anthro.waist_circumference(vertices)}
    keep = ("rest_vertices", "rest_bone_heads", "rest_bone_poses")
    out = {k: rest[k].cpu().numpy() for k in keep}
    out.update({k: v.cpu().numpy() for k, v in measured.items()})
    return out


@functools.lru_cache(maxsize=1)
def _anthropometry():
    import anny

    return anny.Anthropometry(model())


@functools.lru_cache(maxsize=1)
def topology() -> dict[str, object]:
    """Faces, skinning weights/indices, bone names and parents (shared by every Anny body)."""
    m = model()
    return {
        "faces": m.faces.cpu().numpy().astype(np.int64),
        "weights": m.vertex_bone_weights.cpu().numpy(),
        "indices": m.vertex_bone_indices.cpu().numpy().astype(np.int64),
        "bone_names": list(m.bone_labels),
        "bone_parents": np.asarray(m.bone_parents, dtype=np.int64),
    }


def skin(rest_vertices, bone_transforms):
    """Anny's linear-blend skinning of (1 or T, V, 3) rest vertices by (T, J, 4, 4) transforms (torch)."""
    m = model()
    rest = rest_vertices.expand(bone_transforms.shape[0], -1, -1)
    return m.get_skinned_vertices(rest, bone_transforms)
