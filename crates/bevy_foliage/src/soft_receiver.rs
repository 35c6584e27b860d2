//! Receiving screen-space soft shadows (`bevy_soft_shadows`) in the foliage materials: a material
//! holding the SSSS visibility texture swaps its main pass's fragment stage for one that uses it
//! as the sun's shadow term, while its prepass and shadow pipelines keep their own stages.

use bevy::prelude::*;
use bevy::render::render_resource::RenderPipelineDescriptor;
use bevy::shader::{Shader, ShaderDefVal};

/// In `descriptor`, if `receives` and it is a main-pass pipeline (not a prepass or shadow one),
/// replaces the fragment stage's shader with `soft` (when loaded).
pub(crate) fn use_soft_fragment(
    descriptor: &mut RenderPipelineDescriptor,
    receives: bool,
    soft: Option<&Handle<Shader>>,
) {
    if receives
        && let (Some(fragment), Some(soft)) = (descriptor.fragment.as_mut(), soft)
        && !fragment
            .shader_defs
            .iter()
            .any(|d| *d == ShaderDefVal::from("PREPASS_PIPELINE"))
    {
        fragment.shader = soft.clone();
    }
}
