//! Billboard clouds lit as volumes of leaves: while [`TreeLightingSettings::enabled`] the
//! impostors of the forest draw with [`TreeLitImpostorMaterial`], which lights every atlas texel
//! showing a leaf as that leaf is lit by the tree lighting near the camera (Boulanger 2008,
//! §5.2–5.4: sky and ground through the crown, the sun through it, one bounce), from the eight
//! attenuations the bake stored for it (`impostor::texture`'s light atlases), and leaves texels
//! showing bark to Bevy's PBR — so a tree keeps its light when its impostor takes over.
//!
//! The per-fragment lighting is `tree_lit_impostor.wgsl`, which calls the same
//! `bevy_foliage::tree_lighting::leaf_radiance` as the leaves' vertex stage; its CPU reference
//! is `lighting::model::leaf_radiance` on the texel's values (see the render tests
//! `a_tree_lit_billboard_cloud_*` in `tests/tree_lighting.rs`).

use crate::lighting::settings::TreeLightingSettings;
use crate::pruning::material::{LeafParams, TreeLightUniform};
use bevy::asset::embedded_asset;
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{AsBindGroup, ShaderType};
use bevy::shader::ShaderRef;

/// A billboard cloud's material under the tree lighting: the cloud's own `StandardMaterial`
/// (albedo, normals, alpha mask) extended with its light atlases.
pub type TreeLitImpostorMaterial = ExtendedMaterial<StandardMaterial, TreeLitImpostor>;

/// The tree lighting's part of a billboard cloud's material.
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone)]
pub struct TreeLitImpostor {
    /// Lights, optics and the crown.
    #[uniform(100)]
    pub params: TreeLitImpostorParams,
    /// Attenuations of bins 0–2.
    #[texture(101)]
    #[sampler(102)]
    pub light0: Handle<Image>,
    /// Attenuations of bins 3–5.
    #[texture(103)]
    pub light1: Handle<Image>,
    /// Attenuations of bins 6–7, then 1 for a leaf texel and 0 for bark.
    #[texture(104)]
    pub light2: Handle<Image>,
}

/// Uniforms of [`TreeLitImpostor`] (see `tree_lit_impostor.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct TreeLitImpostorParams {
    /// The optics (multiples of the texel's albedo) and the scene's lights.
    pub lights: TreeLightUniform,
    /// The crown's bounding sphere in model space (centre, radius).
    pub crown_sphere: Vec4,
    /// The crown's extinction τ per unit of model space.
    pub extinction: f32,
    /// 1: the sun through the crown by eq. 5.7's envelope blend (else the attenuations' blend).
    pub smooth_envelope: u32,
    /// 1: one bounce of sunlight.
    pub bounce: u32,
    /// 1: the crown's seen-part gains on (`TreeLightingSettings::seen_part`).
    pub seen_part: u32,
    /// The crown's mean seen-part gain per eye octant (`lighting::seen_part`), octants 0–3 then
    /// 4–7.
    pub seen_gains: [Vec4; 2],
    /// The crown's hotspot packed (`lighting::hotspot::Hotspot::packed`): the sun's exponent
    /// nodes, then the bounce's.
    pub hotspot: UVec4,
    /// The crown's mean bounce ratios (`lighting::gathered_bounce`), the front face's fourteen
    /// then the back face's, four a vector.
    pub bounce_ratios: [Vec4; 7],
    /// 1: the bounce scaled by them (`TreeLightingSettings::gathered_bounce`).
    pub gathered_bounce: u32,
    /// The sun height of the crown's ring of re-gathered ratios
    /// ([`crate::lighting::bounce_ring`]; [`NO_RING`](crate::lighting::bounce_ring::NO_RING)
    /// for none).
    pub ring_height: f32,
    /// 1: the ring read where the sun is at its elevation (`BounceRingSettings::enabled`).
    pub bounce_ring: u32,
    /// The crown's mean ring ratios (`lighting::bounce_ring::crown_mean_ring`), the front
    /// faces' fourteen nodes then the back faces', four a vector.
    pub ring_ratios: [Vec4; 7],
}

impl Default for TreeLitImpostorParams {
    fn default() -> Self {
        Self {
            lights: TreeLightUniform::default(),
            crown_sphere: Vec4::ZERO,
            extinction: 0.0,
            smooth_envelope: 0,
            bounce: 0,
            seen_part: 0,
            seen_gains: [Vec4::ONE; 2],
            hotspot: UVec4::ZERO,
            bounce_ratios: [Vec4::ONE; 7],
            gathered_bounce: 0,
            ring_height: crate::lighting::bounce_ring::NO_RING,
            bounce_ring: 0,
            ring_ratios: [Vec4::ONE; 7],
        }
    }
}

/// Twenty-eight ratios (front faces' fourteen, then the back faces') as the shader's seven
/// vectors.
pub fn ratios_as_vectors(front: &[f32; 14], back: &[f32; 14]) -> [Vec4; 7] {
    let all: Vec<f32> = front.iter().chain(back).copied().collect();
    std::array::from_fn(|i| Vec4::from_slice(&all[4 * i..4 * i + 4]))
}

impl TreeLitImpostorParams {
    /// The cloud's own values (its crown and extinction) with the scene's lights and the
    /// settings' switches and optics from `leaves` (what the leaf materials get:
    /// `pruning::systems::tree_lights`).
    pub fn new(leaves: &LeafParams, own: &TreeLitImpostorParams) -> Self {
        Self {
            lights: leaves.lights,
            crown_sphere: own.crown_sphere,
            extinction: own.extinction,
            smooth_envelope: leaves.smooth_envelope,
            bounce: leaves.bounce,
            seen_part: leaves.seen_part,
            seen_gains: own.seen_gains,
            hotspot: own.hotspot,
            bounce_ratios: own.bounce_ratios,
            gathered_bounce: leaves.gathered_bounce,
            ring_height: own.ring_height,
            bounce_ring: leaves.bounce_ring,
            ring_ratios: own.ring_ratios,
        }
    }
}

const TREE_LIT_IMPOSTOR_SHADER: &str = "embedded://bevy_foliage/impostor/tree_lit_impostor.wgsl";

impl MaterialExtension for TreeLitImpostor {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(TREE_LIT_IMPOSTOR_SHADER.into())
    }

    fn specialize(
        _pipeline: &bevy::pbr::MaterialExtensionPipeline,
        descriptor: &mut bevy::render::render_resource::RenderPipelineDescriptor,
        _layout: &bevy::mesh::MeshVertexBufferLayoutRef,
        _key: bevy::pbr::MaterialExtensionKey<Self>,
    ) -> Result<(), bevy::render::render_resource::SpecializedMeshPipelineError> {
        // The fragment stage turns world directions into the tree's frame through the
        // instance's transform.
        descriptor
            .vertex
            .shader_defs
            .push("VERTEX_OUTPUT_INSTANCE_INDEX".into());
        if let Some(fragment) = descriptor.fragment.as_mut() {
            fragment
                .shader_defs
                .push("VERTEX_OUTPUT_INSTANCE_INDEX".into());
        }
        Ok(())
    }
}

/// Keeps every [`TreeLitImpostorMaterial`]'s lights those of the scene (the sun, the sky and
/// the ground the leaf materials get), its switches and optics those of the settings.
pub fn refresh_tree_lit_impostors(
    lighting: Res<TreeLightingSettings>,
    ambient: Option<Res<GlobalAmbientLight>>,
    suns: Query<(&DirectionalLight, &GlobalTransform)>,
    mut materials: ResMut<Assets<TreeLitImpostorMaterial>>,
) {
    if materials.is_empty() {
        return;
    }
    // The settings are sanitised in place by `lighting::settings` (as the leaves read them).
    let lights = crate::pruning::systems::tree_lights(
        &lighting,
        ambient.as_deref(),
        suns.iter().map(|(l, t)| (l, t.back().as_vec3())),
    );
    let ids: Vec<_> = materials.ids().collect();
    for id in ids {
        let Some(material) = materials.get(id) else {
            continue;
        };
        let own = &material.extension.params;
        let params = TreeLitImpostorParams::new(&lights, own);
        if params != *own
            && let Some(mut material) = materials.get_mut(id)
        {
            material.extension.params = params;
        }
    }
}

/// Registers the tree-lit impostor material and keeps its lights current.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "tree_lit_impostor.wgsl");
    app.add_plugins(MaterialPlugin::<TreeLitImpostorMaterial>::default())
        .add_systems(PostUpdate, refresh_tree_lit_impostors);
}
