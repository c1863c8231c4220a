"""The render scene hands meshes and lights to pyrender in a fixed order (pixel-identical clips)."""

from __future__ import annotations

import numpy as np

from stimuli.render.gl import ordered_scene, pyrender_module
from stimuli.render.scene import grey_material, quad, static_mesh


def test_meshes_and_lights_come_in_the_order_they_were_added():
    """pyrender's sets iterate in memory-address order, which changes per process: meshes tied in distance
    (belt, stripes and body all at the slot's pose) were drawn, and lights summed, in another order in
    every process, and one clip rendered in 6 processes gave 2–4 different files."""
    pyrender = pyrender_module()
    scene = ordered_scene()
    meshes = [scene.add(static_mesh(*quad(0, 1, 0, 1, 0.01 * i), grey_material())) for i in range(40)]
    lights = [scene.add(pyrender.DirectionalLight(intensity=0.1 * (i + 1))) for i in range(3)]
    scene.add(pyrender.PointLight(intensity=1.0), pose=np.eye(4))
    assert scene.mesh_nodes == meshes
    assert scene.light_nodes[:3] == lights and len(scene.light_nodes) == 4
    scene.add(pyrender.PerspectiveCamera(yfov=1.0), pose=np.eye(4))
    # pyrender's stable distance sort keeps the insertion order of nodes at the same distance
    assert pyrender.Renderer._sorted_mesh_nodes(None, scene) == meshes
