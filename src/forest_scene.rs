//! The forest scenes of Gumbau 2011, table 3.5, shared by the `forest` example and the
//! `forest_bench` benchmark: a dense forest of 6,450 trees and a sparse one of 210 (and a huge one
//! of 100,000 for scale), mixing the four test trees, on a ground plane, the camera standing
//! inside.
//!
//! Each scene sets `far` so that about as many trees are nearer than `far` in view as in the
//! thesis: 508 of 6,450 (8 %) and 24 of 210. The same placements can be drawn four ways
//! ([`ForestDraw`]): by the manager ([`ForestTree`], pruning, billboard clouds beyond `far`), as
//! the `VisibilityRange` baseline a Bevy user would build, at full detail everywhere (the
//! reference), or not at all; [`set_forest_draw`] swaps them, so a benchmark row runs only its own
//! trees.

use bevy::asset::io::file::FileAssetReader;
use bevy::camera::visibility::VisibilityRange;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy_foliage::forest::hlod::decimated_leaves;
use bevy_foliage::impostor::bake::{ImpostorBakeRequest, ImpostorBakeResult, ImpostorBakeSettings};
use bevy_foliage::impostor::systems::{BakedImpostor, ImpostorFromBake, TreeBark};
use bevy_foliage::impostor::texture::{BakeSurface, ImpostorSource};
use bevy_foliage::meshes::{bark_mesh, leaf_set_mesh};
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, bake};
use bevy_foliage::pruning::leaves::LeafSet;
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::pruning::spawn::{default_bark_material, default_leaf_material};
use bevy_foliage::rng::SplitMix64;
use bevy_foliage::{FoliagePruningSettings, ForestTree};

/// Which forest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ForestKind {
    /// 6,450 trees, about 508 in view.
    Dense,
    /// 210 trees, about 24 in view.
    Sparse,
    /// 100,000 trees at the dense forest's density, laid out procedurally (scale test).
    Huge,
}

impl ForestKind {
    /// Parses `dense` or `sparse`.
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "dense" => Some(Self::Dense),
            "sparse" => Some(Self::Sparse),
            "huge" => Some(Self::Huge),
            _ => None,
        }
    }

    /// Trees in the forest.
    pub fn tree_count(self) -> usize {
        match self {
            Self::Dense => 6450,
            Self::Sparse => 210,
            Self::Huge => 100_000,
        }
    }

    /// Side of the square the trees stand on (m).
    pub fn side(self) -> f32 {
        match self {
            Self::Dense => 1100.0,
            Self::Sparse => 300.0,
            // The dense forest's density: 6,450 trees on 1,100 m × 1,100 m.
            Self::Huge => 1100.0 * (100_000.0f32 / 6450.0).sqrt(),
        }
    }

    /// Near and far of the LoD (m): `far` gives about the thesis' count in view (in the frustum
    /// and nearer than `far`) for the 45° 16:9 benchmark camera at the centre (measured: 239
    /// trees with far = 250 m, so 360 m for ~500; sparse: 18 at 100 m, so 115 m for ~24).
    pub fn near_far(self) -> (f32, f32) {
        match self {
            Self::Dense | Self::Huge => (15.0, 360.0),
            Self::Sparse => (15.0, 115.0),
        }
    }
}

/// The scene flags shared by the `forest` example and benchmark: `--forest dense|sparse` and
/// `--leaf-scale F`; everything else is returned for the example runner.
#[derive(Clone, Debug, PartialEq)]
pub struct ForestArgs {
    /// Which forest (`--forest`, default dense).
    pub kind: ForestKind,
    /// Fraction of the thesis' leaf counts (`--leaf-scale`, in (0, 1]).
    pub leaf_scale: f32,
    /// The flags not taken here, in order.
    pub rest: Vec<String>,
}

impl ForestArgs {
    /// Takes the scene flags out of `args`; `leaf_scale` is the default scale.
    pub fn parse(args: impl IntoIterator<Item = String>, leaf_scale: f32) -> Result<Self, String> {
        let mut out = Self {
            kind: ForestKind::Dense,
            leaf_scale,
            rest: Vec::new(),
        };
        let mut args = args.into_iter();
        while let Some(arg) = args.next() {
            match arg.as_str() {
                "--forest" => {
                    let v = args.next().unwrap_or_default();
                    out.kind = ForestKind::parse(&v).ok_or_else(|| {
                        format!("--forest takes dense, sparse or huge, not '{v}'")
                    })?;
                }
                "--leaf-scale" => {
                    let v = args.next().unwrap_or_default();
                    out.leaf_scale = v
                        .parse()
                        .ok()
                        .filter(|s: &f32| *s > 0.0 && *s <= 1.0)
                        .ok_or_else(|| {
                            format!("--leaf-scale takes a number in (0, 1], not '{v}'")
                        })?;
                }
                _ => out.rest.push(arg),
            }
        }
        Ok(out)
    }
}

/// The forest scene: [`spawn_forest`] at startup (needs [`ForestScene`]).
pub struct ForestScenePlugin;

impl Plugin for ForestScenePlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(Startup, spawn_forest);
    }
}

/// The forest to build.
#[derive(Resource, Clone, Debug)]
pub struct ForestScene {
    /// Which forest.
    pub kind: ForestKind,
    /// Fraction of the thesis' leaf counts (16,107 / 28,645 / 41,155 / 131,042) per tree type.
    pub leaf_scale: f32,
    /// What to draw once the types are built.
    pub draw: ForestDraw,
    /// Bake (or load from `assets/impostors/`) a billboard cloud per type for the distant trees.
    pub impostors: bool,
}

/// How the forest is drawn.
#[derive(Clone, Debug, PartialEq)]
pub enum ForestDraw {
    /// Nothing (the ground and sky alone).
    Nothing,
    /// [`ForestTree`]s: the manager, pruning, and billboard clouds beyond `far` if baked.
    Managed,
    /// What a Bevy user builds without this crate: per type, leaf meshes decimated offline and
    /// switched by `VisibilityRange`; the bark drawn up to the last level's end. No manager, no
    /// pruning pass.
    Baseline(BaselineLevels),
    /// Every tree with every leaf and its bark at every distance: the reference image.
    Reference,
}

/// The levels of the `VisibilityRange` baseline: `(fraction of the leaves, end distance in m)`
/// from near to far; the first starts at 0. The bark ends with the last level.
#[derive(Clone, Debug, PartialEq)]
pub struct BaselineLevels(pub Vec<(f32, f32)>);

impl BaselineLevels {
    /// The thesis-like default: full detail to 20 % of `[near, far]`, 40 % of the leaves to
    /// 55 %, 12 % to `far`.
    pub fn standard(kind: ForestKind) -> Self {
        let (near, far) = kind.near_far();
        Self(
            [(1.0, 0.2), (0.4, 0.55), (0.12, 1.0)]
                .iter()
                .map(|&(f, e)| (f, near + e * (far - near)))
                .collect(),
        )
    }
}

/// Parent of the trees of the current [`ForestDraw`].
#[derive(Component)]
pub struct ForestRoot;

/// A tree's type (index into [`ForestTypes`]).
#[derive(Component, Clone, Copy, Debug)]
pub struct ForestTreeType(pub usize);

/// One tree type, built once.
pub struct ForestType {
    /// Species name.
    pub name: &'static str,
    /// Pruning bake.
    pub baked: Handle<BakedFoliage>,
    /// The leaves (decimated for the baseline).
    pub leaves: LeafSet,
    /// Bark mesh.
    pub bark: Handle<Mesh>,
    /// The entity baking (or loading) its billboard cloud.
    pub impostor_bake: Option<Entity>,
}

/// The forest's tree types, materials and placements.
#[derive(Resource)]
pub struct ForestTypes {
    /// The types.
    pub types: Vec<ForestType>,
    /// Leaves of managed trees.
    pub leaf_material: Handle<LeafMaterial>,
    /// Leaves of the baseline and reference (the same look as a `StandardMaterial`).
    pub mesh_leaf_material: Handle<StandardMaterial>,
    /// Bark.
    pub bark_material: Handle<StandardMaterial>,
    /// Every tree: type and transform.
    pub placements: Vec<(usize, Transform)>,
    /// Decimated leaf meshes by (type, fraction in ‰).
    pub decimated: HashMap<(usize, u32), Handle<Mesh>>,
    /// What is drawn now.
    pub drawn: Option<ForestDraw>,
}

/// Where a species' billboard cloud is cached, relative to the asset root.
fn impostor_asset_path(name: &str, leaf_scale: f32) -> String {
    format!(
        "impostors/{name}-{:04}.bbcloud",
        (leaf_scale * 1000.0).round() as u32
    )
}

/// Builds the forest's types (a startup system; needs [`ForestScene`] inserted), spawns the
/// ground and the light, the impostor bakes, and the trees of `ForestScene::draw`.
#[allow(clippy::too_many_arguments)]
pub fn spawn_forest(
    mut commands: Commands,
    scene: Res<ForestScene>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut leaf_materials: ResMut<Assets<LeafMaterial>>,
    mut baked_assets: ResMut<Assets<BakedFoliage>>,
    mut pruning: ResMut<FoliagePruningSettings>,
) {
    let (near, far) = scene.kind.near_far();
    // The thesis' scenes are set in metres (table 3.5): world distances.
    pruning.distances = bevy_foliage::LodDistances::World { near, far };
    let side = scene.kind.side();
    commands.spawn((
        Name::new("ground"),
        Mesh3d(meshes.add(Plane3d::default().mesh().size(side + 2000.0, side + 2000.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.42, 0.47, 0.32),
            perceptual_roughness: 1.0,
            ..default()
        })),
    ));
    let leaf_look = default_leaf_material();
    let leaf_material = leaf_materials.add(leaf_material(leaf_look.clone()));
    let mesh_leaf_material = materials.add(StandardMaterial {
        double_sided: true,
        cull_mode: None,
        ..leaf_look.clone()
    });
    let bark_look = default_bark_material();
    let bark_material = materials.add(bark_look.clone());
    let mut types = Vec::new();
    for species in TreeSpecies::thesis_trees() {
        let count = ((species.leaf_count as f32 * scene.leaf_scale.clamp(0.001, 1.0)).round()
            as usize)
            .max(50);
        let tree = generate(&species.clone().with_leaf_count(count));
        let started = std::time::Instant::now();
        let baked = match bake(&tree.leaves, &BakeSettings::default(), &|_| {}) {
            Ok((baked, _)) => baked,
            Err(e) => {
                error!("{}: {e}", species.name);
                continue;
            }
        };
        info!(
            "baked {} ({count} leaves) in {:.0} ms",
            species.name,
            started.elapsed().as_secs_f64() * 1e3
        );
        let mut impostor_bake = None;
        if scene.impostors {
            let mut source = ImpostorSource::default();
            source.push_leaves(&tree.leaves, bake_surface(&leaf_look, 0.5));
            source.push_bark(&tree.bark, bake_surface(&bark_look, 0.0));
            let asset_path = impostor_asset_path(species.name, scene.leaf_scale);
            impostor_bake = Some(
                commands
                    .spawn(ImpostorBakeRequest {
                        label: species.name.to_string(),
                        source: std::sync::Arc::new(source),
                        settings: ImpostorBakeSettings::default(),
                        save_to: Some(
                            FileAssetReader::get_base_path()
                                .join("assets")
                                .join(&asset_path),
                        ),
                    })
                    .id(),
            );
        }
        types.push(ForestType {
            name: species.name,
            baked: baked_assets.add(baked),
            leaves: tree.leaves,
            bark: meshes.add(bark_mesh(&tree.bark)),
            impostor_bake,
        });
    }
    let mut placements = Vec::new();
    if !types.is_empty() {
        let mut rng = SplitMix64::new(2011);
        for i in 0..scene.kind.tree_count() {
            let ty = i % types.len();
            let position = Vec3::new(
                rng.range(-side / 2.0, side / 2.0),
                0.0,
                rng.range(-side / 2.0, side / 2.0),
            );
            let transform = Transform::from_translation(position)
                .with_rotation(Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)))
                .with_scale(Vec3::splat(rng.range(0.85, 1.15)));
            // Keep a clearing around the camera's spot.
            if position.length() >= 6.0 {
                placements.push((ty, transform));
            }
        }
    }
    commands.insert_resource(ForestTypes {
        types,
        leaf_material,
        mesh_leaf_material,
        bark_material,
        placements,
        decimated: HashMap::new(),
        drawn: None,
    });
    let draw = scene.draw.clone();
    commands.queue(move |world: &mut World| set_forest_draw(world, &draw));
    commands.spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.4, -1.0, -0.3), Vec3::Y),
    ));
    commands.insert_resource(GlobalAmbientLight {
        brightness: 500.0,
        ..default()
    });
}

/// A `StandardMaterial`'s look as a bake surface (colour factor, no texture).
fn bake_surface(look: &StandardMaterial, alpha_cutoff: f32) -> BakeSurface {
    let c = look.base_color.to_linear();
    BakeSurface {
        base_color: Vec4::new(c.red, c.green, c.blue, c.alpha),
        texture: None,
        alpha_cutoff,
    }
}

/// Whether every species' billboard cloud is baked (or its bake failed) and loaded; true
/// without impostors.
pub fn forest_impostors_ready(world: &mut World) -> bool {
    let Some(types) = world.get_resource::<ForestTypes>() else {
        return false;
    };
    let bakes: Vec<Entity> = types.types.iter().filter_map(|t| t.impostor_bake).collect();
    let server = world.resource::<AssetServer>();
    bakes.iter().all(|&bake| {
        let Ok(entity) = world.get_entity(bake) else {
            return true;
        };
        if entity
            .get::<ImpostorBakeResult>()
            .is_some_and(|r| r.0.is_err())
        {
            return true;
        }
        entity.get::<BakedImpostor>().is_some_and(|b| {
            server.is_loaded_with_dependencies(b.0.id()) || server.load_state(b.0.id()).is_failed()
        })
    })
}

/// Replaces the drawn trees with those of `draw`.
pub fn set_forest_draw(world: &mut World, draw: &ForestDraw) {
    let roots: Vec<Entity> = world
        .query_filtered::<Entity, With<ForestRoot>>()
        .iter(world)
        .collect();
    for root in roots {
        world.entity_mut(root).despawn();
    }
    let Some(mut types) = world.remove_resource::<ForestTypes>() else {
        return;
    };
    // Decimated meshes the baseline needs.
    if let ForestDraw::Baseline(levels) = draw {
        let mut meshes = world.resource_mut::<Assets<Mesh>>();
        for ty in 0..types.types.len() {
            for &(fraction, _) in &levels.0 {
                let key = (ty, (fraction * 1000.0).round() as u32);
                if !types.decimated.contains_key(&key) {
                    let mesh = leaf_set_mesh(&decimated_leaves(
                        &types.types[ty].leaves,
                        fraction,
                        17 + key.1 as u64,
                    ));
                    types.decimated.insert(key, meshes.add(mesh));
                }
            }
        }
    }
    if matches!(draw, ForestDraw::Reference) {
        let mut meshes = world.resource_mut::<Assets<Mesh>>();
        for ty in 0..types.types.len() {
            types
                .decimated
                .entry((ty, 1000))
                .or_insert_with(|| meshes.add(leaf_set_mesh(&types.types[ty].leaves)));
        }
    }
    let root = world
        .spawn((
            Name::new(format!("forest ({draw:?})")),
            ForestRoot,
            Transform::IDENTITY,
            Visibility::Inherited,
        ))
        .id();
    for &(ty, transform) in &types.placements {
        let t = &types.types[ty];
        match draw {
            ForestDraw::Nothing => {}
            ForestDraw::Managed => {
                let mut tree = world.spawn((
                    ForestTree {
                        baked: t.baked.clone(),
                        material: types.leaf_material.clone(),
                    },
                    ForestTreeType(ty),
                    transform,
                    ChildOf(root),
                ));
                if let Some(bake) = t.impostor_bake {
                    tree.insert(ImpostorFromBake(bake));
                }
                tree.with_child((
                    Mesh3d(t.bark.clone()),
                    MeshMaterial3d(types.bark_material.clone()),
                    TreeBark,
                ));
            }
            ForestDraw::Baseline(levels) => {
                let mut start = 0.0;
                let mut children = Vec::new();
                for &(fraction, end) in &levels.0 {
                    let key = (ty, (fraction * 1000.0).round() as u32);
                    children.push((
                        Mesh3d(types.decimated[&key].clone()),
                        MeshMaterial3d(types.mesh_leaf_material.clone()),
                        VisibilityRange::abrupt(start, end),
                    ));
                    start = end;
                }
                world
                    .spawn((transform, Visibility::Inherited, ChildOf(root)))
                    .with_children(|tree| {
                        tree.spawn((
                            Mesh3d(t.bark.clone()),
                            MeshMaterial3d(types.bark_material.clone()),
                            VisibilityRange::abrupt(0.0, start),
                        ));
                        for level in children {
                            tree.spawn(level);
                        }
                    });
            }
            ForestDraw::Reference => {
                world
                    .spawn((transform, Visibility::Inherited, ChildOf(root)))
                    .with_children(|tree| {
                        tree.spawn((
                            Mesh3d(t.bark.clone()),
                            MeshMaterial3d(types.bark_material.clone()),
                        ));
                        tree.spawn((
                            Mesh3d(types.decimated[&(ty, 1000)].clone()),
                            MeshMaterial3d(types.mesh_leaf_material.clone()),
                        ));
                    });
            }
        }
    }
    types.drawn = Some(draw.clone());
    world.insert_resource(types);
}

/// The camera's standing point: the forest's centre, looking along +x, slightly down.
pub fn camera_transform() -> Transform {
    Transform::from_xyz(0.0, 3.0, 0.0).looking_to(Vec3::new(1.0, -0.05, 0.15), Vec3::Y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_flags_are_taken_and_the_rest_kept() {
        let args = [
            "--headless",
            "--forest",
            "sparse",
            "--leaf-scale",
            "0.5",
            "--frames",
            "3",
        ]
        .map(String::from);
        let parsed = ForestArgs::parse(args, 0.1).unwrap();
        assert_eq!(parsed.kind, ForestKind::Sparse);
        assert_eq!(parsed.leaf_scale, 0.5);
        assert_eq!(parsed.rest, ["--headless", "--frames", "3"]);
        assert!(ForestArgs::parse(["--forest".into(), "jungle".into()], 0.1).is_err());
        assert!(ForestArgs::parse(["--leaf-scale".into(), "0".into()], 0.1).is_err());
        assert_eq!(ForestArgs::parse([], 0.25).unwrap().leaf_scale, 0.25);
    }
}
