// Grass as volume slices (Boulanger 2008, thesis §4.2.3–4.2.5, §4.2.7): quads standing where the
// base patch's vertical slices stand in every cell of a block, and a horizontal quad on the
// ground — or one horizontal quad over a whole macro-cell. Each fragment finds its cell, that
// cell's mirrored version (eq. 4.9) and so its point in the base patch; reads the slice image
// there (the unlit, threshold and five lit layers of the side it is seen from); keeps the blades
// the density map and the slice's weight keep (algorithm 1), dithered; and lights them by the
// five baked directions blended by appendix A's spherical barycentric weights, with Bevy's sun,
// its shadow map and the ambient light as Bevy's PBR gives it to the blades. Each quad of each
// cell dithers with its own shift, so crossed layers combine as independent coverage.
// `grass::slice_shading` is the CPU reference.

#import bevy_pbr::forward_io::Vertex
#import bevy_pbr::{
    mesh_functions,
    view_transformations::position_world_to_clip,
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    shadows::fetch_directional_shadow,
    lighting::{F_AB, EnvBRDFApprox},
}
#import bevy_foliage::grass_functions as grass

struct GrassSliceParams {
    eye: vec4<f32>,
    // (min_geom, max_geom, min_btf, max_btf)
    distances: vec4<f32>,
    // (ω_max, ω₀, max_silhouettes, silhouette ε)
    window: vec4<f32>,
    density_rect: vec4<f32>,
    // (origin x, origin z, cell side, ground y)
    grid: vec4<f32>,
    // (slice height, slices per axis K, texels a side, transmission γ)
    slices: vec4<f32>,
    // x: the patch's mirror seed (bits as f32-exact integer below 2^24)
    seed: vec4<u32>,
    // The ground under the field and the wind over it.
    ground_wind: grass::GroundWind,
    // The blade shadow mask's (slab height, cylinder radius, 0, 0); radius 0: no mask.
    mask_shape: vec4<f32>,
    // The blades' (perceptual roughness, reflectance at normal incidence, 0, 0) in Bevy's PBR.
    surface: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: GrassSliceParams;
@group(#{MATERIAL_BIND_GROUP}) @binding(1) var slice_images: texture_2d_array<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(2) var slice_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(3) var density_map: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(4) var ground_heights: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(5) var wind_map: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(6) var shadow_mask: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(8) var terrain_occlusion_map: texture_2d<f32>;
#ifdef SOFT_SHADOWS
// Screen-space soft shadows (bevy_soft_shadows' visibility texture: .r the visibility, negative
// where inactive; .g the light, −1 for the directional one).
@group(#{MATERIAL_BIND_GROUP}) @binding(7) var soft_visibility: texture_2d<f32>;
#endif

const LAYERS: u32 = 12u;

struct SlicePoint {
    // The slice image (its first layer's index) and the uv in it.
    base_layer: u32,
    uv: vec2<f32>,
    back: bool,
    // Mirror signs of the cell (−1 mirrors that axis).
    mirror: vec2<f32>,
    // Which quad of which cell: the key of its dither's shift (`slice_shading::dither_key`).
    dither_key: u32,
}

struct SliceVaryings {
    @builtin(position) position: vec4<f32>,
    // The point on the ground and in the wind.
    @location(0) world_position: vec3<f32>,
    // The same point in the flat volume: world x, z before the wind, y on the field's plane.
    @location(1) flat_position: vec3<f32>,
    // xy: the ground's slope (∂h/∂x, ∂h/∂z) under the point; z: the quad's axis.
    @location(2) slope_axis: vec3<f32>,
}

// The slice quads are laid out flat, one segment per cell (`grass::mesh::slice_block_mesh`);
// each vertex goes onto the ground and into the wind as the blades' do (`on_ground`).
@vertex
fn vertex(vertex: Vertex) -> SliceVaryings {
    var out: SliceVaryings;
    let world_from_local = mesh_functions::get_world_from_local(vertex.instance_index);
    let flat = mesh_functions::mesh_position_local_to_world(world_from_local, vec4(vertex.position, 1.0)).xyz;
    let gw = params.ground_wind;
    // `on_ground`, keeping the ground's slope for the fragment stage.
    let ground = grass::ground_at(ground_heights, gw, flat.xz);
    let push = grass::wind_offset(wind_map, gw, flat.xz, vertex.position.y);
    let world = vec3(flat.x + push.x, flat.y + ground.height, flat.z + push.y);
    out.position = position_world_to_clip(world);
    out.world_position = world;
    out.flat_position = flat;
    out.slope_axis = vec3(ground.gradient, vertex.uv_b.x);
    return out;
}

// Where point p of the flat volume on a quad of `axis` (0 across x, 1 across z, 2 horizontal)
// reads the slices, seen along `to_eye` (in the unlifted volume, any length).
fn slice_point(p: vec3<f32>, axis: u32, to_eye: vec3<f32>) -> SlicePoint {
    let size = params.grid.z;
    let k = u32(params.slices.y);
    let cells = (p.xz - params.grid.xy) / size;
    let cell = vec2<i32>(floor(cells));
    let f = cells - floor(cells);
    let m = grass::mirror_of_cell(cell.x, cell.y, params.seed.x);
    let local_xz = vec2(select(f.x, 1.0 - f.x, m.x), select(f.y, 1.0 - f.y, m.y)) * size;
    let y = p.y - params.grid.w;
    let h = params.slices.x;
    let mirror = vec2(select(1.0, -1.0, m.x), select(1.0, -1.0, m.y));
    // The view direction in the base patch's frame.
    let v = to_eye * vec3(mirror.x, 1.0, mirror.y);
    var out: SlicePoint;
    out.mirror = mirror;
    let slab = size / f32(k);
    let row = (h - y) / h;
    if axis == 0u {
        let s = min(u32(local_xz.x / slab), k - 1u);
        out.back = v.x < 0.0;
        out.base_layer = s * LAYERS;
        out.uv = vec2(select((size - local_xz.y) / size, local_xz.y / size, out.back), row);
    } else if axis == 1u {
        let s = k + min(u32(local_xz.y / slab), k - 1u);
        out.back = v.z < 0.0;
        out.base_layer = s * LAYERS;
        out.uv = vec2(select(local_xz.x / size, (size - local_xz.x) / size, out.back), row);
    } else {
        out.back = false;
        out.base_layer = 2u * k * LAYERS;
        out.uv = local_xz / size;
    }
    out.dither_key = grass::hash32(
        bitcast<u32>(cell.x) ^ grass::hash32(bitcast<u32>(cell.y) ^ grass::hash32(out.base_layer)));
    return out;
}

fn layer(uv: vec2<f32>, index: u32, lod: f32) -> vec4<f32> {
    return textureSampleLevel(slice_images, slice_sampler, uv, index, lod);
}

@fragment
fn fragment(in: SliceVaryings) -> @location(0) vec4<f32> {
    let p = in.world_position;
    let eye = params.eye.xyz;
    let axis = u32(in.slope_axis.z + 0.5);
    let slope = in.slope_axis.xy;
    // The eye as the unlifted patch sees it (eq. 4.11).
    let to_eye = normalize(grass::lift_to_patch(slope, eye - p));
    let sp = slice_point(in.flat_position, axis, to_eye);
    // The mip: texels under a pixel, from the world-space footprint (uv jumps at mirrored cell
    // edges, so hardware derivatives of uv would not do).
    let footprint = max(length(dpdx(p)), length(dpdy(p)));
    let texel = params.grid.z / params.slices.z;
    let lod = max(log2(max(footprint, 1e-9) / texel), 0.0);
    // Algorithm 1: this slice's weight, the density here, the blade's threshold.
    let d = distance(p, eye);
    var w = grass::horizontal_weight(params.distances, d);
    if axis < 2u {
        // Eq. 4.14 against the ground's normal: the eye's height in the patch frame.
        w = grass::vertical_weight(params.distances, params.window, d, to_eye.y);
        // Where their weight is zero the horizontal slice carries the window's complement
        // alone: out before any texture is read, since a view along the ground crosses many
        // such quads.
        if w <= 0.0 {
            discard;
        }
    }
    // No blade here (most of a slice): out before the threshold and the density are read.
    let unlit = layer(sp.uv, sp.base_layer, lod);
    if unlit.a < grass::DISCARD {
        discard;
    }
    let threshold = layer(sp.uv, sp.base_layer + 1u, lod).r;
    let ld = grass::density_at(density_map, params.density_rect, in.flat_position.xz);
    let opacity = unlit.a * grass::slice_opacity(params.window, w, ld, threshold);
    if opacity < grass::DISCARD || opacity <= grass::shifted_dither(in.position.xy, sp.dither_key) {
        discard;
    }
    let gamma = params.slices.w;
    // Ambient: the blades' kd·ao lit as Bevy's PBR lights the blades (`lighting::slice_ambient`):
    // the reflected share (1 − γ) through the environment BRDF, with the blades' specular, under
    // the terrain's ambient occlusion there (§4.2.6); the transmitted share γ unoccluded. The
    // blades' normals face along a vertical slice's axis and lie level under the horizontal one
    // (`slice_shading::blade_n_dot_v`).
    let terrain_ao = grass::density_at(terrain_occlusion_map, params.density_rect, in.flat_position.xz);
    var n_dot_v = length(to_eye.xz);
    if axis == 0u {
        n_dot_v = abs(to_eye.x);
    } else if axis == 1u {
        n_dot_v = abs(to_eye.z);
    }
    n_dot_v = max(n_dot_v, 1e-4);
    let lit_ambient = EnvBRDFApprox(unlit.rgb * (1.0 - gamma), F_AB(1.0, n_dot_v));
    let through_ambient = EnvBRDFApprox(unlit.rgb * gamma, F_AB(1.0, 1.0));
    let f0 = vec3(params.surface.y);
    let specular_occlusion = saturate(dot(f0, vec3(50.0 * 0.33)));
    let specular_ambient = EnvBRDFApprox(f0, F_AB(params.surface.x, n_dot_v)) * specular_occlusion;
    var color = view_bindings::lights.ambient_color.rgb
        * ((lit_ambient + specular_ambient) * terrain_ao + through_ambient);
    // The sun through the five baked directions.
    if view_bindings::lights.n_directional_lights > 0u {
        let light = &view_bindings::lights.directional_lights[0];
        let l = normalize(grass::lift_to_patch(slope, (*light).direction_to_light))
            * vec3(sp.mirror.x, 1.0, sp.mirror.y);
        let weights = grass::btf_weights(l);
        var direct = vec3(0.0);
        let first = sp.base_layer + 2u + select(0u, 5u, sp.back);
        for (var i = 0u; i < 5u; i += 1u) {
            if weights[i] > 0.0 {
                direct += weights[i] * layer(sp.uv, first + i, lod).rgb;
            }
        }
        var shadow = 1.0;
        if ((*light).flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            let view_z = dot(vec4<f32>(
                view_bindings::view.view_from_world[0].z,
                view_bindings::view.view_from_world[1].z,
                view_bindings::view.view_from_world[2].z,
                view_bindings::view.view_from_world[3].z
            ), vec4(p, 1.0));
            shadow = fetch_directional_shadow(0u, vec4(p, 1.0), vec3(0.0, 1.0, 0.0), view_z, in.position.xy);
#ifdef SOFT_SHADOWS
            let pixel = vec2<u32>(in.position.xy);
            if all(pixel < textureDimensions(soft_visibility)) {
                let soft = textureLoad(soft_visibility, pixel, 0).rg;
                if soft.x >= 0.0 && soft.y < -0.5 && soft.y > -1.5 {
                    shadow = soft.x;
                }
            }
#endif
        }
        // The neighbours' shadows on the blades here (§4.2.6, eq. 4.7), as on the blades drawn
        // as geometry: at the texel's height in the slab.
        let y = in.flat_position.y - params.grid.w;
        shadow *= grass::shadow_mask_light(
            shadow_mask, params.mask_shape, y, (*light).direction_to_light, ld);
        // Lambert's 1/π, as Bevy's diffuse lobe.
        color += (*light).color.rgb * shadow * direct * (1.0 / 3.14159265);
    }
    return vec4(color * view_bindings::view.exposure, 1.0);
}
