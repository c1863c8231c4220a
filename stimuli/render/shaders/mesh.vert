#version 330 core
// shapemotion: pyrender's mesh.vert without the per-vertex matrix inverse (poses here are rigid).
layout(location = 0) in vec3 position;
#ifdef NORMAL_LOC
layout(location = NORMAL_LOC) in vec3 normal;
#endif
#ifdef TEXCOORD_0_LOC
layout(location = TEXCOORD_0_LOC) in vec2 texcoord_0;
#endif
#ifdef COLOR_0_LOC
layout(location = COLOR_0_LOC) in vec4 color_0;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;

uniform vec3 cam_pos;

// Shading happens in the mesh's own (rotated) frame: normal and view direction are turned back by
// the mesh's rotation, so the lights turn with each figure's slot (mesh.frag).
out vec3 frag_view;        // towards the camera, in the mesh's frame
out vec3 frag_local;       // the mesh's own coordinates: where the contact shadow falls (mesh.frag)
#ifdef NORMAL_LOC
out vec3 frag_normal;
#endif
#ifdef TEXCOORD_0_LOC
out vec2 uv_0;
#endif
#ifdef COLOR_0_LOC
out vec4 color_multiplier;
#endif

void main()
{
    mat4 model = M * inst_m;
    gl_Position = P * V * model * vec4(position, 1.0);
    vec3 world = vec3(model * vec4(position, 1.0));
    frag_view = transpose(mat3(model)) * (cam_pos - world);   // poses are rigid: transpose = inverse
    frag_local = position;
#ifdef NORMAL_LOC
    frag_normal = normal;
#endif
#ifdef TEXCOORD_0_LOC
    uv_0 = texcoord_0;
#endif
#ifdef COLOR_0_LOC
    color_multiplier = color_0;
#endif
}
