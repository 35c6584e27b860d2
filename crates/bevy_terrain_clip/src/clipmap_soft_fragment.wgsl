// The terrain's fragment stage with screen-space soft shadows (bevy_soft_shadows) as the sun's
// shadow term. Used only when the material has a soft-visibility texture; it imports
// `bevy_soft_shadows::receiver_functions`, which that crate's plugin provides.
#import bevy_pbr::forward_io::{VertexOutput, FragmentOutput}
#import bevy_terrain_clip::clipmap::clipmap_pbr_input
#import bevy_soft_shadows::receiver_functions::soft_shaded_color

@group(#{MATERIAL_BIND_GROUP}) @binding(105) var soft_visibility: texture_2d<f32>;

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> FragmentOutput {
    var out: FragmentOutput;
    out.color = soft_shaded_color(clipmap_pbr_input(in, is_front), in.position.xy, soft_visibility);
    return out;
}
