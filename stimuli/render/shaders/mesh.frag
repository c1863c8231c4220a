#version 330 core
// shapemotion: plain matte shading (wrapped Lambert + a faint highlight) instead of pyrender's PBR.
// Same uniform names as pyrender, so its renderer binds lights and materials unchanged; the
// result is in display space (no sRGB round trip) and costs a fraction of the PBR shader.
struct DirectionalLight {
    vec3 color;
    float intensity;
    vec3 direction;
};

struct Material {
    vec3 emissive_factor;
    vec4 base_color_factor;
    float metallic_factor;
    float roughness_factor;
#ifdef HAS_BASE_COLOR_TEX
    sampler2D base_color_texture;
#endif
};

uniform Material material;
uniform DirectionalLight directional_lights[MAX_DIRECTIONAL_LIGHTS];
uniform int n_directional_lights;
uniform vec3 ambient_light;

in vec3 frag_view;
in vec3 frag_local;
#ifdef NORMAL_LOC
in vec3 frag_normal;
#endif
#ifdef TEXCOORD_0_LOC
in vec2 uv_0;
#endif
#ifdef COLOR_0_LOC
in vec4 color_multiplier;
#endif

out vec4 frag_color;

void main()
{
    vec4 base = material.base_color_factor;
#ifdef HAS_BASE_COLOR_TEX
#ifdef TEXCOORD_0_LOC
    base *= texture(material.base_color_texture, uv_0);
#endif
#endif
#ifdef COLOR_0_LOC
    base *= color_multiplier;
#endif
    if (material.emissive_factor.r > 0.0) {
        frag_color = base;  // unlit surface (the floor): its colours are final display colours
        return;
    }
    vec3 v = normalize(frag_view);
#ifdef NORMAL_LOC
    vec3 n = normalize(frag_normal);
#else
    vec3 n = v;
#endif
    if (dot(n, v) < 0.0) {
        n = -n;  // two-sided: the inside of a mouth or ear is lit like the outside
    }
    vec3 light = ambient_light;
    float highlight = 0.0;
    float shine = 1.0 - material.roughness_factor;
    // A compile-time bound lets the shader compiler unroll the loop (much faster on llvmpipe);
    // the scene always has exactly MAX_DIRECTIONAL_LIGHTS directional lights.
    // n and v are in the mesh's own frame (mesh.vert), so the lights, set for an unturned figure,
    // turn with each mesh's rotation (a side-by-side slot is turned ~20 deg to face the camera):
    // both figures are lit alike, not one more from the front than the other.
    for (int i = 0; i < MAX_DIRECTIONAL_LIGHTS; i++) {
        vec3 l = -directional_lights[i].direction;
        float wrapped = max((dot(n, l) + 0.25) * 0.8, 0.0);  // soft terminator: "soft" lights
        light += directional_lights[i].color * directional_lights[i].intensity * wrapped;
        float s = max(dot(n, normalize(l + v)), 0.0);
        s *= s; s *= s; s *= s; s *= s; s *= s;            // s^32 without pow()
        highlight += directional_lights[i].intensity * shine * 0.25 * s;
    }
    vec3 colour = clamp(base.rgb * light + vec3(highlight), 0.0, 1.0);
    // Contact shadow: metallic_factor (unused by this matte shader) is how much a surface darkens
    // under the figure standing at its origin -- a soft elliptical blob, 0.32 m across and 0.50 m
    // along the belt (1/e radii), so the feet do not look pasted on (stimuli.render.treadmill).
    if (material.metallic_factor > 0.0) {
        vec2 q = frag_local.xz / vec2(0.32, 0.50);
        colour *= 1.0 - material.metallic_factor * exp(-dot(q, q));
    }
    frag_color = vec4(colour, base.a);
}
