"""A pyrender mesh whose vertices change every frame without rebuilding anything.

pyrender uploads a primitive's interleaved vertex buffer (positions, normals, …) once, when the
primitive first enters a GL context. Afterwards :class:`DynamicMesh` overwrites that same buffer
with ``glBufferSubData`` — no new VAO, no new mesh, no new node — so a frame costs one upload of
V × 6 floats plus the draw call.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from stimuli.render.gl import make_current, pyrender_module


def vertex_normal_operator(faces: np.ndarray, n_vertices: int) -> scipy.sparse.csr_matrix:
    """Sparse (V, F) incidence matrix: vertex normal = sum of its faces' area-weighted normals."""
    rows = faces.reshape(-1)
    cols = np.repeat(np.arange(len(faces)), 3)
    return scipy.sparse.csr_matrix((np.ones(rows.size, np.float32), (rows, cols)), shape=(n_vertices, len(faces)))


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, operator) -> np.ndarray:
    """Unit vertex normals (V, 3) of one posed mesh (float32)."""
    v = np.asarray(vertices, np.float32)
    face_n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = operator @ face_n
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return n


class DynamicMesh:
    """One triangle mesh with a fixed topology and per-frame positions (normals recomputed)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, material, texcoords: np.ndarray | None = None):
        pyrender = pyrender_module()
        self.faces = np.asarray(faces, np.int64)
        self._operator = vertex_normal_operator(self.faces, len(vertices))
        self._texcoords = None if texcoords is None else np.asarray(texcoords, np.float32)
        normals = vertex_normals(vertices, self.faces, self._operator)
        self.primitive = pyrender.Primitive(
            positions=np.asarray(vertices, np.float32), normals=normals, texcoord_0=self._texcoords,
            indices=self.faces.astype(np.uint32), material=material, mode=pyrender.GLTF.TRIANGLES)
        self.mesh = pyrender.Mesh([self.primitive])
        self._interleaved = None

    def update(self, vertices: np.ndarray, texcoords: np.ndarray | None = None) -> None:
        """Set new positions (V, 3) (and optionally texture coordinates) for the next render."""
        positions = np.asarray(vertices, np.float32)
        normals = vertex_normals(positions, self.faces, self._operator)
        if texcoords is not None:
            self._texcoords = np.asarray(texcoords, np.float32)
        prim = self.primitive
        if prim._vaid is None:  # not uploaded yet: pyrender will upload these on the first render
            prim.positions, prim.normals = positions, normals
            if texcoords is not None:
                prim.texcoord_0 = self._texcoords
            return
        parts = [positions, normals] + ([self._texcoords] if self._texcoords is not None else [])
        data = np.ascontiguousarray(np.hstack(parts), dtype=np.float32)
        from OpenGL import GL

        make_current()
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, prim._buffers[0])
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, data.nbytes, data)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
