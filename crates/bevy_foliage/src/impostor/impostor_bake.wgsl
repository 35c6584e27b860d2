// Billboard-cloud texture bake (seed 001 §4.2): a plane's member triangles, seen by an
// orthographic camera down the plane's normal, written unlit into the plane's atlas rectangle —
// albedo and coverage in one pass, tangent-space normals in the second, the tree lighting's values
// of the leaf (eight attenuations and "a leaf", from the vertex colours) in the next three. Alpha
// is always one (coverage): an alpha below one comes back multiplied into the colour. `impostor::texture`'s `bake_reference` is the CPU reference of exactly this.

#import bevy_pbr::forward_io::VertexOutput

struct BakeParams {
    // Linear RGBA base colour.
    base_color: vec4<f32>,
    // xyz: the plane's tangent; w: the pass (0 albedo, 1 normal, 2 and 3 light).
    tangent: vec4<f32>,
    // xyz: the plane's bitangent; w: alpha cutoff.
    bitangent: vec4<f32>,
    // xyz: the plane's normal; w: 1 if the colour texture is used.
    normal: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: BakeParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(1) var color_texture: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(2) var color_sampler: sampler;

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    var color = params.base_color;
#ifdef VERTEX_UVS_A
    if params.normal.w > 0.5 {
        color *= textureSample(color_texture, color_sampler, in.uv);
    }
#endif
    if color.a < params.bitangent.w {
        discard;
    }
    if params.tangent.w < 0.5 {
        return vec4<f32>(color.rgb, 1.0);
    }
    if params.tangent.w > 1.5 {
#ifdef VERTEX_COLORS
        return vec4<f32>(in.color.rgb, 1.0);
#else
        return vec4<f32>(1.0);
#endif
    }
    // Leaves are two-sided: the baked normal faces the plane's front, where its camera stands.
    var n = normalize(in.world_normal);
    if dot(n, params.normal.xyz) < 0.0 {
        n = -n;
    }
    let ts = vec3<f32>(dot(n, params.tangent.xyz), dot(n, params.bitangent.xyz), dot(n, params.normal.xyz));
    return vec4<f32>(ts * 0.5 + 0.5, 1.0);
}
