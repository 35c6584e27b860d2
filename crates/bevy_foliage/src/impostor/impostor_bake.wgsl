// Billboard-cloud texture bake (seed 001 §4.2): a plane's member triangles, seen by an
// orthographic camera down the plane's normal, written unlit into the plane's atlas rectangle —
// albedo and coverage in one pass, tangent-space normals in the other. `impostor::texture`'s
// `bake_reference` is the CPU reference of exactly this.

#import bevy_pbr::forward_io::VertexOutput

struct BakeParams {
    // Linear RGBA base colour.
    base_color: vec4<f32>,
    // xyz: the plane's tangent; w: 0 albedo pass, 1 normal pass.
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
    // Leaves are two-sided: the baked normal faces the plane's front, where its camera stands.
    var n = normalize(in.world_normal);
    if dot(n, params.normal.xyz) < 0.0 {
        n = -n;
    }
    let ts = vec3<f32>(dot(n, params.tangent.xyz), dot(n, params.bitangent.xyz), dot(n, params.normal.xyz));
    return vec4<f32>(ts * 0.5 + 0.5, 1.0);
}
