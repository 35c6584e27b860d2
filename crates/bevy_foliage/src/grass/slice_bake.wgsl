// The grass slice bake (Boulanger 2008, thesis §4.3.2): the base patch's blades, seen by one
// slice camera, write one layer of the slice image — the unlit row (kd·ao, coverage), the
// density-threshold row (the blade's threshold and height fraction), or the direct response to
// one of the five baked light directions (eq. 4.1 without its ambient term, the lit face keeping
// 1 − γ as Bevy's diffuse transmission does) on the face towards the camera.
// `grass::slices::bake_reference` is the CPU reference of exactly this.

#import bevy_pbr::forward_io::VertexOutput

struct SliceBakeParams {
    // xyz: unit direction to the camera; w: the layer.
    view: vec4<f32>,
    // rgb: root colour; w: ambient occlusion at the root.
    root_color: vec4<f32>,
    // rgb: tip colour; w: transmission γ.
    tip_color: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: SliceBakeParams;

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    // uv_b = (blade threshold, height fraction), `grass::mesh`.
    let h = clamp(in.uv_b.y, 0.0, 1.0);
    let kd = mix(params.root_color.rgb, params.tip_color.rgb, h);
    let layer = u32(params.view.w + 0.5);
    if layer == 0u {
        let ao = params.root_color.w + (1.0 - params.root_color.w) * h;
        return vec4(kd * ao, 1.0);
    }
    if layer == 1u {
        return vec4(in.uv_b.x, h, 0.0, 1.0);
    }
    var n = normalize(in.world_normal);
    if dot(n, params.view.xyz) < 0.0 {
        n = -n;
    }
    // Y+, X+, X−, Z+, Z− (`grass::lighting::BTF_DIRECTIONS`).
    var directions = array<vec3<f32>, 5>(
        vec3(0.0, 1.0, 0.0), vec3(1.0, 0.0, 0.0), vec3(-1.0, 0.0, 0.0),
        vec3(0.0, 0.0, 1.0), vec3(0.0, 0.0, -1.0),
    );
    let l = directions[(layer - 2u) % 5u];
    let c = dot(n, l);
    let g = params.tip_color.w;
    let direct = (1.0 - g) * max(c, 0.0) + g * max(-c, 0.0);
    return vec4(kd * direct, 1.0);
}
