"""Offscreen OpenGL for pyrender: EGL first, OSMesa as the fallback, one renderer per process.

``PYOPENGL_PLATFORM`` must be set before PyOpenGL is first imported, so every module of this
package that needs pyrender gets it through :func:`pyrender_module`. On a machine without a GPU,
EGL runs on Mesa's llvmpipe (software rasteriser); with a GPU it uses the vendor's EGL.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from stimuli.errors import StimuliError

_STATE: dict[str, object] = {}


def pyrender_module():
    """Import pyrender with an offscreen platform chosen (``egl`` unless the user set one)."""
    if "pyrender" not in _STATE:
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        # llvmpipe would start one raster thread per core in every worker process; the pool
        # already keeps both cores busy, so extra threads only add contention.
        os.environ.setdefault("LP_NUM_THREADS", "1")
        import pyrender

        _STATE["pyrender"] = pyrender
    return _STATE["pyrender"]


def ordered_scene(**kwargs):
    """A ``pyrender.Scene`` that hands its meshes and lights to the renderer in the order they were added.

    pyrender keeps nodes in sets, which iterate in memory-address order: a different order in every
    process. Meshes at the same distance from the camera (belt, stripes, frame and body all sit at
    the slot's pose) were drawn in that order, and the lights' terms summed in it, so one clip
    rendered in three processes gave three files (up to 20 grey levels apart on a few dozen pixels).
    """
    if "scene_type" not in _STATE:
        base = pyrender_module().Scene

        class OrderedScene(base):
            def add_node(self, node, parent_node=None):
                self.__dict__.setdefault("_added", {}).setdefault(node, len(self._added))
                return super().add_node(node, parent_node)

            @property
            def mesh_nodes(self):
                return sorted(base.mesh_nodes.fget(self), key=self._added.__getitem__)

            @property
            def light_nodes(self):
                return sorted(base.light_nodes.fget(self), key=self._added.__getitem__)

        _STATE["scene_type"] = OrderedScene
    return _STATE["scene_type"](**kwargs)


def renderer(width: int, height: int):
    """The process's one ``OffscreenRenderer``, resized in place when a clip needs another size."""
    pyrender = pyrender_module()
    current = _STATE.get("renderer")
    if current is None:
        current = _create(pyrender, width, height)
        _install_fast_paths(current)
        _STATE["renderer"] = current
    elif (current.viewport_width, current.viewport_height) != (width, height):
        current.viewport_width, current.viewport_height = width, height
    return current


def _create(pyrender, width: int, height: int):
    try:
        return pyrender.OffscreenRenderer(width, height)
    except Exception as exc:  # EGL missing or broken: say which platform failed and what to try
        platform = os.environ.get("PYOPENGL_PLATFORM")
        raise StimuliError(
            f"offscreen rendering: cannot create an OpenGL context with PYOPENGL_PLATFORM={platform} "
            f"({type(exc).__name__}: {exc}). Install libegl1 (EGL) or libosmesa6 with PyOpenGL >= 3.1.5 "
            "and set PYOPENGL_PLATFORM=osmesa") from exc


SHADER_DIR = Path(__file__).with_name("shaders")


class _ShaderCache:
    """pyrender's program cache, except that meshes use the matte shaders of ``shaders/``."""

    def __init__(self, pyrender):
        from pyrender.shader_program import ShaderProgramCache

        self.ours = ShaderProgramCache(shader_dir=str(SHADER_DIR))
        self.default = ShaderProgramCache()

    def get_program(self, vertex_shader, fragment_shader, geometry_shader=None, defines=None):
        cache = self.ours if (vertex_shader, fragment_shader) == ("mesh.vert", "mesh.frag") else self.default
        return cache.get_program(vertex_shader, fragment_shader, geometry_shader, defines)

    def clear(self):
        self.ours.clear()
        self.default.clear()


def _install_fast_paths(offscreen) -> None:
    """Matte shaders and a colour-only read-back (pyrender also reads and linearises depth)."""
    inner = offscreen._renderer
    inner._program_cache = _ShaderCache(pyrender_module())

    def read_colour(scene, flags):
        from OpenGL import GL

        width, height = inner._main_fb_dims
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb_ms)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, inner._main_fb)
        GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb)
        rgba = bool(flags & pyrender_module().RenderFlags.RGBA)
        data = GL.glReadPixels(0, 0, width, height, GL.GL_RGBA if rgba else GL.GL_RGB, GL.GL_UNSIGNED_BYTE)
        colour = np.frombuffer(data, dtype=np.uint8).reshape(height, width, 4 if rgba else 3)
        return colour[::-1], None

    inner._read_main_framebuffer = read_colour


def make_current() -> None:
    """Make the renderer's GL context current (needed before touching GL buffers directly)."""
    r = _STATE.get("renderer")
    if r is not None:
        r._platform.make_current()


def device_name() -> str:
    """The OpenGL renderer string (e.g. ``llvmpipe`` or the GPU's name), for benchmarks and logs."""
    make_current()
    from OpenGL import GL

    name = GL.glGetString(GL.GL_RENDERER)
    return name.decode() if isinstance(name, bytes) else str(name)
