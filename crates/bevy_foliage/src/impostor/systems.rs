//! Forest trees drawn by their billboard cloud where pruning has thinned their crown to nothing.
//!
//! A [`ForestTree`] with a [`TreeImpostor`] gets an impostor (the cloud's quads and
//! `StandardMaterial`, or its `TreeLitImpostorMaterial` while the tree lighting is on): an entity
//! beside the tree — a child of the tree's parent with the tree's
//! transform — so that it stays drawn while the manager hides the tree itself, bark and leaves,
//! where its leaves are gone. The handover is a cross-fade over a distance band ending at the pruning's
//! `far` (where the desired LoD reaches 0): inside the band the impostor dithers in through Bevy's
//! own `VisibilityRange` dithering while pruning removes the last leaves stochastically (another
//! dither, leaf by leaf, with area compensation), and the tree's bark, marked [`TreeBark`],
//! dithers out. Beyond `far` the tree is its impostor alone — never nothing.
//!
//! With `LodDistances::ScreenSize` the band is converted per tree into world distances from its
//! crown radius and the camera's projection, so large and small trees hand over at the same size
//! on screen.

use super::assets::BillboardCloudAsset;
use super::bake::{ImpostorBakeRequest, ImpostorBakeResult};
use crate::distance::{LodDistances, LodView};
use crate::forest::components::{ForestSettings, ForestTree, TreeLod};
use crate::pruning::components::FoliageCamera;
use crate::pruning::systems::pruning_camera;
use crate::settings::FoliagePruningSettings;
use bevy::camera::visibility::VisibilityRange;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::prelude::*;

/// A forest tree's billboard cloud: drawn beyond the pruning's `far`, cross-faded over
/// [`ImpostorSettings::fade_band`].
#[derive(Component, Clone, Debug)]
pub struct TreeImpostor(pub Handle<BillboardCloudAsset>);

/// Put on a forest tree: it gets the billboard cloud baked by the named entity (an
/// [`ImpostorBakeRequest`], usually one per species) as its
/// [`TreeImpostor`] once that bake is done. A failed bake leaves the tree on its pruned geometry
/// (the bake logged why).
#[derive(Component, Clone, Copy, Debug)]
pub struct ImpostorFromBake(pub Entity);

/// On a finished bake entity: the billboard cloud asset it made (loaded through the
/// `AssetServer` when the bake was saved under the asset folder).
#[derive(Component, Clone, Debug)]
pub struct BakedImpostor(pub Handle<BillboardCloudAsset>);

/// Marks a forest tree's bark mesh (a child entity): it fades out where the impostor fades in.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct TreeBark;

/// The impostor the plugin spawned for a tree (on the tree).
#[derive(Component, Clone, Copy, Debug)]
pub struct ImpostorChild(pub Entity);

/// On an impostor entity: the tree it draws (it is despawned with it).
#[derive(Component, Clone, Copy, Debug)]
pub struct ImpostorOf(pub Entity);

/// On an impostor entity drawn with the tree lighting's material
/// ([`TreeLitImpostorMaterial`](super::tree_lit::TreeLitImpostorMaterial)). When the tree
/// lighting is switched, impostors are spawned again with the other material rather than
/// having their material component swapped.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct TreeLitImpostorDraw;

/// Settings of the impostors.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Default, Debug, PartialEq)]
pub struct ImpostorSettings {
    /// Draw impostors (off: trees beyond `far` draw nothing, as without this module).
    pub enabled: bool,
    /// Width of the cross-fade band before `far`, as a fraction of `far` (world distance).
    pub fade_band: f32,
    /// Colour-code each tree by what draws it: billboard clouds orange, leaf geometry by LoD band
    /// ([`GEOMETRY_TINTS`](crate::forest::systems::GEOMETRY_TINTS): full detail blue, pruned
    /// cyan, green, magenta).
    pub show_representation: bool,
}

impl Default for ImpostorSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            fade_band: 0.15,
            show_representation: false,
        }
    }
}

impl ImpostorSettings {
    /// These settings with unusable values replaced, and what was replaced.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut s = self.clone();
        let mut fixes = Vec::new();
        if !(s.fade_band.is_finite() && (0.0..=0.9).contains(&s.fade_band)) {
            fixes.push(format!(
                "fade_band = {} must be in [0, 0.9]: using 0.15",
                s.fade_band
            ));
            s.fade_band = 0.15;
        }
        (s, fixes)
    }
}

/// Trees drawn by their impostor (fully or fading in) this frame.
pub const IMPOSTORS_DRAWN: DiagnosticPath = DiagnosticPath::const_new("forest/impostors");

/// The world distance at which a crown of `radius` is at LoD distance `rho` (inverse of
/// [`LodDistances::lod_distance`]); orthographic screen sizes do not depend on distance.
pub fn world_distance(distances: &LodDistances, rho: f32, radius: f32, view: &LodView) -> f32 {
    match distances {
        LodDistances::World { .. } => rho,
        LodDistances::ScreenSize { .. } => {
            if view.orthographic {
                f32::INFINITY
            } else {
                rho * radius * view.yy
            }
        }
    }
}

/// The visibility ranges of a tree's impostor (fading in) and bark (fading out) for a tree whose
/// LoD reaches 0 at world distance `far`.
pub fn handover_ranges(far: f32, fade_band: f32) -> (VisibilityRange, VisibilityRange) {
    let far = if far.is_finite() {
        far.max(0.0)
    } else {
        f32::MAX
    };
    let start = far * (1.0 - fade_band.clamp(0.0, 0.9));
    (
        // Distances to the entity's origin: what Bevy's shaders dither by, too.
        VisibilityRange {
            start_margin: start..far,
            end_margin: f32::MAX..f32::MAX,
            use_aabb: false,
        },
        VisibilityRange {
            start_margin: 0.0..0.0,
            end_margin: start..far,
            use_aabb: false,
        },
    )
}

/// Dither levels of Bevy's visibility-range fade: a fading mesh is drawn at one of 16 + 1
/// levels, `round(16 · fraction)` (`get_visibility_range_dither_level` in `bevy_pbr`).
pub const FADE_LEVELS: f32 = 16.0;

/// Ratio between consecutive distances a fading tree's window is anchored at.
///
/// Bevy keeps every distinct [`VisibilityRange`] it has ever seen in its render-world table
/// (`RenderVisibilityRanges` never frees a slot, so indices baked into meshes stay valid) and
/// aliases every range past the 65,535th onto slot 0. A window anchored at each tree's exact
/// distance would add two ranges per fading tree per frame — a table that grows without bound
/// (resident memory rising by megabytes a frame in a flying camera's soak) and, after a minute
/// of fades, wrong dithering. Anchored on this geometric ladder instead, the fade uses at most
/// `2 · 15 · FADE_ANCHORS` ranges for the life of the app. With the window as wide as the
/// anchor distance, a tree up to half a step from its anchor is off by at most
/// `16 · (√ratio − 1) < 0.25` of a dither level, so Bevy rounds it to exactly the level it
/// would get from a window at its own distance: nothing visible is lost.
pub const FADE_ANCHOR_RATIO: f32 = 1.0 + 1.0 / 32.0;

/// Nearest anchor distance of the fade's ladder (closer trees use it).
pub const FADE_NEAREST_ANCHOR: f32 = 0.25;

/// Number of anchors of the fade's ladder, from [`FADE_NEAREST_ANCHOR`] up (about 65 km).
pub const FADE_ANCHORS: i32 = 406;

/// The visibility ranges that show a tree at `distance` from the camera as `weight` of its
/// impostor and `1 − weight` of its bark, dithered (the mixed LoD's fade over time): a window
/// of the dithering ramp placed so the tree's distance falls `weight` of the way into it.
///
/// The weight is rounded to Bevy's 16 dither levels and the window anchored on a ladder of
/// distances ([`FADE_ANCHOR_RATIO`]), so the ranges come from a bounded set however long the
/// camera flies, and Bevy draws the same dither level as for an exact window.
pub fn fade_ranges(distance: f32, weight: f32) -> (VisibilityRange, VisibilityRange) {
    let d = if distance.is_finite() {
        distance.max(0.0)
    } else {
        0.0
    };
    let level = (weight.clamp(0.0, 1.0) * FADE_LEVELS).round();
    // Settled trees (and trees within half a level of settling) get ranges that do not depend
    // on the distance, so only the trees fading right now change their ranges.
    if level >= FADE_LEVELS {
        return (
            VisibilityRange::abrupt(0.0, f32::MAX),
            VisibilityRange::abrupt(0.0, 0.0),
        );
    }
    if level <= 0.0 {
        return (
            VisibilityRange::abrupt(0.0, 0.0),
            VisibilityRange::abrupt(0.0, f32::MAX),
        );
    }
    let w = level / FADE_LEVELS;
    let step = (d.max(FADE_NEAREST_ANCHOR) / FADE_NEAREST_ANCHOR).ln() / FADE_ANCHOR_RATIO.ln();
    let anchor =
        FADE_NEAREST_ANCHOR * FADE_ANCHOR_RATIO.powi((step.round() as i32).min(FADE_ANCHORS - 1));
    // The window is as wide as the anchor distance: [anchor·(1 − w), anchor·(2 − w)].
    let window = anchor * (1.0 - w)..anchor * (2.0 - w);
    (
        VisibilityRange {
            start_margin: window.clone(),
            end_margin: f32::MAX..f32::MAX,
            use_aabb: false,
        },
        VisibilityRange {
            start_margin: 0.0..0.0,
            end_margin: window,
            use_aabb: false,
        },
    )
}

/// Spawns the impostor child of every forest tree whose billboard cloud has loaded, and keeps
/// the impostors' and barks' visibility ranges on the pruning's `far`.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn place_impostors(
    mut commands: Commands,
    settings: Res<ImpostorSettings>,
    lighting: Res<crate::lighting::settings::TreeLightingSettings>,
    pruning: Res<FoliagePruningSettings>,
    clouds: Res<Assets<BillboardCloudAsset>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut tinted: Local<Vec<(AssetId<StandardMaterial>, Handle<StandardMaterial>)>>,
    marked: Query<(&Camera, &GlobalTransform), With<FoliageCamera>>,
    cameras: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    forest: Res<ForestSettings>,
    trees: Query<
        (
            Entity,
            &TreeImpostor,
            &GlobalTransform,
            &Transform,
            Option<&ChildOf>,
            &TreeLod,
            Option<&ImpostorChild>,
            Option<&Children>,
        ),
        With<ForestTree>,
    >,
    // The material is optional: another plugin may have swapped it (soft-shadow receivers).
    mut impostors: Query<
        (
            &mut Visibility,
            &mut Transform,
            Option<&mut MeshMaterial3d<StandardMaterial>>,
            Option<&mut VisibilityRange>,
            Has<TreeLitImpostorDraw>,
        ),
        (With<ImpostorOf>, Without<ForestTree>),
    >,
    mut barks: Query<Option<&mut VisibilityRange>, (With<TreeBark>, Without<ImpostorOf>)>,
) {
    let (camera, view) = pruning_camera(&marked, &cameras)
        .map(|(_, camera, view)| (camera, view))
        .unwrap_or((Vec3::splat(f32::INFINITY), LodView::default()));
    let (_, far_rho) = pruning.distances.range();
    let mixed = forest.enabled && forest.mixed.enabled;
    // Under the tree lighting the clouds' leaf texels are lit as the leaves are (the tinted
    // representation view keeps Bevy's lighting).
    let tree_lit = lighting.enabled && !settings.show_representation;
    for (tree, impostor, transform, local, parent, lod, child, children) in &trees {
        let Some(cloud) = clouds.get(&impostor.0) else {
            continue;
        };
        let scale = transform.scale().abs().max_element();
        let far = world_distance(&pruning.distances, far_rho, cloud.radius * scale, &view);
        let (impostor_range, bark_range) = if settings.enabled && mixed {
            // The mixed LoD chose per tree and fades over time.
            fade_ranges(
                transform.translation().distance(camera),
                lod.impostor_weight,
            )
        } else if settings.enabled {
            handover_ranges(far, settings.fade_band)
        } else {
            // Impostors off: hidden; bark drawn at every distance, as without this module.
            (
                VisibilityRange::abrupt(f32::MAX, f32::MAX),
                VisibilityRange::abrupt(0.0, f32::MAX),
            )
        };
        let material = if settings.show_representation {
            let id = cloud.material.id();
            match tinted.iter().find(|(source, _)| *source == id) {
                Some((_, handle)) => handle.clone(),
                None => {
                    let mut m = materials.get(id).cloned().unwrap_or_default();
                    m.base_color = Color::srgb(1.0, 0.45, 0.1);
                    let handle = materials.add(m);
                    tinted.push((id, handle.clone()));
                    handle
                }
            }
        } else {
            cloud.material.clone()
        };
        let mut existing = child.and_then(|c| impostors.get_mut(c.0).ok().map(|i| (c.0, i)));
        if let Some((entity, (.., lit))) = &existing
            && *lit != tree_lit
        {
            // The other lighting: this impostor goes, one with the other material comes.
            commands.entity(*entity).despawn();
            existing = None;
        }
        match existing.map(|(_, i)| i) {
            Some((mut visibility, mut placed, mesh_material, range, _)) => {
                if *placed != *local {
                    *placed = *local;
                }
                // Not drawn at all when fully faded out (with the mixed LoD) or switched off.
                let v = if settings.enabled && !(mixed && lod.impostor_weight <= 0.0) {
                    Visibility::Inherited
                } else {
                    Visibility::Hidden
                };
                if *visibility != v {
                    *visibility = v;
                }
                if let Some(mut mesh_material) = mesh_material
                    && mesh_material.0 != material
                {
                    mesh_material.0 = material;
                }
                if let Some(mut range) = range
                    && *range != impostor_range
                {
                    *range = impostor_range;
                }
            }
            None => {
                let mut spawned = commands.spawn((
                    Name::new("billboard cloud"),
                    ImpostorOf(tree),
                    Mesh3d(cloud.mesh.clone()),
                    impostor_range,
                    *local,
                ));
                if tree_lit {
                    spawned.insert((MeshMaterial3d(cloud.tree_lit.clone()), TreeLitImpostorDraw));
                } else {
                    spawned.insert(MeshMaterial3d(material));
                }
                if let Some(parent) = parent {
                    spawned.insert(ChildOf(parent.parent()));
                }
                let entity = spawned.id();
                commands.entity(tree).insert(ImpostorChild(entity));
            }
        }
        for &child in children.into_iter().flatten() {
            if let Ok(range) = barks.get_mut(child) {
                match range {
                    Some(mut r) => {
                        if *r != bark_range {
                            *r = bark_range.clone();
                        }
                    }
                    None => {
                        commands.entity(child).insert(bark_range.clone());
                    }
                }
            }
        }
    }
}

/// Despawns the impostors of trees that are gone (or no longer have one).
pub fn despawn_orphan_impostors(
    mut commands: Commands,
    impostors: Query<(Entity, &ImpostorOf)>,
    trees: Query<(), With<TreeImpostor>>,
) {
    for (entity, of) in &impostors {
        if !trees.contains(of.0) {
            commands.entity(entity).despawn();
        }
    }
}

/// Turns finished bakes into billboard cloud assets ([`BakedImpostor`]) and hands them to the
/// trees waiting for them ([`ImpostorFromBake`]).
#[allow(clippy::too_many_arguments)]
pub fn adopt_baked_impostors(
    mut commands: Commands,
    server: Res<AssetServer>,
    mut clouds: ResMut<Assets<BillboardCloudAsset>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut images: ResMut<Assets<Image>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut tree_lit: ResMut<Assets<super::tree_lit::TreeLitImpostorMaterial>>,
    finished: Query<(Entity, &ImpostorBakeRequest, &ImpostorBakeResult), Without<BakedImpostor>>,
    baked: Query<&BakedImpostor>,
    waiting: Query<(Entity, &ImpostorFromBake), Without<TreeImpostor>>,
) {
    for (entity, request, result) in &finished {
        let Ok(data) = &result.0 else {
            continue;
        };
        // Saved under the asset folder: load it as an asset, like any other file.
        let assets_root = bevy::asset::io::file::FileAssetReader::get_base_path().join("assets");
        let handle = match request
            .save_to
            .as_ref()
            .filter(|p| p.exists())
            .and_then(|p| p.strip_prefix(&assets_root).ok())
        {
            Some(relative) => server.load(relative.to_string_lossy().replace('\\', "/")),
            None => clouds.add(BillboardCloudAsset::from_data(
                data,
                &mut meshes,
                &mut images,
                &mut materials,
                &mut tree_lit,
            )),
        };
        commands.entity(entity).insert(BakedImpostor(handle));
    }
    for (tree, from) in &waiting {
        if let Ok(BakedImpostor(handle)) = baked.get(from.0) {
            commands.entity(tree).insert(TreeImpostor(handle.clone()));
        }
    }
}

/// Counts the impostors Bevy decided to draw this frame.
pub fn count_impostors(
    mut diagnostics: Diagnostics,
    impostors: Query<&ViewVisibility, With<ImpostorOf>>,
) {
    let n = impostors.iter().filter(|v| v.get()).count();
    diagnostics.add_measurement(&IMPOSTORS_DRAWN, || n as f64);
}

/// Replaces unusable [`ImpostorSettings`] values, with a warning for each.
pub fn sanitize_impostor_settings(mut settings: ResMut<ImpostorSettings>) {
    let (fixed, fixes) = settings.sanitized();
    if !fixes.is_empty() {
        for fix in &fixes {
            warn!("ImpostorSettings: {fix}");
        }
        *settings = fixed;
    }
}

/// Registers the systems.
pub(crate) fn build(app: &mut App) {
    app.register_type::<ImpostorSettings>()
        .init_resource::<ImpostorSettings>()
        .register_diagnostic(Diagnostic::new(IMPOSTORS_DRAWN).with_max_history_length(1))
        .add_systems(
            PreUpdate,
            sanitize_impostor_settings.run_if(resource_changed::<ImpostorSettings>),
        )
        .add_systems(
            PostUpdate,
            (despawn_orphan_impostors, place_impostors)
                .chain()
                .after(crate::pruning::systems::FoliageSystems::PruningParams)
                .before(bevy::camera::visibility::VisibilitySystems::CheckVisibility),
        )
        .add_systems(
            Update,
            adopt_baked_impostors.after(super::bake::BakeSystems),
        )
        .add_systems(Last, count_impostors);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_impostor_fades_in_where_the_bark_fades_out_and_stays() {
        let (imp, bark) = handover_ranges(100.0, 0.2);
        assert_eq!(imp.start_margin, 80.0..100.0);
        assert_eq!(bark.end_margin, 80.0..100.0);
        // Beyond far: the impostor alone, at any distance.
        assert!(imp.is_visible_at_all(100.0) && imp.is_visible_at_all(1e6));
        assert!(!bark.is_visible_at_all(100.5));
        // Near: no impostor.
        assert!(!imp.is_visible_at_all(79.0));
        assert!(bark.is_visible_at_all(79.0));
    }

    /// Bevy's dither level for a mesh at `d` fading in through `range` (`bevy_pbr`'s
    /// `get_visibility_range_dither_level`, start margin only).
    fn bevy_fade_in_level(range: &VisibilityRange, d: f32) -> i32 {
        let s = &range.start_margin;
        ((d - s.start) / (s.end - s.start) * 16.0)
            .round()
            .clamp(0.0, 16.0) as i32
    }

    #[test]
    fn the_fade_window_puts_the_tree_its_weight_of_the_way_in() {
        for (d, w) in [
            (50.0, 0.125),
            (50.0, 0.25),
            (50.0, 0.875),
            (300.0, 0.6),
            (3.0, 0.5),
            (0.5, 0.3),
            (20_000.0, 0.7),
        ] {
            let (imp, bark) = fade_ranges(d, w);
            // Exactly the dither level of the weight, as Bevy computes it from the window.
            let level = (w * 16.0_f32).round() as i32;
            assert_eq!(bevy_fade_in_level(&imp, d), level, "{d} {w}");
            let e = &bark.end_margin;
            let bark_shown = (e.end - d) / (e.end - e.start);
            let s = &imp.start_margin;
            assert!((bark_shown - (1.0 - (d - s.start) / (s.end - s.start))).abs() < 1e-4);
        }
        // Settled: all of one and none of the other, at any distance.
        let (imp, bark) = fade_ranges(80.0, 1.0);
        assert!(!bark.is_visible_at_all(80.0) && !bark.is_visible_at_all(3.0));
        assert!(imp.is_visible_at_all(3.0) && imp.is_visible_at_all(5000.0));
        let (imp, bark) = fade_ranges(80.0, 0.0);
        assert!(!imp.is_visible_at_all(80.0) && bark.is_visible_at_all(5000.0));
    }

    #[test]
    fn fades_draw_bevys_exact_level_from_a_bounded_set_of_ranges() {
        // A long flight: every distance from 0 to 100 km, finely, at every weight. Bevy never
        // frees a visibility range it has seen and aliases those past 65,535 onto slot 0.
        let mut seen = std::collections::HashSet::new();
        let mut d = 0.0_f32;
        let mut worst = 0;
        while d < 100_000.0 {
            for i in 0..=64 {
                let w = i as f32 / 64.0;
                let (imp, bark) = fade_ranges(d, w);
                for r in [&imp, &bark] {
                    seen.insert([
                        r.start_margin.start.to_bits(),
                        r.start_margin.end.to_bits(),
                        r.end_margin.start.to_bits(),
                        r.end_margin.end.to_bits(),
                    ]);
                }
                if (FADE_NEAREST_ANCHOR..60_000.0).contains(&d) && imp.start_margin.start > 0.0 {
                    let want = (w * 16.0).round() as i32;
                    worst = worst.max((bevy_fade_in_level(&imp, d) - want).abs());
                }
            }
            d = d * 1.001 + 0.01;
        }
        assert_eq!(
            worst, 0,
            "a tree drew another dither level than its weight's"
        );
        let bound = 2 * 15 * FADE_ANCHORS as usize + 4;
        assert!(
            seen.len() <= bound && seen.len() < 65_535 / 2,
            "{} distinct ranges (bound {bound})",
            seen.len()
        );
    }

    #[test]
    fn screen_size_distances_hand_over_at_the_same_size_on_screen() {
        let distances = LodDistances::ScreenSize {
            near: 0.6,
            far: 0.015,
        };
        let view = LodView {
            yy: 2.0,
            orthographic: false,
        };
        let (_, far_rho) = distances.range();
        for radius in [1.0, 4.0, 40.0] {
            let d = world_distance(&distances, far_rho, radius, &view);
            let rho = distances.lod_distance(d, radius, &view);
            assert!((rho - far_rho).abs() / far_rho < 1e-4, "{radius}: {rho}");
        }
    }
}
