// The trees' opacity shadow map's lookup (Boulanger 2008, §5.5.2.2, algorithm 7): how much of the
// sun reaches a receiver through the leaves. CPU reference: `visibility` in `opacity_map.rs`.
#define_import_path bevy_soft_shadows::opacity_receiver

struct TreeOpacityReceiver {
    // Unit direction from the scene to the sun, and the plane's height.
    to_light: vec3<f32>,
    plane_y: f32,
    // World (x, z) of the map's corner at uv (0, 0), and its world extent.
    origin: vec2<f32>,
    extent: vec2<f32>,
    // The smaller side of a texel (world units), the sun's angular diameter, the mip count.
    texel: f32,
    sun_angle: f32,
    mips: f32,
    pad: f32,
    // Bevy's index of the directional light the map is for; 0xffffffff: no map.
    light: vec4<u32>,
}

const NO_TREE_MAP: u32 = 0xffffffffu;

// The mip level the occluders' height is read at (algorithm 7 reads level 4).
const HEIGHT_SEARCH_LEVEL: f32 = 4.0;

// The transmittance of the leaves between `position` and the sun: 1 lit, 0 fully shadowed.
fn tree_transmittance(
    receiver: TreeOpacityReceiver,
    map: texture_2d<f32>,
    map_sampler: sampler,
    position: vec3<f32>,
) -> f32 {
    if receiver.light.x == NO_TREE_MAP {
        return 1.0;
    }
    // Eq. 5.27: the receiver projected along the sun's ray onto the plane.
    let along = (position.y - receiver.plane_y) / receiver.to_light.y;
    let world = vec2(position.x - receiver.to_light.x * along, position.z - receiver.to_light.z * along);
    let uv = (world - receiver.origin) / receiver.extent;
    if any(uv < vec2(0.0)) || any(uv > vec2(1.0)) {
        return 1.0;
    }
    let last = receiver.mips - 1.0;
    let coarse = textureSampleLevel(map, map_sampler, uv, min(HEIGHT_SEARCH_LEVEL, last));
    let height = position.y - receiver.plane_y;
    if coarse.y >= 0.99 || coarse.x <= height {
        return 1.0;
    }
    // From the receiver up its ray to the occluders, and the sun's disk's width there in texels.
    let distance = (coarse.x - height) / receiver.to_light.y;
    let footprint = distance * receiver.sun_angle / receiver.texel;
    let level = clamp(log2(max(footprint, 1.0)), 0.0, last);
    return clamp(textureSampleLevel(map, map_sampler, uv, level).y, 0.0, 1.0);
}
