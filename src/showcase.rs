//! The main example scene (`cargo run --example nature`), shared with the tests so that what a
//! new user sees first is also what CI renders.
//!
//! So far: a ground with relief (seamless terrain patches over a streamed height clip stack, flat
//! around the foreground and rolling into hills under the forest) textured from a streamed clip
//! stack, a box casting a soft shadow under the
//! sun, an olive tree (the thesis' *Olea europaea*, 16,107 leaves) whose leaves are pruned every
//! frame by distance and view direction ([`bevy_foliage::pruning`]), and behind it the edge of a
//! forest of 40 ash, oak and cedar trees drawn by the forest LoD manager, a meadow of grass
//! (blade geometry near, baked volume slices beyond) around them, with
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
    /// Radius (m) around the origin where the ground is flat (`y = 0`): the box, the olive tree
    /// and the camera stand there.
    pub const FLAT_RADIUS: f64 = 30.0;

    /// Height (m) of the ground at world (x, z) with the clipmap terrain on: flat within
    /// [`FLAT_RADIUS`], rising over the next 90 m into rolling hills with crests up to about
    /// 30 m, 100–1,500 m across, on which the backdrop forest stands.
    pub fn ground_height(x: f64, z: f64) -> f64 {
        let r = (x * x + z * z).sqrt();
        let t = ((r - FLAT_RADIUS) / 90.0).clamp(0.0, 1.0);
        let rise = t * t * (3.0 - 2.0 * t);
        let hills = 10.0
            + 12.0 * (x / 170.0 + 0.7).sin() * (z / 230.0).cos()
            + 7.0 * ((x + 0.6 * z) / 95.0).sin()
            + 5.0 * (z / 480.0 - 0.4).sin();
        rise * hills
    }
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
    /// The ground with relief ([`layout::ground_height`]) textured from a clip stack of
    /// procedural aerial imagery streamed tile by tile (a 65 km virtual texture of 0.5 m texels);
    /// off, a flat plane. Tests turn it off: what a frame shows then
    /// depends on how far streaming got, so two renders of the scene could differ.
    pub terrain: bool,
    /// A backdrop forest of [`ForestTree`](bevy_foliage::ForestTree)s behind the scene, drawn by
    /// the forest LoD manager from shared LoD-cache extractions.
    pub forest: bool,
    /// The backdrop's leaf counts as a fraction of the species' full counts (ash 28,645, oak
    /// 41,155, cedar 131,042), in `(0, 1]`. Fewer leaves are larger, so the crowns keep the
    /// coverage of the full counts ([`TreeSpecies::with_leaf_count`]).
    pub forest_leaf_scale: f32,
    /// A second band of 168 backdrop trees 100–425 m away, drawn beyond the pruning's `far` by
    /// their billboard clouds (baked on the GPU at the first run and cached in
    /// `assets/impostors/`), which every backdrop tree gets. Tests turn it off: when a bake
    /// finishes depends on the machine, so two renders of the scene could differ.
    pub impostors: bool,
    /// Screen Space Soft Shadows on the sun: penumbrae harden at contact and widen with the
    /// distance to the blocker on the ground (plain or clipmap-textured), the box and the bark.
    pub soft_shadows: bool,
    /// A 40 m meadow around the box and the tree ([`bevy_foliage::grass`]): blade geometry
    /// near, baked volume slices beyond, thinned by a procedural density map with clearings at
    /// the box and the trunk (slices cached in `assets/grass/`). Tests turn it off: when the
    /// slice bake finishes depends on the machine.
    pub grass: bool,
    /// The camera flies a closed path out over the hills and back every
    /// [`FLIGHT_FRAMES`] frames, so streaming, LoD and shadows change all the time (the
    /// `nature` example's `--soak` run turns it on).
    pub fly: bool,
    /// The trees' leaves lit as volumes ([`bevy_foliage::TreeLightingSettings`]): sky and sun
    /// through the crown, one bounce — the near trees' leaves and the backdrop's billboard
    /// clouds alike. Off: Bevy's PBR lighting.
    pub tree_lighting: bool,
    /// How the trees' bakes estimate the tree lighting's eight bins: traced through the crown
    /// (the default) or §5.6's estimate from the neighbours, ten times cheaper to bake and
    /// further from the truth leaf by leaf
    /// ([`BinEstimate`](bevy_foliage::lighting::traced_bins::BinEstimate)). Render tests that do
    /// not look at the lighting take the cheaper one.
    pub tree_light_bins: bevy_foliage::lighting::traced_bins::BinEstimate,
}

/// Frames of one lap of the camera's flight ([`ShowcaseOptions::fly`]).
pub const FLIGHT_FRAMES: u32 = 2_000;

impl Default for ShowcaseOptions {
    fn default() -> Self {
        Self {
            box_color: Color::srgb(0.8, 0.25, 0.2),
            box_offset: Vec3::ZERO,
            msaa: true,
            forest: true,
            forest_leaf_scale: 0.15,
            impostors: true,
            terrain: true,
            soft_shadows: true,
            grass: true,
            fly: false,
            tree_lighting: true,
            tree_light_bins: default(),
        }
    }
}

/// Adds the suite's plugins and the showcase scene to an app that already has Bevy's default
/// plugins (windowed or headless).
pub fn build_showcase(app: &mut App, options: ShowcaseOptions) {
    app.add_plugins(crate::NaturePlugins)
        .insert_resource(bevy_foliage::grass::GrassSettings {
            slice_cache: Some("assets/grass".into()),
            ..default()
        })
        .insert_resource(bevy_foliage::TreeLightingSettings {
            enabled: options.tree_lighting,
            ..default()
        })
        .insert_resource(options)
        .insert_resource(ClearColor(Color::srgb(0.55, 0.7, 0.9)))
        .add_systems(Startup, spawn_showcase)
        .add_systems(Update, fly_showcase_camera);
}

/// With [`ShowcaseOptions::fly`], moves the showcase camera one frame along its flight: out from
/// the meadow to 400 m and back each lap while circling twice, 15 m above the ground, looking at
/// the meadow — the near trees, the forest's LoD bands, the impostors and new terrain tiles all
/// pass through the view.
fn fly_showcase_camera(
    options: Res<ShowcaseOptions>,
    mut frame: Local<u32>,
    mut cameras: Query<&mut Transform, With<ShowcaseCamera>>,
) {
    if !options.fly {
        return;
    }
    *frame += 1;
    let lap = (*frame % FLIGHT_FRAMES) as f32 / FLIGHT_FRAMES as f32 * std::f32::consts::TAU;
    let radius = 40.0 + 180.0 * (1.0 - lap.cos());
    let angle = 2.0 * lap;
    let (x, z) = (radius * angle.cos(), radius * angle.sin());
    let ground = if options.terrain {
        layout::ground_height(x as f64, z as f64) as f32
    } else {
        0.0
    };
    for mut transform in &mut cameras {
        *transform =
            Transform::from_xyz(x, ground + 15.0, z).looking_at(Vec3::new(0.0, 5.0, 0.0), Vec3::Y);
    }
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
    // The thesis' olive tree, baked at start-up (about three seconds on two cores with the
    // traced bins, a fifth of a second without).
    let bake_settings = bevy_foliage::pruning::bake::BakeSettings {
        bins: options.tree_light_bins,
        ..default()
    };
    match trees.bake_species(&TreeSpecies::olea(), &bake_settings) {
        Ok((baked, bark)) => {
            trees.spawn(
                &mut commands,
                TreeSpecies::olea().name,
                baked,
                bark,
                bevy_foliage::pruning::spawn::default_leaf_material(),
                Transform::from_translation(layout::TREE_POSITION),
            );
        }
        Err(e) => error!("could not bake the showcase tree: {e}"),
    }
    if options.forest {
        spawn_backdrop_forest(
            &mut commands,
            &mut trees,
            options.forest_leaf_scale,
            options.impostors,
            options.terrain,
            &bake_settings,
        );
        if options.impostors {
            // Pruning thins a crown to nothing once it is 4 % of the view tall (about 300 m for
            // these trees): the billboard clouds take over there.
            commands.queue(|world: &mut World| {
                world
                    .resource_mut::<bevy_foliage::FoliagePruningSettings>()
                    .distances = bevy_foliage::LodDistances::ScreenSize {
                    near: 0.6,
                    far: 0.04,
                };
            });
        }
    }
    if options.grass {
        spawn_meadow(&mut commands, &mut trees.images, options.terrain);
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

/// Side of the showcase meadow (m): the flat ground and, with the terrain on, the foot of the
/// hills around it.
const MEADOW: f32 = 64.0;

/// The meadow: the default grass species over [`MEADOW`] metres, cleared at the box and the
/// olive tree's trunk; with the terrain on, lifted onto its relief ([`layout::ground_height`]
/// sampled every 0.5 m).
fn spawn_meadow(commands: &mut Commands, images: &mut Assets<Image>, relief: bool) {
    use bevy_foliage::grass::density::{DensityMap, meadow};
    use bevy_foliage::grass::ground::ambient_occlusion_map;
    use bevy_foliage::grass::{GrassField, GrassSpecies, height_map_image};
    use layout::*;
    let clearings = [
        ([BOX_CENTER.x, BOX_CENTER.z], BOX_SIZE * 0.75),
        ([TREE_POSITION.x, TREE_POSITION.z], 0.6),
    ];
    let density = match meadow(128, [0.0, 0.0], [MEADOW, MEADOW], &clearings, 3) {
        Ok(map) => Some(images.add(bevy_foliage::grass::material::density_map_image(&map))),
        Err(e) => {
            error!("showcase meadow: {e}");
            None
        }
    };
    commands.spawn((
        Name::new("meadow"),
        GrassField {
            size: Vec2::splat(MEADOW),
            species: GrassSpecies::default(),
            density,
            ground: relief.then(|| {
                images.add(height_map_image(
                    Vec2::splat(MEADOW),
                    UVec2::splat(129),
                    |p| ground_height(p.x as f64, p.y as f64) as f32,
                ))
            }),
            // The terrain's own ambient occlusion, computed once (§4.2.6).
            ambient_occlusion: relief.then(|| {
                let half = Vec2::splat(MEADOW / 2.0);
                let texels = UVec2::splat(64);
                let ao = ambient_occlusion_map(
                    |p| ground_height(p.x as f64, p.y as f64) as f32,
                    -half,
                    2.0 * half,
                    texels,
                    12.0,
                );
                let map = DensityMap::new(texels.x, texels.y, ao, (-half).to_array(), [MEADOW; 2])
                    .expect("a finite map");
                images.add(bevy_foliage::grass::material::density_map_image(&map))
            }),
        },
    ));
}

/// A backdrop forest behind the scene: 40 managed trees of three species (ash, oak, cedar) in a
/// band 14–90 m deep, on a jittered grid so crowns stand apart: the forest LoD manager ranks them
/// and draws them from per-type LoD-cache extractions.
fn spawn_backdrop_forest(
    commands: &mut Commands,
    trees: &mut TreeAssets,
    leaf_scale: f32,
    impostors: bool,
    relief: bool,
    bake_settings: &bevy_foliage::pruning::bake::BakeSettings,
) {
    use bevy_foliage::pruning::material::leaf_material;
    use bevy_foliage::pruning::spawn::{default_bark_material, default_leaf_material};
    let scale = if leaf_scale.is_finite() {
        leaf_scale.clamp(0.001, 1.0)
    } else {
        0.15
    };
    let reduced = |s: TreeSpecies| {
        let n = ((s.leaf_count as f32 * scale).round() as usize).max(50);
        s.with_leaf_count(n)
    };
    // Species and the colour of their leaves.
    let species = [
        (
            reduced(TreeSpecies::fraxinus()),
            Color::srgb(0.3, 0.45, 0.18),
        ),
        (
            reduced(TreeSpecies::quercus()),
            Color::srgb(0.26, 0.38, 0.16),
        ),
        (reduced(TreeSpecies::cedrus()), Color::srgb(0.16, 0.3, 0.2)),
    ];
    let mut types = Vec::new();
    for (s, colour) in &species {
        match trees.bake_species(s, bake_settings) {
            Ok((baked, bark)) => {
                let look = StandardMaterial {
                    base_color: *colour,
                    ..default_leaf_material()
                };
                let leaves = trees.leaf_materials.add(leaf_material(look.clone()));
                let bake = impostors.then(|| {
                    use bevy_foliage::impostor::bake::{ImpostorBakeRequest, ImpostorBakeSettings};
                    use bevy_foliage::impostor::texture::{BakeSurface, ImpostorSource};
                    let surface = |m: &StandardMaterial, cutoff| {
                        let c = m.base_color.to_linear();
                        BakeSurface {
                            base_color: Vec4::new(c.red, c.green, c.blue, 1.0),
                            texture: None,
                            alpha_cutoff: cutoff,
                        }
                    };
                    let tree = bevy_foliage::pruning::procedural::generate(s);
                    let mut source = ImpostorSource::default();
                    source.push_leaves(&tree.leaves, surface(&look, 0.5));
                    source.push_bark(&tree.bark, surface(&default_bark_material(), 0.0));
                    let path = format!(
                        "impostors/showcase-{}-{:04}.bbcloud",
                        s.name,
                        (scale * 1000.0).round() as u32
                    );
                    commands
                        .spawn(ImpostorBakeRequest {
                            label: s.name.to_string(),
                            source: std::sync::Arc::new(source),
                            settings: ImpostorBakeSettings {
                                bins: bake_settings.bins,
                                ..default()
                            },
                            save_to: Some(
                                bevy::asset::io::file::FileAssetReader::get_base_path()
                                    .join("assets")
                                    .join(path),
                            ),
                        })
                        .id()
                });
                types.push((baked, bark, leaves, bake));
            }
            Err(e) => error!("could not bake the backdrop {}: {e}", s.name),
        }
    }
    if types.is_empty() {
        return;
    }
    let bark = trees.materials.add(default_bark_material());
    let root = commands
        .spawn((
            Name::new("backdrop forest"),
            Transform::IDENTITY,
            Visibility::Inherited,
        ))
        .id();
    let mut rng = bevy_foliage::rng::SplitMix64::new(42);
    let mut place = |i: usize, x: f32, z: f32, rng: &mut bevy_foliage::rng::SplitMix64| {
        let (baked, bark_mesh, leaves, bake) = &types[rng.below(types.len() as u32) as usize];
        let mut tree = commands.spawn((
            Name::new(format!("forest tree {i}")),
            bevy_foliage::ForestTree {
                baked: baked.clone(),
                material: leaves.clone(),
            },
            // On the hills when the ground has relief.
            Transform::from_xyz(
                x,
                if relief {
                    layout::ground_height(x as f64, z as f64) as f32
                } else {
                    0.0
                },
                z,
            )
            .with_rotation(Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)))
            .with_scale(Vec3::splat(rng.range(0.8, 1.2))),
            ChildOf(root),
            children![(
                Mesh3d(bark_mesh.clone()),
                MeshMaterial3d(bark.clone()),
                bevy_foliage::impostor::systems::TreeBark
            )],
        ));
        if let Some(bake) = bake {
            tree.insert(bevy_foliage::impostor::systems::ImpostorFromBake(*bake));
        }
    };
    let mut i = 0;
    for row in 0..5 {
        for column in 0..8 {
            let x = -56.0 + column as f32 * 16.0 + rng.range(-5.0, 5.0) + (row % 2) as f32 * 8.0;
            let z = -14.0 - row as f32 * 16.0 - rng.range(0.0, 8.0);
            place(i, x, z, &mut rng);
            i += 1;
        }
    }
    if impostors {
        // The distant band: drawn by billboard clouds beyond about 300 m.
        for row in 0..14 {
            for column in 0..12 {
                let x = -200.0 + column as f32 * 34.0 + rng.range(-10.0, 10.0);
                let z = -100.0 - row as f32 * 25.0 - rng.range(0.0, 12.0);
                place(i, x, z, &mut rng);
                i += 1;
            }
        }
    }
}

/// The ground: seamless terrain patches ([`TerrainGeometry`](bevy_terrain_clip::terrain::TerrainGeometry))
/// displaced by a height clip stack of [`layout::ground_height`] and textured from a clip stack
/// of procedural aerial imagery, both streamed around the camera.
fn spawn_terrain(
    commands: &mut Commands,
    trees: &mut TreeAssets,
    clip_materials: &mut Assets<bevy_terrain_clip::material::ClipmapMaterial>,
) {
    use bevy::math::DVec2;
    use bevy_terrain_clip::source::{ProceduralTileSource, imagery_texel};
    use bevy_terrain_clip::stack_gpu::{ClipStackTexture, TextureMapping};
    use bevy_terrain_clip::terrain::{TerrainGeometry, TerrainPrecision};
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
    // The heights at each level's texel centres, over the same square.
    let heights = std::sync::Arc::new(ProceduralTileSource::heights(256, 10, move |l, x, y| {
        let texel = size_m / 2f64.powi(l as i32);
        layout::ground_height(
            mapping.origin_m.x + (x as f64 + 0.5) * texel,
            mapping.origin_m.y + (y as f64 + 0.5) * texel,
        ) as f32
    }));
    let mut heights = ClipStackTexture::heights(
        heights,
        &bevy_terrain_clip::ClipmapSettings::default(),
        [0.5, 0.5],
        &mut trees.images,
    );
    heights.mapping = Some(mapping);
    let heights = commands
        .spawn((Name::new("terrain height stack"), heights))
        .id();
    commands.spawn((
        Name::new("ground (clipmap terrain with relief)"),
        TerrainGeometry {
            // Vertices 3 px apart where a patch edge reaches the paper's ε = 1: the hills' outline
            // is a few metres off the full mesh's at most, for (3 / 1.1)² ≈ 7× fewer triangles
            // than the default.
            precision: TerrainPrecision::VertexPixels(3.0),
            ..TerrainGeometry::new(heights, material)
        },
    ));
}
