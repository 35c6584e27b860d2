// Screen Space Soft Shadows, steps 2–4 (Gumbau 2011, §6.2.2–6.3.2), as fullscreen passes that
// bind Bevy's mesh view group (view, lights, shadow maps, prepass depth and normals):
//
// - `distance`: per pixel the hard shadow (Bevy's own lookup), the blocker found in the dilated
//   shadow map, the penumbra width by eq. 6.1 (a spot or point light, or its limit for a light at
//   infinity) and eq. 6.2 (in pixels), and the kernel's σ along x and y from the surface
//   normal; written as (hard, σx, σy, eye depth). Its blocker is the dilated map's, the farthest
//   in the window, so its σ is an upper bound: the tile classification (`tiles.wgsl`) runs on it.
//   It also writes the hard visibility into both blur targets: a tile the blur cannot change
//   keeps it (`ssss::tiles`).
// - `refine`: the same on the active tiles only, with the refined blocker search (49 shadow-map
//   reads a pixel, the pass's dearest part): the σ the blur uses.
// - `blur_horizontal`, `blur_vertical`: the separable Gaussian with depth rejection and lazy
//   shadowing. `refine` and the blurs draw one 8×8 quad per active tile (`tile_vertex`, an
//   indirect draw whose instance count the classification wrote).
//
// CPU references: `ssss::penumbra`, `ssss::kernel`, `ssss::blur`, `ssss::tiles`.
#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_pbr::{
    mesh_view_bindings as view_bindings,
    mesh_view_types::{DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT, POINT_LIGHT_FLAGS_SPOT_LIGHT_Y_NEGATIVE},
    prepass_utils::{prepass_depth, prepass_normal},
    shadows::{
        fetch_directional_shadow, fetch_point_shadow, fetch_spot_shadow, get_cascade_index,
        world_to_directional_light_local,
    },
    view_transformations::{frag_coord_to_ndc, position_ndc_to_world, position_world_to_view, depth_ndc_to_view_z},
}
#import bevy_render::maths::orthonormalize
#import bevy_soft_shadows::ssss_types::{
    SsssUniform, NO_LIGHT, KERNEL_REACH_SIGMAS, MAX_COARSE_RADIUS, LIGHT_KIND_DIRECTIONAL,
    LIGHT_KIND_SPOT, LIGHT_KIND_POINT,
    TILE, BLOCKER_GRID, tap_offset, tap_cell, tap_layout, SUM_SCALE,
}

@group(2) @binding(0) var dilated: texture_2d_array<f32>;
@group(2) @binding(1) var<uniform> ssss: SsssUniform;
@group(2) @binding(2) var distances: texture_2d<f32>;
@group(2) @binding(3) var blur_in: texture_2d<f32>;
// The active tiles, `x | y << 16` (`tiles.wgsl`).
@group(2) @binding(4) var<storage, read> active_tiles: array<u32>;
// Prefix sums of `blur_in.r` along the pass (`box_sums.wgsl`): rows for the horizontal pass,
// columns for the vertical one.
@group(2) @binding(5) var line_sums: texture_2d<u32>;
// The point lights' cube shadow texture viewed as a 2D array (face f of the light of clustered
// index i is layer 6i + f): the mesh view group binds it as a cube array, which `textureLoad`
// cannot read.
@group(2) @binding(6) var point_faces: texture_depth_2d_array;

// One quad per active tile: instance `i` covers tile `active_tiles[i]`, clipped to the screen.
@vertex
fn tile_vertex(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> FullscreenVertexOutput {
    let packed = active_tiles[instance];
    let tile = vec2(packed & 0xffffu, packed >> 16u);
    // Two triangles: (0,0) (1,0) (0,1) and (0,1) (1,0) (1,1).
    var corners = array(vec2(0u, 0u), vec2(1u, 0u), vec2(0u, 1u), vec2(0u, 1u), vec2(1u, 0u), vec2(1u, 1u));
    let size = textureDimensions(distances);
    let px = vec2<f32>(min((tile + corners[vertex % 6u]) * TILE, size));
    let uv = px / vec2<f32>(size);
    var out: FullscreenVertexOutput;
    out.position = vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

// What a pixel is when the blur does not change it (the blur passes' results for σ = 0, or with
// SSSS off: −1 for the receivers).
struct DistanceOutput {
    @location(0) distance: vec4<f32>,
    @location(1) horizontal: vec4<f32>,
    @location(2) visibility: vec4<f32>,
}

// Which light the receivers re-weight (`receiver_functions::apply_soft_shadow`): a spot light's
// clustered index i, a point light's as −2 − i, −1 for the directional light.
fn receiver_light() -> f32 {
    if ssss.light_kind == LIGHT_KIND_SPOT {
        return f32(ssss.light_index);
    }
    if ssss.light_kind == LIGHT_KIND_POINT {
        return -2.0 - f32(ssss.light_index);
    }
    return -1.0;
}

// The SSSS light: a spot or point light's clustered index, or the first shadow-casting
// directional light.
fn ssss_light() -> u32 {
    if ssss.light_kind != LIGHT_KIND_DIRECTIONAL {
        return ssss.light_index;
    }
    for (var i = 0u; i < view_bindings::lights.n_directional_lights; i += 1u) {
        if (view_bindings::lights.directional_lights[i].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            return i;
        }
    }
    return NO_LIGHT;
}

fn view_z_of(world: vec3<f32>) -> f32 {
    return position_world_to_view(world).z;
}

// Bevy's own hard shadow lookup for the SSSS light (2×2 hardware PCF, the thesis' hard shadow).
fn hard_shadow(light: u32, world: vec3<f32>, normal: vec3<f32>, frag_xy: vec2<f32>) -> f32 {
    if ssss.light_kind == LIGHT_KIND_SPOT {
        let near = view_bindings::clustered_lights.data[light].shadow_map_near_z;
        return fetch_spot_shadow(light, vec4(world, 1.0), normal, near, frag_xy);
    }
    if ssss.light_kind == LIGHT_KIND_POINT {
        return fetch_point_shadow(light, vec4(world, 1.0), normal, frag_xy);
    }
    return fetch_directional_shadow(light, vec4(world, 1.0), normal, view_z_of(world), frag_xy);
}

// Pixels per metre at unit eye distance (perspective) or everywhere (orthographic).
fn pixels_per_unit() -> f32 {
    return view_bindings::view.clip_from_view[1][1] * 0.5 * view_bindings::view.viewport.w;
}

fn is_orthographic() -> bool {
    return view_bindings::view.clip_from_view[3][3] == 1.0;
}

// A surface is not its own blocker: across the dilation footprint (`reach` metres) a receiver's
// own plane rises towards the light by up to reach · tan(angle to the light); a gap no larger
// than that is the surface itself (`penumbra::own_surface_gap`).
fn is_own_surface(gap: f32, reach: f32, cos_nl: f32) -> bool {
    return cos_nl > 0.0 && gap <= reach * sqrt(max(1.0 - cos_nl * cos_nl, 0.0)) / max(cos_nl, 0.05);
}

// Eq. 6.1 for a light at infinity: the penumbra's world width behind the blocker found in the
// dilated map at the receiver's texel (reverse Z: larger is nearer the light).
fn directional_penumbra(i: u32, world: vec3<f32>, normal: vec3<f32>, view_z: f32, refine: bool) -> f32 {
    let light = &view_bindings::lights.directional_lights[i];
    let cascade = get_cascade_index(i, view_z);
    if cascade >= (*light).num_cascades {
        return 0.0;
    }
    let local = world_to_directional_light_local(i, cascade, vec4(world, 1.0));
    if local.w == 0.0 {
        return 0.0;
    }
    let size = vec2<f32>(textureDimensions(dilated));
    let texel = vec2<i32>(clamp(local.xy * size, vec2(0.0), size - 1.0));
    let layer = i32((*light).depth_texture_base_index + cascade);
    let blocker = textureLoad(dilated, texel, layer, 0).r;
    // Light-space depth per metre along the light (orthographic cascade: constant).
    let m = (*light).cascades[cascade].clip_from_world;
    let depth_per_metre = length(vec3(m[0].z, m[1].z, m[2].z));
    let gap = (blocker - local.z) / max(depth_per_metre, 1e-8);
    let texel_size = (*light).cascades[cascade].texel_size;
    let half_width = ssss.max_occluder_distance * tan(0.5 * ssss.light_size);
    // The coarse radius of this cascade (`min_filter::coarse_radius`), one block more.
    let block = f32(ssss.dilation_block);
    let r = ceil(max(half_width / max(texel_size, 1e-6), 0.0));
    let reach = (min(ceil(r / block), f32(MAX_COARSE_RADIUS)) + 1.0) * block * texel_size;
    let cos_nl = dot(normal, (*light).direction_to_light.xyz);
    if is_own_surface(gap, reach, cos_nl) {
        return 0.0;
    }
    var blocker_gap = gap;
    if refine {
        blocker_gap = refined_gap(local.xyz, gap, texel_size, depth_per_metre, cos_nl, layer);
    }
    return max(blocker_gap, 0.0) * 2.0 * tan(0.5 * ssss.light_size);
}

// The refined blocker search's grid (`distance::FineMap::blocker_grid`): the receiver's texel of
// the fine map, and the offset of sample (i, j) of a grid spanning `reach_texels` each way.
fn blocker_grid_centre(uv: vec2<f32>, size: vec2<i32>) -> vec2<i32> {
    return clamp(vec2<i32>(floor(uv * vec2<f32>(size))), vec2(0), size - 1);
}

fn blocker_grid_offset(i: i32, j: i32, reach_texels: f32) -> vec2<i32> {
    return vec2<i32>(round(vec2<f32>(vec2(i, j)) * reach_texels / f32(BLOCKER_GRID)));
}

// The blocker estimate for eq. 6.1 (`distance::refined_gap`). The dilated map holds the blocker
// nearest the light within the window, which for a long thin blocker (a trunk, a pole) is its far
// end, not the part in front of the light's centre: the penumbra comes out too wide and the thin
// shadow too faint. Among the fine shadow-map texels on a 7×7 grid within the reach of that
// farthest blocker, the blockers that hide part of the light's disk from the receiver (a blocker
// at gap g covers texels within g·tan(θ/2) of the receiver's light ray) are averaged instead,
// weighted by the share of the disk each hides (1/g²); with none found the dilated map's gap
// stands.
fn refined_gap(local: vec3<f32>, gap_max: f32, texel_size: f32, depth_per_metre: f32, cos_nl: f32, layer: i32) -> f32 {
    let size = vec2<i32>(textureDimensions(view_bindings::directional_shadow_textures).xy);
    let centre = blocker_grid_centre(local.xy, size);
    let t = tan(0.5 * ssss.light_size);
    let reach_texels = gap_max * t / max(texel_size, 1e-6);
    let slope = sqrt(max(1.0 - cos_nl * cos_nl, 0.0)) / max(cos_nl, 0.05);
    var sum = 0.0;
    var count = 0.0;
    for (var j = -BLOCKER_GRID; j <= BLOCKER_GRID; j += 1) {
        for (var i = -BLOCKER_GRID; i <= BLOCKER_GRID; i += 1) {
            let offset = blocker_grid_offset(i, j, reach_texels);
            let p = centre + offset;
            if any(p < vec2(0)) || any(p >= size) {
                continue;
            }
            let depth = textureLoad(view_bindings::directional_shadow_textures, p, layer, 0);
            let gap = (depth - local.z) / max(depth_per_metre, 1e-8);
            let r = length(vec2<f32>(offset)) * texel_size;
            // A blocker hiding part of the light's disk, and not the receiver's own plane (which
            // rises towards the light by up to `slope` per metre, plus a texel of slack: the
            // receiver's own texel holds its surface at the texel's centre), nor closer to it
            // than a texel (depth precision).
            if gap > texel_size && r <= gap * t && (cos_nl <= 0.0 || gap > (r + texel_size) * slope) {
                let share = 1.0 / (gap * gap);
                sum += gap * share;
                count += share;
            }
        }
    }
    // Never past the dilated map's blocker: the distance pass's bound stays an upper bound.
    if count > 0.0 {
        return min(sum / count, gap_max);
    }
    return gap_max;
}

// Where a local light's shadow map sees a point: its map coordinates (v down), its distance
// from the light along the map's axis (0 where the map does not see it), the layer of the shadow
// texture array, and the tangent of the map's half angle.
struct LocalTexel {
    uv: vec2<f32>,
    distance: f32,
    layer: i32,
    tan_half_angle: f32,
}

// Bevy's spot shadow projection (`distance::SpotProjection`): the spot's axis from the clustered
// light, `orthonormalize` for the map's orientation about it.
fn spot_texel(id: u32, world: vec3<f32>) -> LocalTexel {
    let light = &view_bindings::clustered_lights.data[id];
    let to_light = (*light).position_radius.xyz - world;
    var spot_dir = vec3((*light).light_custom_data.x, 0.0, (*light).light_custom_data.y);
    spot_dir.y = sqrt(max(0.0, 1.0 - spot_dir.x * spot_dir.x - spot_dir.z * spot_dir.z));
    if ((*light).flags & POINT_LIGHT_FLAGS_SPOT_LIGHT_Y_NEGATIVE) != 0u {
        spot_dir.y = -spot_dir.y;
    }
    let projected = (-to_light) * orthonormalize(-spot_dir);
    var out: LocalTexel;
    out.distance = max(-projected.z, 0.0);
    out.tan_half_angle = (*light).spot_light_tan_angle;
    out.uv = projected.xy / (out.tan_half_angle * max(out.distance, 1e-8)) * vec2(0.5, -0.5) + vec2(0.5);
    out.layer = i32(id) + view_bindings::lights.spot_light_shadowmap_offset;
    return out;
}

// Bevy's point shadow projection (`distance::PointProjection`): six 90° faces, sampled along the
// light-to-point direction with z flipped (`fetch_point_shadow`: Bevy's cube maps are
// left-handed), the face and its coordinates by the cube-map face selection of Vulkan and
// Direct3D; the distance is the major axis', as Bevy's depth `near / major axis` stores it.
fn point_texel(id: u32, world: vec3<f32>) -> LocalTexel {
    let light = &view_bindings::clustered_lights.data[id];
    let d = world - (*light).position_radius.xyz;
    let r = vec3(d.x, d.y, -d.z);
    let a = abs(r);
    var face = 0;
    var sc_tc = vec2(0.0);
    var major = 0.0;
    if a.x >= a.y && a.x >= a.z {
        major = a.x;
        face = select(1, 0, r.x >= 0.0);
        sc_tc = select(vec2(r.z, -r.y), vec2(-r.z, -r.y), r.x >= 0.0);
    } else if a.y >= a.z {
        major = a.y;
        face = select(3, 2, r.y >= 0.0);
        sc_tc = select(vec2(r.x, -r.z), vec2(r.x, r.z), r.y >= 0.0);
    } else {
        major = a.z;
        face = select(5, 4, r.z >= 0.0);
        sc_tc = select(vec2(-r.x, -r.y), vec2(r.x, -r.y), r.z >= 0.0);
    }
    var out: LocalTexel;
    out.distance = major;
    out.tan_half_angle = 1.0;
    out.uv = sc_tc / max(major, 1e-8) * 0.5 + vec2(0.5);
    out.layer = i32(id) * 6 + face;
    return out;
}

// The fine shadow map of the SSSS light: its size, and its stored depth at a texel.
fn fine_size() -> vec2<i32> {
    if ssss.light_kind == LIGHT_KIND_POINT {
        return vec2<i32>(textureDimensions(point_faces).xy);
    }
    return vec2<i32>(textureDimensions(view_bindings::directional_shadow_textures).xy);
}

fn fine_depth(p: vec2<i32>, layer: i32) -> f32 {
    if ssss.light_kind == LIGHT_KIND_POINT {
        return textureLoad(point_faces, p, layer, 0);
    }
    return textureLoad(view_bindings::directional_shadow_textures, p, layer, 0);
}

// Eq. 6.1 for a local (spot or point) light of diameter `light_size`:
// w = light_size · (d_r − d_b) / d_b, with the distances along the map's axis — on one ray from
// the light their ratio is that of the distances themselves. Bevy's local shadow maps are
// infinite reverse-Z perspective projections, so a stored depth is near / d (as in
// `fetch_spot_shadow` and `fetch_point_shadow`). A point light's faces are dilated each on its own:
// a receiver near a face's edge does not see blockers across it (`distance::point_penumbra_width`).
fn local_penumbra(id: u32, world: vec3<f32>, normal: vec3<f32>, refine: bool) -> f32 {
    let light = &view_bindings::clustered_lights.data[id];
    let to_light = (*light).position_radius.xyz - world;
    var t: LocalTexel;
    if ssss.light_kind == LIGHT_KIND_POINT {
        t = point_texel(id, world);
    } else {
        t = spot_texel(id, world);
    }
    let d_r = t.distance;
    let near = (*light).shadow_map_near_z;
    if d_r <= near {
        return 0.0;
    }
    let uv = t.uv;
    if any(uv < vec2(0.0)) || any(uv > vec2(1.0)) {
        return 0.0;
    }
    let size = vec2<f32>(textureDimensions(dilated));
    let texel = vec2<i32>(clamp(uv * size, vec2(0.0), size - 1.0));
    let blocker = textureLoad(dilated, texel, t.layer, 0).r;
    if blocker <= near / d_r {
        return 0.0;
    }
    let d_b = near / blocker;
    let gap = d_r - d_b;
    // A shadow-map texel spans 2·d·tan_half_angle / size metres at distance d.
    let fine = f32(fine_size().x);
    let texel_size = 2.0 * d_r * t.tan_half_angle / fine;
    let reach = (f32(ssss.local_radius) + 1.0) * f32(ssss.dilation_block) * texel_size;
    let cos_nl = dot(normal, normalize(to_light));
    if is_own_surface(gap, reach, cos_nl) {
        return 0.0;
    }
    var d_blocker = d_b;
    if refine {
        d_blocker = refined_local_blocker(uv, d_r, d_b, near, t.tan_half_angle, cos_nl, t.layer);
    }
    return (d_r - d_blocker) * ssss.light_size / d_blocker;
}

// `refined_gap` for a local light (`distance::refined_local_blocker`): the distance from the light
// of the blockers hiding part of the lamp's disk from the receiver, averaged weighted by the share
// of the disk each hides (1/g²). Seen from the
// receiver `d_r` away, the disk of diameter `light_size` spans `light_size/2 · g / d_r` around
// the receiver's ray at a blocker `g` in front of the receiver; a texel spans
// `2 d tan_half_angle / size` metres at distance `d` from the light.
fn refined_local_blocker(uv: vec2<f32>, d_r: f32, d_nearest: f32, near: f32, tan_half_angle: f32, cos_nl: f32, layer: i32) -> f32 {
    let size = fine_size();
    let centre = blocker_grid_centre(uv, size);
    let half = 0.5 * ssss.light_size;
    let texel_per_distance = 2.0 * tan_half_angle / f32(size.x);
    let reach_texels = half * (d_r - d_nearest) / d_r / max(d_nearest * texel_per_distance, 1e-8);
    let slope = sqrt(max(1.0 - cos_nl * cos_nl, 0.0)) / max(cos_nl, 0.05);
    let receiver_texel = d_r * texel_per_distance;
    var sum = 0.0;
    var count = 0.0;
    for (var j = -BLOCKER_GRID; j <= BLOCKER_GRID; j += 1) {
        for (var i = -BLOCKER_GRID; i <= BLOCKER_GRID; i += 1) {
            let offset = blocker_grid_offset(i, j, reach_texels);
            let p = centre + offset;
            if any(p < vec2(0)) || any(p >= size) {
                continue;
            }
            let depth = fine_depth(p, layer);
            if depth <= near / d_r {
                continue;
            }
            let d = near / depth;
            let gap = d_r - d;
            let texels = length(vec2<f32>(offset));
            let lateral = texels * d * texel_per_distance;
            let own = (texels * receiver_texel + receiver_texel) * slope;
            if gap > receiver_texel && lateral <= half * gap / d_r && (cos_nl <= 0.0 || gap > own) {
                let share = 1.0 / (gap * gap);
                sum += d * share;
                count += share;
            }
        }
    }
    if count > 0.0 {
        return max(sum / count, d_nearest);
    }
    return d_nearest;
}

@fragment
fn distance(in: FullscreenVertexOutput) -> DistanceOutput {
    let d = distance_map(in, false);
    // The blur passes' results where they leave the pixel as it is.
    let hard = select(d.x, -1.0, ssss.enabled == 0u);
    var out: DistanceOutput;
    out.distance = d;
    out.horizontal = vec4(hard, d.w, 0.0, 1.0);
    out.visibility = vec4(hard, receiver_light(), 0.0, 1.0);
    return out;
}

// The refined distance map on the active tiles (`tile_vertex` quads): the same as `distance`
// with the refined blocker search, whose σ the blur passes use. Its σ never exceeds the
// distance pass's bound, so the tiles classified on the bound still hold every pixel the blur
// changes (`ssss::tiles`).
@fragment
fn refine(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    return distance_map(in, true);
}

fn distance_map(in: FullscreenVertexOutput, refine: bool) -> vec4<f32> {
    let frag = vec4(in.position.xy, 0.0, 1.0);
    let depth = prepass_depth(frag, 0u);
    let i = ssss_light();
    if depth <= 0.0 || i == NO_LIGHT || ssss.enabled == 0u {
        return vec4(1.0, 0.0, 0.0, 0.0);
    }
    let ndc = vec3(frag_coord_to_ndc(frag).xy, depth);
    let world = position_ndc_to_world(ndc);
    let normal = normalize(prepass_normal(frag, 0u));
    let view_z = view_z_of(world);
    let eye_depth = -view_z;
    let hard = hard_shadow(i, world, normal, in.position.xy);
    var world_width = 0.0;
    if ssss.light_kind != LIGHT_KIND_DIRECTIONAL {
        world_width = local_penumbra(i, world, normal, refine);
    } else {
        world_width = directional_penumbra(i, world, normal, view_z, refine);
    }
    // Eq. 6.2: in pixels, divided by the eye distance for a perspective view.
    var px = world_width * pixels_per_unit();
    if !is_orthographic() {
        px = px / max(eye_depth, 1e-4);
    }
    var sigma = 0.25 * px;
    // The mask of §6.2.2: a kernel reaching less than a pixel would leave the hard shadow as it
    // is (its ±1 px taps weigh < 4 %), so the blur skips the pixel. This also drops the tiny
    // "blocker" gaps a surface finds in its own neighbourhood of the dilated map.
    if KERNEL_REACH_SIGMAS * sigma < 1.0 {
        sigma = 0.0;
    }
    if sigma > 0.0 {
        let reach = clamp(KERNEL_REACH_SIGMAS * sigma, ssss.min_kernel_px, ssss.max_kernel_px);
        sigma = reach / KERNEL_REACH_SIGMAS;
    }
    // The kernel's axes: the screen extents of a disk on the surface (`penumbra::kernel_axes`).
    let n = normalize((view_bindings::view.view_from_world * vec4(normal, 0.0)).xyz);
    let axes = sqrt(max(vec2(1.0) - n.xy * n.xy, vec2(0.0)));
    return vec4(hard, sigma * axes, eye_depth);
}

// Lazy shadowing (§6.3.2): the hard shadow at the point where the sample pixel's view ray meets
// the centre pixel's tangent plane; negative when there is no such point.
fn lazy_shadow(sample_px: vec2<i32>, centre_world: vec3<f32>, normal: vec3<f32>, light: u32) -> f32 {
    let frag = vec4(vec2<f32>(sample_px) + 0.5, 0.0, 1.0);
    let ndc_xy = frag_coord_to_ndc(frag).xy;
    let near = position_ndc_to_world(vec3(ndc_xy, 1.0));
    let mid = position_ndc_to_world(vec3(ndc_xy, 0.5));
    let dir = normalize(mid - near);
    let denom = dot(dir, normal);
    if abs(denom) < 1e-4 {
        return -1.0;
    }
    let t = dot(centre_world - near, normal) / denom;
    if t <= 0.0 {
        return -1.0;
    }
    let p = near + t * dir;
    return hard_shadow(light, p, normal, frag.xy);
}

// `blur_in` holds the value to blur in .r and the eye depth in channel `depth_channel` (the
// distance map's .w for the horizontal pass, the horizontal result's .g for the vertical one),
// so each tap is one texture load.
fn blur(in: FullscreenVertexOutput, direction: vec2<i32>, sigma_channel: u32, depth_channel: u32) -> f32 {
    let centre = vec2<i32>(in.position.xy);
    let d = textureLoad(distances, centre, 0);
    let own = textureLoad(blur_in, centre, 0).r;
    if ssss.enabled == 0u {
        return -1.0;
    }
    let sigma = d[sigma_channel];
    let z = d.w;
    if z <= 0.0 || sigma <= 0.0 {
        return own;
    }
    let size = vec2<i32>(textureDimensions(distances));
    // Tap layout (`kernel::tap_offsets`): one per pixel while the kernel fits, spread beyond.
    let taps = tap_layout(sigma, ssss.taps_per_side);
    let n = i32(taps.x);
    let step = taps.y;
    // Along the pass: the centre's position and the line's length.
    let along = dot(centre, direction);
    let len = dot(size, direction);
    // The centre's surface, for lazy shadowing.
    let light = ssss_light();
    var centre_world = vec3(0.0);
    var normal = vec3(0.0, 1.0, 0.0);
    if ssss.lazy_shadowing != 0u {
        let frag = vec4(in.position.xy, 0.0, 1.0);
        let depth = prepass_depth(frag, 0u);
        centre_world = position_ndc_to_world(vec3(frag_coord_to_ndc(frag).xy, depth));
        normal = normalize(prepass_normal(frag, 0u));
    }
    var sum = 0.0;
    var weights = 0.0;
    for (var i = -n; i <= n; i += 1) {
        let offset = tap_offset(i, step);
        let p = centre + direction * offset;
        if any(p < vec2(0)) || any(p >= size) {
            continue;
        }
        let tap = textureLoad(blur_in, p, 0);
        let sample_depth = tap[depth_channel];
        // A spread tap stands for its cell (`kernel::tap_cell`), clamped to the line: it reads
        // the cell's mean and weighs as many pixels. Depth is tested at the tap itself.
        let cell = tap_cell(i, step);
        let first = max(along + cell.x, 0);
        let last = min(along + cell.y, len - 1);
        let count = last - first + 1;
        var value = 0.0;
        if sample_depth > 0.0 && abs(sample_depth - z) <= ssss.depth_rejection * z {
            value = tap.r;
            if step > 1.0 {
                // Texel k of a line's sums covers its pixels 0..k.
                let before = centre * (vec2(1) - direction) + direction * first;
                let through = centre * (vec2(1) - direction) + direction * (last + 1);
                let sum = textureLoad(line_sums, through, 0).r - textureLoad(line_sums, before, 0).r;
                value = f32(sum) / (SUM_SCALE * f32(count));
            }
        } else if ssss.lazy_shadowing != 0u && light != NO_LIGHT {
            value = lazy_shadow(p, centre_world, normal, light);
            if value < 0.0 {
                continue;
            }
        } else {
            continue;
        }
        let w = exp(-f32(offset * offset) / (2.0 * sigma * sigma)) * f32(count);
        sum += w * value;
        weights += w;
    }
    if weights > 0.0 {
        return sum / weights;
    }
    return own;
}

@fragment
fn blur_horizontal(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    // The eye depth rides along for the vertical pass.
    let depth = textureLoad(distances, vec2<i32>(in.position.xy), 0).w;
    return vec4(blur(in, vec2(1, 0), 1u, 3u), depth, 0.0, 1.0);
}

// The receivers read (visibility, light): `receiver_light`.
@fragment
fn blur_vertical(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    return vec4(blur(in, vec2(0, 1), 2u, 1u), receiver_light(), 0.0, 1.0);
}
