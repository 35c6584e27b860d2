// The trees' opacity shadow map after its casters drew (Boulanger 2008, §5.5.2): `resolve` turns
// each texel's accumulated words (`opacity_caster.wgsl`) into (height, transmittance) at mip 0;
// `downsample` makes each coarser texel the maximum height and the mean transmittance of the
// four below it. CPU reference: `OpacityShadowMap::mips` in `opacity_map.rs`.
#import bevy_soft_shadows::opacity_caster::OpacityPlane

// The leaf's transparency (§5.5.2.1): each leaf fragment on a ray lets 0.9 of the light through.
const LEAF_TRANSPARENCY: f32 = 0.9;

@group(0) @binding(0) var<storage, read> texels: array<u32>;
@group(0) @binding(1) var<uniform> plane: OpacityPlane;
@group(0) @binding(2) var finer: texture_2d<f32>;
@group(0) @binding(3) var level: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8, 1)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= plane.resolution) {
        return;
    }
    let texel = 2u * (id.y * plane.resolution.x + id.x);
    let height = bitcast<f32>(texels[texel]);
    let transmittance = pow(LEAF_TRANSPARENCY, f32(texels[texel + 1u]));
    textureStore(level, id.xy, vec4(height, transmittance, 0.0, 0.0));
}

@compute @workgroup_size(8, 8, 1)
fn downsample(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= textureDimensions(level)) {
        return;
    }
    let below = textureDimensions(finer);
    var height = 0.0;
    var transmittance = 0.0;
    var n = 0.0;
    for (var k = 0u; k < 4u; k++) {
        let p = 2u * id.xy + vec2(k & 1u, k >> 1u);
        if all(p < below) {
            let t = textureLoad(finer, p, 0);
            height = max(height, t.x);
            transmittance += t.y;
            n += 1.0;
        }
    }
    textureStore(level, id.xy, vec4(height, transmittance / max(n, 1.0), 0.0, 0.0));
}
