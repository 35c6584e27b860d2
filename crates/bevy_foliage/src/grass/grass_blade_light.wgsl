#define_import_path bevy_foliage::grass_blade_light

// The blade shadow mask in the blades' main pass (Boulanger 2008, thesis §4.2.6, eq. 4.7): the
// shadows neighbouring blades cast on a blade, which a shadow map cannot resolve. Bevy's PBR
// lights the blade; the share of the sun's direct light the mask holds back is then taken off —
// eq. 4.1's diffuse as Bevy splits it ((1 − γ) on the lit face, γ through to the other, Lambert's
// 1/π), times the sun's shadow term. Main-pass stages only (it reads the view's lights).
#import bevy_pbr::{
    pbr_types::PbrInput,
    mesh_view_bindings as view_bindings,
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    shadows::fetch_directional_shadow,
}
#import bevy_foliage::grass_blade::{blade, shadow_mask}
#import bevy_foliage::grass_functions as grass

// Bevy's shadow term for the sun (the first directional light) at the fragment.
fn sun_visibility(pbr_input: PbrInput, frag_xy: vec2<f32>) -> f32 {
    if view_bindings::lights.n_directional_lights == 0u {
        return 0.0;
    }
    let light = &view_bindings::lights.directional_lights[0];
    if ((*light).flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
        return 1.0;
    }
    let view = view_bindings::view.view_from_world;
    let view_z = dot(vec4(view[0].z, view[1].z, view[2].z, view[3].z), pbr_input.world_position);
    return fetch_directional_shadow(0u, pbr_input.world_position, pbr_input.world_normal, view_z, frag_xy);
}

// The share of the sun's light the shadow mask lets through to this blade point (1 where it
// holds nothing back: above the mask's slab, on the blades' upper parts, or with no sun or no
// mask). Callers fetch the sun's shadow term (a second filtered cascade lookup after the one
// Bevy's lighting made) only where this is below 1.
// `h`: the point's height above the ground; `ld`: the density at the blade.
fn shadow_mask_through(h: f32, ld: f32) -> f32 {
    if view_bindings::lights.n_directional_lights == 0u || blade.mask_shape.y <= 0.0 {
        return 1.0;
    }
    let l = view_bindings::lights.directional_lights[0].direction_to_light;
    return grass::shadow_mask_light(shadow_mask, blade.mask_shape, h, l, ld);
}

// The sun's light the shadow mask holds back at this blade point, exposed, given the sun's
// shadow term `visibility` and the mask's `through` (`shadow_mask_through`).
fn shadow_mask_loss(pbr_input: PbrInput, visibility: f32, through: f32) -> vec3<f32> {
    if view_bindings::lights.n_directional_lights == 0u || visibility <= 0.0 || through >= 1.0 {
        return vec3(0.0);
    }
    let light = &view_bindings::lights.directional_lights[0];
    let c = dot(pbr_input.N, (*light).direction_to_light);
    let g = pbr_input.material.diffuse_transmission;
    let diffuse = pbr_input.material.base_color.rgb * ((1.0 - g) * max(c, 0.0) + g * max(-c, 0.0))
        * (1.0 / 3.14159265);
    return view_bindings::view.exposure * (*light).color.rgb * diffuse * visibility * (1.0 - through);
}
