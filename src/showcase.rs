//! The main example scene (`cargo run --example nature`), shared with the tests so that what a
//! new user sees first is also what CI renders.
//!
//! So far: a lit ground plane with a box casting a shadow under a directional light, and an
//! olive tree (the thesis' *Olea europaea*, 16,107 leaves) whose leaves are pruned every frame by
//! distance and view direction ([`bevy_foliage::pruning`]), with
//! [`NaturePlugins`](crate::NaturePlugins) added. Each feature of the suite adds itself here as
//! it lands.

use bevy::prelude::*;
use bevy_foliage::pruning::procedural::TreeSpecies;
use bevy_foliage::pruning::spawn::TreeAssets;

/// Where the showcase puts things, so tests can find them on screen.
pub mod layout {
    use bevy::math::Vec3;

    /// Centre of the box; it stands on the ground (`y = 0`).
    pub const BOX_CENTER: Vec3 = Vec3::new(0.0, 0.5, 0.0);
    /// Edge length of the box.
    pub const BOX_SIZE: f32 = 1.0;
    /// Direction the sunlight travels (from the sun into the scene).
    pub const SUN_DIRECTION: Vec3 = Vec3::new(1.0, -1.0, 0.0);
    /// Camera position.
    pub const CAMERA_POSITION: Vec3 = Vec3::new(1.5, 4.5, 9.0);
    /// Where the camera looks.
    pub const CAMERA_TARGET: Vec3 = Vec3::new(-1.0, 1.8, -2.0);
    /// Edge length of the square ground plane.
    pub const GROUND_SIZE: f32 = 20.0;
    /// Where the pruned olive tree stands (behind the box, its shadow falls away from it).
    pub const TREE_POSITION: Vec3 = Vec3::new(-4.0, 0.0, -4.5);
}

/// Options of the showcase scene.
#[derive(Resource, Clone, Debug, Reflect)]
#[reflect(Resource)]
pub struct ShowcaseOptions {
    /// Colour of the box.
    pub box_color: Color,
    /// Offset added to the box position (tests use it to make a different scene).
    pub box_offset: Vec3,
    /// Multisampling of the camera (tests turn it off: the software rasteriser pays for it).
    pub msaa: bool,
    /// The ground textured from a clip stack of procedural aerial imagery streamed tile by tile
    /// (a 131 km virtual texture of 0.5 m texels). Tests turn it off: what a frame shows then
    /// depends on how far streaming got, so two renders of the scene could differ.
    pub terrain: bool,
    /// A backdrop forest of [`ForestTree`](bevy_foliage::ForestTree)s behind the scene, drawn by
    /// the forest LoD manager from shared LoD-cache extractions.
    pub forest: bool,
    /// Screen Space Soft Shadows on the sun: penumbrae harden at contact and widen with the
    /// distance to the blocker on the ground (plain or clipmap-textured), the box and the bark.
    pub soft_shadows: bool,
}

impl Default for ShowcaseOptions {
    fn default() -> Self {
        Self {
            box_color: Color::srgb(0.8, 0.25, 0.2),
            box_offset: Vec3::ZERO,
            msaa: true,
            forest: true,
            terrain: true,
            soft_shadows: true,
        }
    }
}

/// Adds the suite's plugins and the showcase scene to an app that already has Bevy's default
/// plugins (windowed or headless).
pub fn build_showcase(app: &mut App, options: ShowcaseOptions) {
    app.add_plugins(crate::NaturePlugins)
        .insert_resource(options)
        .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
        .add_systems(Startup, spawn_showcase);
}

/// Marks the showcase camera.
#[derive(Component)]
pub struct ShowcaseCamera;

fn spawn_showcase(
    mut commands: Commands,
    options: Res<ShowcaseOptions>,
    mut trees: TreeAssets,
    mut clip_materials: ResMut<Assets<bevy_terrain_clip::material::ClipmapMaterial>>,
) {
    use layout::*;
    if options.terrain {
        spawn_terrain(&mut commands, &mut trees, &mut clip_materials);
    } else {
        let TreeAssets {
            meshes, materials, ..
        } = &mut trees;
        commands.spawn((
            Name::new("ground"),
            Mesh3d(
                meshes.add(
                    Plane3d::default()
                        .mesh()
                        .size(GROUND_SIZE * 6.0, GROUND_SIZE * 6.0),
                ),
            ),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.6, 0.6, 0.55),
                perceptual_roughness: 0.9,
                ..default()
            })),
        ));
    }
    let TreeAssets {
        meshes, materials, ..
    } = &mut trees;
    commands.spawn((
        Name::new("box"),
        Mesh3d(meshes.add(Cuboid::from_length(BOX_SIZE))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: options.box_color,
            ..default()
        })),
        Transform::from_translation(BOX_CENTER + options.box_offset),
    ));
    // The thesis' olive tree, baked at start-up (about a fifth of a second).
    if let Err(e) = trees.spawn_procedural(
        &mut commands,
        &TreeSpecies::olea(),
        Transform::from_translation(layout::TREE_POSITION),
    ) {
        error!("could not bake the showcase tree: {e}");
    }
    if options.forest {
        spawn_backdrop_forest(&mut commands, &mut trees);
    }
    let mut sun = commands.spawn((
        Name::new("sun"),
        DirectionalLight {
            illuminance: 10_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(SUN_DIRECTION, Vec3::Y),
    ));
    if options.soft_shadows {
        // A sun of 3° (six times the real one), so the penumbrae read at this scale.
        sun.insert(bevy_soft_shadows::ScreenSpaceSoftShadows {
            light_size: 0.05,
            max_occluder_distance: 8.0,
            ..default()
        });
    }
    commands.insert_resource(GlobalAmbientLight {
        brightness: 300.0,
        ..default()
    });
    let mut camera = commands.spawn((
        Name::new("camera"),
        ShowcaseCamera,
        Camera3d::default(),
        Transform::from_translation(CAMERA_POSITION).looking_at(CAMERA_TARGET, Vec3::Y),
    ));
    if !options.msaa {
        camera.insert(Msaa::Off);
    }
}

/// Sixteen managed trees (ash and cedar at reduced leaf counts) in a band 18–50 m behind the
/// scene: the forest LoD manager ranks them and draws them from per-type LoD-cache extractions.
fn spawn_backdrop_forest(commands: &mut Commands, trees: &mut TreeAssets) {
    use bevy_foliage::pruning::bake::BakeSettings;
    use bevy_foliage::pruning::material::leaf_material;
    use bevy_foliage::pruning::spawn::{default_bark_material, default_leaf_material};
    let species = [
        TreeSpecies::fraxinus().with_leaf_count(2000),
        TreeSpecies::cedrus().with_leaf_count(3000),
    ];
    let mut types = Vec::new();
    for s in &species {
        match trees.bake_species(s, &BakeSettings::default()) {
            Ok(t) => types.push(t),
            Err(e) => error!("could not bake the backdrop {}: {e}", s.name),
        }
    }
    if types.is_empty() {
        return;
    }
    let leaves = trees
        .leaf_materials
        .add(leaf_material(default_leaf_material()));
    let bark = trees.materials.add(default_bark_material());
    let root = commands
        .spawn((
            Name::new("backdrop forest"),
            Transform::IDENTITY,
            Visibility::Inherited,
        ))
        .id();
    let mut rng = bevy_foliage::rng::SplitMix64::new(42);
    for i in 0..16 {
        let (baked, bark_mesh) = &types[i % types.len()];
        let x = rng.range(-40.0, 40.0);
        let z = -rng.range(18.0, 50.0);
        commands.entity(root).with_child((
            Name::new(format!("forest tree {i}")),
            bevy_foliage::ForestTree {
                baked: baked.clone(),
                material: leaves.clone(),
            },
            Transform::from_xyz(x, 0.0, z)
                .with_rotation(Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)))
                .with_scale(Vec3::splat(rng.range(0.8, 1.2))),
            children![(Mesh3d(bark_mesh.clone()), MeshMaterial3d(bark.clone()))],
        ));
    }
}

/// A 3 km ground patch textured from a clip stack of procedural aerial imagery whose centre of
/// detail follows the camera.
fn spawn_terrain(
    commands: &mut Commands,
    trees: &mut TreeAssets,
    clip_materials: &mut Assets<bevy_terrain_clip::material::ClipmapMaterial>,
) {
    use bevy::math::DVec2;
    use bevy_terrain_clip::material::flat_patch_mesh;
    use bevy_terrain_clip::source::{ProceduralTileSource, imagery_texel};
    use bevy_terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
    // 10 pyramid levels of 256² tiles: virtual levels 0..18, the finest 2^17 texels of 0.5 m.
    let size_m = 0.5 * 2f64.powi(17);
    let source = std::sync::Arc::new(ProceduralTileSource::new(256, 10, move |l, x, y| {
        imagery_texel(l, x, y, size_m)
    }));
    let mapping = TextureMapping {
        origin_m: DVec2::splat(-size_m / 2.0),
        size_m,
    };
    let mut clip = ClipStackTexture::new(source, 1024, 128, 128, [0.5, 0.5], &mut trees.images);
    clip.mapping = Some(mapping);
    let material = clip.material(
        StandardMaterial {
            perceptual_roughness: 0.95,
            ..default()
        },
        clip_materials,
    );
    commands.spawn((Name::new("terrain clip stack"), clip));
    commands.spawn((
        Name::new("ground (clipmap terrain)"),
        Mesh3d(trees.meshes.add(flat_patch_mesh(
            DVec2::splat(-1500.0),
            3000.0,
            48,
            DVec2::ZERO,
            move |p| mapping.uv_of(p),
        ))),
        MeshMaterial3d(material),
    ));
}
