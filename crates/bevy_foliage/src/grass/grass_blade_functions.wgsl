#define_import_path bevy_foliage::grass_blade

// The blade material's bindings and its per-fragment test, shared by the blade vertex stage
// (`grass_blade_vertex.wgsl`) and fragment stages
// (`grass_blade.wgsl`, and `grass_blade_soft.wgsl` where the blades receive screen-space soft
// shadows).
#import bevy_foliage::grass_functions as grass
#ifdef BLADE_TERMS
#import bevy_pbr::forward_io::VertexOutput
#endif

// What the main pass's vertex stage hands its fragments (`BLADE_TERMS`): Bevy's forward outputs
// (rebuilt by `forward_input`) and, worked out once per vertex, the terrain's ambient occlusion
// at the blade and the point's height above the ground.
struct BladeVertexOutput {
    @builtin(position) position: vec4<f32>,
    @location(0) world_position: vec4<f32>,
    @location(1) world_normal: vec3<f32>,
    // (blade threshold, height fraction), as `uv_b` of the mesh.
    @location(2) uv_b: vec2<f32>,
    // (terrain occlusion, height above the ground).
    @location(3) terms: vec2<f32>,
    @location(4) @interpolate(flat) instance_index: u32,
#ifdef VISIBILITY_RANGE_DITHER
    @location(5) @interpolate(flat) visibility_range_dither: i32,
#endif
}

#ifdef BLADE_TERMS
// Bevy's forward inputs from the blade's, for its PBR input.
fn forward_input(in: BladeVertexOutput) -> VertexOutput {
    var out: VertexOutput;
    out.position = in.position;
    out.world_position = in.world_position;
    out.world_normal = in.world_normal;
#ifdef VERTEX_UVS_A
    out.uv = vec2(0.0);
#endif
#ifdef VERTEX_UVS_B
    out.uv_b = in.uv_b;
#endif
#ifdef VERTEX_OUTPUT_INSTANCE_INDEX
    out.instance_index = in.instance_index;
#endif
#ifdef VISIBILITY_RANGE_DITHER
    out.visibility_range_dither = in.visibility_range_dither;
#endif
    return out;
}
#endif

struct GrassBladeParams {
    // xyz: the eye the transitions are measured from (the field's camera, so the shadow pass
    // keeps the same blades).
    eye: vec4<f32>,
    // (min_geom, max_geom, min_btf, max_btf)
    distances: vec4<f32>,
    // (ω_max, ω₀, max_silhouettes, silhouette ε)
    window: vec4<f32>,
    // The density map's rectangle (min.x, min.z, size.x, size.z).
    density_rect: vec4<f32>,
    // rgb: root colour; w: ambient occlusion at the root.
    root_color: vec4<f32>,
    // rgb: tip colour.
    tip_color: vec4<f32>,
    // The ground under the field and the wind over it.
    ground_wind: grass::GroundWind,
    // The blade shadow mask's (slab height, cylinder radius, 0, 0); radius 0: no mask.
    mask_shape: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<uniform> blade: GrassBladeParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var density_map: texture_2d<f32>;
// The ground's samples (`grass::ground_map::ground_image`) and the wind map.
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var ground_heights: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var wind_map: texture_2d<f32>;
// The blade shadow mask (`R32Float` visibility; `grass_blade_light.wgsl`).
@group(#{MATERIAL_BIND_GROUP}) @binding(105) var shadow_mask: texture_2d<f32>;
// The terrain's ambient occlusion over the field (`R32Float`, §4.2.6).
@group(#{MATERIAL_BIND_GROUP}) @binding(106) var terrain_occlusion_map: texture_2d<f32>;

// The density map at a blade point.
fn density_here(world: vec3<f32>) -> f32 {
    return grass::density_at(density_map, blade.density_rect, world.xz);
}

// Algorithm 1 / eq. 4.6 at this fragment: is the blade point drawn here?
fn blade_kept(world: vec3<f32>, threshold: f32, frag: vec2<f32>) -> bool {
    return blade_kept_at_density(
        world, threshold, frag, grass::density_at(density_map, blade.density_rect, world.xz));
}

// `blade_kept` where the density at the point, `ld`, is known (`density_here`).
fn blade_kept_at_density(world: vec3<f32>, threshold: f32, frag: vec2<f32>, ld: f32) -> bool {
    let d = distance(world, blade.eye.xyz);
    let opacity = grass::geometry_opacity(blade.distances, blade.window, d, ld, threshold);
    return opacity >= grass::DISCARD && opacity > grass::dither(frag);
}

