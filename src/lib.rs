//! # bevy_nature
//!
//! Nature rendering for Bevy 0.19, in one dependency and one plugin group:
//!
//! - [`foliage`] ([`bevy_foliage`]): GPU view-dependent stochastic pruning of leaves, forest LoD
//!   management under a frame budget, grass, tree lighting, impostors.
//! - [`terrain_clip`] ([`bevy_terrain_clip`]): clipmap virtual textures streamed from tile pyramids
//!   on disk, terrain geometry LoD.
//! - [`soft_shadows`] ([`bevy_soft_shadows`]): screen-space soft shadows, filtered shadow maps,
//!   foliage shadows.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_nature::prelude::*;
//!
//! App::new()
//!     .add_plugins((DefaultPlugins, NaturePlugins))
//!     .run();
//! ```
//!
//! [`showcase`] holds the main example scene (`cargo run --example nature`), shared with the tests.

use bevy::app::{PluginGroup, PluginGroupBuilder};

pub use bevy_foliage as foliage;
pub use bevy_soft_shadows as soft_shadows;
pub use bevy_terrain_clip as terrain_clip;

pub mod bench_curves;
pub mod forest_scene;
pub mod grass_terrain;
pub mod shadow_scene;
pub mod showcase;

/// All the suite's plugins. Each can be disabled or configured like any Bevy plugin group:
/// `NaturePlugins.build().disable::<bevy_nature::foliage::FoliagePlugin>()`.
pub struct NaturePlugins;

impl PluginGroup for NaturePlugins {
    fn build(self) -> PluginGroupBuilder {
        PluginGroupBuilder::start::<Self>()
            .add(foliage::FoliagePlugin)
            .add(foliage::grass::GrassPlugin)
            .add(terrain_clip::TerrainClipPlugin)
            .add(soft_shadows::SoftShadowsPlugin)
            .add(NatureGluePlugin)
    }
}

/// Connects the suite's crates where they meet (each works without the others): the clipmap
/// terrain, leaf, grass-blade and grass-slice materials receive Screen Space Soft Shadows while a
/// light has them.
#[derive(Default)]
pub struct NatureGluePlugin;

impl bevy::app::Plugin for NatureGluePlugin {
    fn build(&self, app: &mut bevy::app::App) {
        app.add_systems(
            bevy::app::PostUpdate,
            (
                receive_soft_shadows::<terrain_clip::material::ClipmapExtension>,
                receive_soft_shadows::<foliage::pruning::material::LeafExtension>,
                receive_soft_shadows::<foliage::grass::material::GrassBladeExtension>,
                grass_slices_receive_soft_shadows,
            ),
        );
    }
}

/// A material extension that can hold the SSSS visibility texture.
trait SoftShadowReceiving: bevy::pbr::MaterialExtension {
    fn soft_visibility(&mut self) -> &mut Option<bevy::prelude::Handle<bevy::prelude::Image>>;
    fn holds(&self, texture: &bevy::prelude::Handle<bevy::prelude::Image>) -> bool;
}

impl SoftShadowReceiving for terrain_clip::material::ClipmapExtension {
    fn soft_visibility(&mut self) -> &mut Option<bevy::prelude::Handle<bevy::prelude::Image>> {
        &mut self.soft_visibility
    }
    fn holds(&self, texture: &bevy::prelude::Handle<bevy::prelude::Image>) -> bool {
        self.soft_visibility.as_ref() == Some(texture)
    }
}

impl SoftShadowReceiving for foliage::pruning::material::LeafExtension {
    fn soft_visibility(&mut self) -> &mut Option<bevy::prelude::Handle<bevy::prelude::Image>> {
        &mut self.soft_visibility
    }
    fn holds(&self, texture: &bevy::prelude::Handle<bevy::prelude::Image>) -> bool {
        self.soft_visibility.as_ref() == Some(texture)
    }
}

impl SoftShadowReceiving for foliage::grass::material::GrassBladeExtension {
    fn soft_visibility(&mut self) -> &mut Option<bevy::prelude::Handle<bevy::prelude::Image>> {
        &mut self.soft_visibility
    }
    fn holds(&self, texture: &bevy::prelude::Handle<bevy::prelude::Image>) -> bool {
        self.soft_visibility.as_ref() == Some(texture)
    }
}

/// The SSSS visibility texture, while SSSS is on and has one.
fn ssss_visibility(
    active: Option<bevy::prelude::Res<soft_shadows::ssss::receiver::SsssActive>>,
    textures: Option<bevy::prelude::Res<soft_shadows::ssss::receiver::SsssTextures>>,
) -> Option<bevy::prelude::Handle<bevy::prelude::Image>> {
    let (active, textures) = (active?, textures?);
    (active.0 && textures.size != bevy::math::UVec2::ZERO).then(|| textures.visibility.clone())
}

/// Puts `texture` in the soft-visibility `slot` of every material in `materials` not holding it.
fn hand_over_visibility<M: bevy::asset::Asset>(
    materials: &mut bevy::prelude::Assets<M>,
    texture: &bevy::prelude::Handle<bevy::prelude::Image>,
    slot: impl Fn(&mut M) -> &mut Option<bevy::prelude::Handle<bevy::prelude::Image>>,
    holds: impl Fn(&M) -> bool,
) {
    let stale: Vec<_> = materials
        .iter()
        .filter(|(_, m)| !holds(m))
        .map(|(id, _)| id)
        .collect();
    for id in stale {
        if let Some(mut material) = materials.get_mut(id) {
            *slot(&mut material) = Some(texture.clone());
        }
    }
}

/// Gives every `ExtendedMaterial<StandardMaterial, E>` the SSSS visibility texture once SSSS is
/// on.
fn receive_soft_shadows<E: SoftShadowReceiving>(
    active: Option<bevy::prelude::Res<soft_shadows::ssss::receiver::SsssActive>>,
    textures: Option<bevy::prelude::Res<soft_shadows::ssss::receiver::SsssTextures>>,
    materials: Option<
        bevy::prelude::ResMut<
            bevy::prelude::Assets<bevy::pbr::ExtendedMaterial<bevy::prelude::StandardMaterial, E>>,
        >,
    >,
) {
    let (Some(texture), Some(mut materials)) = (ssss_visibility(active, textures), materials)
    else {
        return;
    };
    hand_over_visibility(
        &mut materials,
        &texture,
        |m| m.extension.soft_visibility(),
        |m| m.extension.holds(&texture),
    );
}

/// Gives the grass slice material the SSSS visibility texture once SSSS is on.
fn grass_slices_receive_soft_shadows(
    active: Option<bevy::prelude::Res<soft_shadows::ssss::receiver::SsssActive>>,
    textures: Option<bevy::prelude::Res<soft_shadows::ssss::receiver::SsssTextures>>,
    materials: Option<
        bevy::prelude::ResMut<
            bevy::prelude::Assets<foliage::grass::slice_material::GrassSliceMaterial>,
        >,
    >,
) {
    let (Some(texture), Some(mut materials)) = (ssss_visibility(active, textures), materials)
    else {
        return;
    };
    hand_over_visibility(
        &mut materials,
        &texture,
        |m| &mut m.soft_visibility,
        |m| m.soft_visibility.as_ref() == Some(&texture),
    );
}

/// Everything a game usually imports.
pub mod prelude {
    pub use crate::NaturePlugins;
    pub use bevy_foliage::prelude::*;
    pub use bevy_soft_shadows::prelude::*;
    pub use bevy_terrain_clip::prelude::*;
}
