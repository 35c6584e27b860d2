// Drawing occluders into the trees' world-space opacity shadow map (Boulanger 2008, §5.5.2.1),
// for the compute passes of the crates that own the casters (bevy_foliage's pruned leaves).
//
// A caster pipeline binds its own data at group 0 and `TreeOpacityTargets::caster_bind_group`
// (layout `caster_layout()`) at group 1, and calls `draw_occluder_triangle` once per world-space
// triangle. Each texel keeps two words, updated atomically so that any number of invocations may
// draw at once: the bits of the highest occluder's height above the plane (non-negative floats
// order as their bits do, so `atomicMax` is the MAX blend) and the number of leaf fragments on
// the texel's ray (the resolve turns n into the transmittance 0.9^n). The CPU reference is
// `OpacityShadowMap::draw` in `opacity_map.rs`, texel for texel: the same projection (eq. 5.27),
// texel-centre coverage and fill rule.
#define_import_path bevy_soft_shadows::opacity_caster

struct OpacityPlane {
    // Unit direction from the scene to the sun.
    to_light: vec3<f32>,
    // The plane's height.
    plane_y: f32,
    // World (x, z) of the map's corner at uv (0, 0), and the map's world extent.
    origin: vec2<f32>,
    extent: vec2<f32>,
    resolution: vec2<u32>,
    // 0: no map this frame (draw nothing).
    drawing: u32,
    pad: u32,
}

@group(1) @binding(0) var<storage, read_write> opacity_texels: array<atomic<u32>>;
@group(1) @binding(1) var<uniform> opacity_plane: OpacityPlane;

// The fragments an opaque occluder counts for: 0.9^256 ≈ 2e-12, no light.
const OPAQUE_FRAGMENTS: u32 = 256u;

// The widest span, in texels, one triangle is rasterised over (one invocation draws it; a leaf
// covers a few texels): larger triangles are clipped to it.
const MAX_SPAN: f32 = 256.0;

// Eq. 5.27: where the sun's ray through `p` meets the plane, in texels, and `p`'s height above it.
fn opacity_project(p: vec3<f32>) -> vec3<f32> {
    let along = (p.y - opacity_plane.plane_y) / opacity_plane.to_light.y;
    let world = vec2(p.x - opacity_plane.to_light.x * along, p.z - opacity_plane.to_light.z * along);
    let size = vec2<f32>(opacity_plane.resolution);
    return vec3((world - opacity_plane.origin) / opacity_plane.extent * size, p.y - opacity_plane.plane_y);
}

fn perp_dot(a: vec2<f32>, b: vec2<f32>) -> f32 {
    return a.x * b.y - a.y * b.x;
}

// A texel centre exactly on an edge belongs to the triangle for which the edge runs "up", or
// along x backwards: of the two opposite directions a shared edge has, exactly one qualifies.
fn owns(start: vec2<f32>, end: vec2<f32>) -> bool {
    let d = end - start;
    return d.y > 0.0 || (d.y == 0.0 && d.x < 0.0);
}

fn inside(e: f32, start: vec2<f32>, end: vec2<f32>) -> bool {
    return e > 0.0 || (e == 0.0 && owns(start, end));
}

// Draws the triangle p0 p1 p2 (world space, either facing) as `fragments` occluder fragments per
// covered texel: 1 for a leaf, OPAQUE_FRAGMENTS for an opaque occluder.
fn draw_occluder_triangle(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, fragments: u32) {
    if opacity_plane.drawing == 0u {
        return;
    }
    let a = opacity_project(p0);
    var b = opacity_project(p1);
    var c = opacity_project(p2);
    var area = perp_dot(b.xy - a.xy, c.xy - a.xy);
    // Degenerate, NaN or infinite: nothing to draw.
    if !(abs(area) >= 1e-12 && abs(area) <= 3.0e38) {
        return;
    }
    // Counter-clockwise, so that an edge two triangles share runs opposite ways in them.
    if area < 0.0 {
        let t = b;
        b = c;
        c = t;
        area = -area;
    }
    let size = vec2<f32>(opacity_plane.resolution);
    let lo = max(floor(min(a.xy, min(b.xy, c.xy))), vec2(0.0));
    let hi = min(min(ceil(max(a.xy, max(b.xy, c.xy))), size), lo + MAX_SPAN);
    if any(lo >= hi) {
        return;
    }
    let width = opacity_plane.resolution.x;
    for (var y = u32(lo.y); y < u32(hi.y); y++) {
        for (var x = u32(lo.x); x < u32(hi.x); x++) {
            let p = vec2(f32(x) + 0.5, f32(y) + 0.5);
            // Edge functions: twice the areas opposite each corner.
            let ea = perp_dot(c.xy - b.xy, p - b.xy);
            let eb = perp_dot(a.xy - c.xy, p - c.xy);
            let ec = perp_dot(b.xy - a.xy, p - a.xy);
            if !(inside(ea, b.xy, c.xy) && inside(eb, c.xy, a.xy) && inside(ec, a.xy, b.xy)) {
                continue;
            }
            let height = max((ea * a.z + eb * b.z + ec * c.z) / area, 0.0);
            let texel = 2u * (y * width + x);
            atomicMax(&opacity_texels[texel], bitcast<u32>(height));
            atomicAdd(&opacity_texels[texel + 1u], fragments);
        }
    }
}
