//! Terrain with relief, the main-world side: each frame the seamless patches of
//! [`crate::geometry`] are selected for the scene camera and drawn as instanced unit tile meshes
//! (one entity per tile; Bevy batches the tiles sharing a mesh and the material into one
//! instanced draw), displaced in the vertex stage by a height clip stack
//! ([`ClipStackTexture::heights`]) and coloured by a colour stack's material.
//!
//! ```no_run
//! # use bevy::prelude::*;
//! # use bevy_terrain_clip::{terrain::TerrainGeometry, stack_gpu::{ClipStackTexture, TextureMapping}};
//! # fn setup(mut commands: Commands, heights: ClipStackTexture, material: Handle<bevy_terrain_clip::material::ClipmapMaterial>) {
//! // `heights` is a height stack with a mapping; `material` a colour stack's material.
//! let heights = commands.spawn(heights).id();
//! commands.spawn(TerrainGeometry::new(heights, material));
//! # }
//! ```

use crate::RenderOrigin;
use crate::geometry::patch::{PatchGrid, PatchView, Selection, select_patches};
use crate::geometry::tile::unit_tile;
use crate::material::{ClipmapMaterial, MAX_LAYERS, ReliefParams};
use crate::stack_gpu::ClipStackTexture;
use bevy::asset::RenderAssetUsages;
use bevy::camera::primitives::Frustum;
use bevy::camera::visibility::NoFrustumCulling;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::math::Vec4;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;

/// Draws a terrain with relief over a height clip stack. Its tiles are children of its entity
/// (despawning it despawns them); the heights are in world space, so the entity's transform stays
/// the identity.
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component)]
#[require(Transform, Visibility)]
pub struct TerrainGeometry {
    /// The entity holding the height stack ([`ClipStackTexture::heights`]); its
    /// [`mapping`](ClipStackTexture::mapping) places the terrain square in the world.
    pub heights: Entity,
    /// The material colouring the ground (a colour stack's
    /// [`material`](ClipStackTexture::material)); its relief bindings are filled in from the
    /// height stack.
    pub material: Handle<ClipmapMaterial>,
    /// Segments along a patch edge at the high resolution (rounded up to a power of two, clamped
    /// to 4..=1024); the low resolution is half of it.
    pub resolution: u32,
    /// Depth of the patch hierarchy; `None`: as deep as the height pyramid, so the finest
    /// patches' vertices are one finest height texel apart (capped at the 2^24 lattice).
    pub max_level: Option<u8>,
    /// How fine the mesh is (ρ of eq. 1, set from the screen by default).
    pub precision: TerrainPrecision,
    /// Hierarchical frustum culling of the patches.
    pub culling: bool,
    /// The lowest and highest terrain heights (m): patch bounds and edge distances. `None`
    /// (the default): those of the heights streamed so far
    /// ([`ClipStackTexture::height_range`]), which bound what the vertex stage reads.
    pub height_range: Option<(f32, f32)>,
}

impl TerrainGeometry {
    /// A terrain over the height stack on `heights`, coloured by `material`, with defaults:
    /// 16 segments an edge, vertices at most [`DEFAULT_VERTEX_PIXELS`] apart on screen, culling
    /// on, the height range of the heights streamed.
    pub fn new(heights: Entity, material: Handle<ClipmapMaterial>) -> Self {
        Self {
            heights,
            material,
            resolution: 16,
            max_level: None,
            precision: TerrainPrecision::VertexPixels(DEFAULT_VERTEX_PIXELS),
            culling: true,
            height_range: None,
        }
    }
}

/// How fine the terrain mesh is.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub enum TerrainPrecision {
    /// ρ of eq. 1 set each frame from the camera so that where a patch edge reaches ε = 1 its
    /// vertices (at the high resolution) are this many pixels apart on screen: the mesh keeps
    /// its on-screen density at any resolution and field of view. (Orthographic views, where
    /// eq. 1's distance does not set the size on screen, use ρ = 6.)
    VertexPixels(f32),
    /// ρ of eq. 1 as given (`ε = ρ·l/d`; the paper's precision factor): larger gives finer
    /// meshes.
    Rho(f32),
}

/// The default on-screen vertex spacing (px). Measured against the full-resolution mesh in the
/// same run (`tests/terrain_relief.rs`, rough relief of 10 m bumps over 1 m heights): the
/// silhouette stays within a pixel of it; twice the spacing (a quarter of the triangles) moves
/// it by up to 3 px.
pub const DEFAULT_VERTEX_PIXELS: f32 = 1.1;

impl TerrainPrecision {
    /// ρ for a perspective view `pixels_per_radian` pixels per unit of tangent (the viewport's
    /// height over `2·tan(fov/2)`; `None` for orthographic) and patches of `resolution`
    /// segments an edge.
    pub fn rho(self, pixels_per_radian: Option<f32>, resolution: u32) -> f32 {
        match self {
            Self::Rho(rho) => rho.max(1e-3),
            Self::VertexPixels(px) => match pixels_per_radian {
                // ε = ρ·l/d = 1 where the edge spans l/d·P pixels, its vertices l/d·P/r apart.
                Some(p) => (p / (resolution as f32 * px.max(0.05))).max(1e-3),
                None => 6.0,
            },
        }
    }
}

/// The patches drawn this frame, and what the selection did.
#[derive(Component, Clone, Debug, Default)]
pub struct TerrainPatches {
    /// The hierarchy they come from.
    pub grid: Option<PatchGrid>,
    /// The view they were selected for.
    pub view: Option<PatchView>,
    /// The patches and counters.
    pub selection: Selection,
    /// Triangles drawn.
    pub triangles: usize,
    /// CPU time of the selection (µs).
    pub selection_us: f64,
}

/// A tile entity of a terrain (its [`TerrainTiles`] owns it).
#[derive(Component, Clone, Copy, Debug)]
pub struct TerrainTile;

/// The tile entities of a terrain, reused frame to frame.
#[derive(Component, Clone, Debug, Default)]
pub struct TerrainTiles(pub Vec<Entity>);

/// A unit tile mesh's key: (patch resolution, edge, segments on the edge, on the half-diagonal
/// at its start, at its end).
type UnitTileKey = (u32, usize, u32, u32, u32);

/// The unit tile meshes, with their triangle counts.
#[derive(Resource, Default)]
struct UnitTileMeshes(HashMap<UnitTileKey, (Handle<Mesh>, usize)>);

/// Patches drawn.
pub const PATCHES: DiagnosticPath = DiagnosticPath::const_new("terrain/patches");
/// Triangles drawn.
pub const TRIANGLES: DiagnosticPath = DiagnosticPath::const_new("terrain/triangles");
/// CPU time of the patch selection (µs).
pub const SELECTION_US: DiagnosticPath = DiagnosticPath::const_new("terrain/selection_us");

/// Lattice steps between the anchors a terrain's tiles may be placed relative to: the anchor
/// stays put while the camera moves within a few thousand steps (the material is not rewritten
/// every frame), and a vertex's offset from it stays short enough to be exact to a fraction of a
/// millimetre in f32.
pub const ANCHOR_CELL: u32 = 4096;

/// The hierarchy over a height stack's texture, in render space, its positions taken relative
/// to the lattice point nearest `eye` (render space) on a grid of [`ANCHOR_CELL`] steps.
pub fn patch_grid(
    geometry: &TerrainGeometry,
    heights: &ClipStackTexture,
    origin: &RenderOrigin,
    eye: Vec3,
) -> Option<PatchGrid> {
    let mapping = heights.mapping?;
    // Absurd resolutions are clamped (a patch edge of 4 to 1,024 segments), never a panic.
    let r = geometry.resolution.clamp(4, 1024).next_power_of_two();
    let finest = heights
        .stack
        .layers
        .last()
        .map_or(heights.stack.base_level, |l| l.level);
    let lattice_bits = 24 - r.trailing_zeros();
    let max_level = geometry
        .max_level
        .map_or(finest.saturating_sub(r.trailing_zeros()), u32::from)
        .min(lattice_bits) as u8;
    let grid = PatchGrid::new(
        origin.render_xz(mapping.origin_m),
        mapping.size_m as f32,
        max_level,
        r,
    )
    .ok()?;
    // In f64: the eye's lattice point, snapped to the anchor grid, and its render position.
    let side = grid.lattice_side() as f64;
    let step = mapping.size_m / side;
    let eye_world = if eye.is_finite() {
        origin.world_xz(eye)
    } else {
        mapping.origin_m
    };
    let cell = ANCHOR_CELL as f64;
    let anchor = ((eye_world - mapping.origin_m) / step / cell)
        .round()
        .clamp(
            bevy::math::DVec2::ZERO,
            bevy::math::DVec2::splat(side / cell).floor(),
        )
        * cell;
    let anchor = [anchor.x as u32, anchor.y as u32];
    let at = mapping.origin_m + bevy::math::DVec2::new(anchor[0] as f64, anchor[1] as f64) * step;
    Some(grid.anchored(anchor, origin.render_xz(at)))
}

/// The relief parameters of a height stack drawn on `grid` (the one its tiles were placed on),
/// with the colour texture's place.
pub fn relief_params(
    heights: &ClipStackTexture,
    color: Option<&ClipStackTexture>,
    grid: &PatchGrid,
    origin: &RenderOrigin,
) -> ReliefParams {
    let mapping = heights.mapping.unwrap_or(crate::stack_gpu::TextureMapping {
        origin_m: default(),
        size_m: 1.0,
    });
    let color_mapping = color.and_then(|c| c.mapping).unwrap_or(mapping);
    let mut coverage = [Vec4::ZERO; MAX_LAYERS];
    for (i, c) in heights
        .stack
        .coverage()
        .into_iter()
        .take(MAX_LAYERS)
        .enumerate()
    {
        if let Some((min, max)) = c {
            coverage[i] = Vec4::new(min[0] as f32, min[1] as f32, max[0] as f32, max[1] as f32);
        }
    }
    ReliefParams {
        coverage,
        base_level: heights.stack.base_level,
        layer_count: heights.stack.layers.len().min(MAX_LAYERS) as u32,
        clip_size: heights.stack.clip_size as f32,
        lattice_side: grid.lattice_side() as f32,
        anchor: Vec2::new(grid.anchor[0] as f32, grid.anchor[1] as f32),
        anchor_render: grid.origin,
        lattice_step: (mapping.size_m / grid.lattice_side() as f64) as f32,
        height_offset: -origin.0.y as f32,
        color_origin: origin.render_xz(color_mapping.origin_m),
        color_size: color_mapping.size_m as f32,
    }
}

/// Fills in each terrain material's height stack and keeps its coverage current.
fn update_relief(
    terrains: Query<(&TerrainGeometry, &TerrainPatches)>,
    stacks: Query<&ClipStackTexture>,
    origin: Res<RenderOrigin>,
    mut materials: ResMut<Assets<ClipmapMaterial>>,
) {
    for (geometry, patches) in &terrains {
        let (Ok(heights), Some(grid)) = (stacks.get(geometry.heights), patches.grid.as_ref())
        else {
            continue;
        };
        let color = stacks
            .iter()
            .find(|c| c.materials().contains(&geometry.material));
        let relief = relief_params(heights, color, grid, &origin);
        let Some(material) = materials.get(&geometry.material) else {
            continue;
        };
        let ext = &material.extension;
        if ext.relief != relief
            || ext.height_layers.as_ref() != Some(&heights.layers)
            || ext.height_base.as_ref() != Some(&heights.base)
        {
            let ext = &mut materials.get_mut(&geometry.material).unwrap().extension;
            ext.relief = relief;
            ext.height_layers = Some(heights.layers.clone());
            ext.height_base = Some(heights.base.clone());
        }
    }
}

fn unit_mesh(r: u32, e: usize, n: u32, d0: u32, d1: u32) -> (Mesh, usize) {
    let tile = unit_tile(r, e, n, d0, d1);
    let positions: Vec<[f32; 3]> = tile
        .vertices
        .iter()
        .map(|p| [p[0] as f32, 0.0, p[1] as f32])
        .collect();
    let count = positions.len();
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    // The vertex stage computes both from the heights and the world position; the attributes
    // make Bevy's pipeline pass them on.
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; count]);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, vec![[0.0f32, 0.0]; count]);
    mesh.insert_indices(Indices::U32(
        tile.triangles.iter().flatten().copied().collect(),
    ));
    (mesh, tile.triangles.len())
}

/// Selects the patches for the scene camera and places the tile entities.
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn draw_terrain(
    mut commands: Commands,
    cameras: Query<
        (&Camera, &GlobalTransform, &Frustum, Option<&Projection>),
        (With<Camera3d>, Without<TerrainTile>),
    >,
    mut terrains: Query<(
        Entity,
        &TerrainGeometry,
        Option<&mut TerrainPatches>,
        Option<&mut TerrainTiles>,
    )>,
    stacks: Query<&ClipStackTexture>,
    mut tiles: Query<
        (
            &mut Mesh3d,
            &mut MeshMaterial3d<ClipmapMaterial>,
            &mut Transform,
            &mut GlobalTransform,
            &mut Visibility,
        ),
        With<TerrainTile>,
    >,
    mut meshes: ResMut<Assets<Mesh>>,
    mut unit_meshes: ResMut<UnitTileMeshes>,
    origin: Res<RenderOrigin>,
    mut diagnostics: Diagnostics,
    mut warned: Local<bevy::platform::collections::HashSet<Entity>>,
) {
    let Some((camera_settings, camera, frustum, projection)) = cameras
        .iter()
        .filter(|(c, ..)| c.is_active)
        .min_by_key(|(c, ..)| c.order)
    else {
        return;
    };
    for (entity, geometry, patches, owned) in &mut terrains {
        let height_stack = stacks.get(geometry.heights).ok();
        let Some(grid) =
            height_stack.and_then(|h| patch_grid(geometry, h, &origin, camera.translation()))
        else {
            if warned.insert(entity) {
                warn!(
                    "TerrainGeometry on {entity}: {:?} holds no height stack with a mapping \
                     (ClipStackTexture::heights, then set its mapping); nothing is drawn",
                    geometry.heights
                );
            }
            continue;
        };
        let pixels_per_radian = match projection {
            Some(Projection::Perspective(p)) => camera_settings
                .physical_viewport_size()
                .map(|size| size.y as f32 / (2.0 * (p.fov * 0.5).tan())),
            _ => None,
        };
        let view = PatchView {
            eye: camera.translation(),
            precision: geometry.precision.rho(pixels_per_radian, grid.r_high),
            frustum: geometry
                .culling
                .then(|| frustum.half_spaces.map(|h| h.normal_d())),
            heights: {
                let (a, b) = geometry
                    .height_range
                    .or_else(|| height_stack.and_then(|h| h.height_range()))
                    .unwrap_or((0.0, 0.0));
                (a.min(b), a.max(b))
            },
        };
        let started = std::time::Instant::now();
        let selection = select_patches(&grid, &view);
        let selection_us = started.elapsed().as_secs_f64() * 1e6;
        // One tile per patch edge, on its unit mesh.
        let mut placed = Vec::with_capacity(selection.patches.len() * 4);
        let mut triangles = 0;
        for patch in &selection.patches {
            // In lattice steps from the anchor (integers: exact); the vertex stage maps them to
            // render space (`relief.wgsl`).
            let corner = grid.relative(patch.id.corner(&grid));
            let unit = (patch.id.side(&grid) / grid.r_high) as f32;
            for e in 0..4 {
                let key = (
                    grid.r_high,
                    e,
                    patch.edges[e],
                    patch.diagonal(e),
                    patch.diagonal(e + 1),
                );
                let (handle, count) = unit_meshes
                    .0
                    .entry(key)
                    .or_insert_with(|| {
                        let (mesh, count) = unit_mesh(key.0, key.1, key.2, key.3, key.4);
                        (meshes.add(mesh), count)
                    })
                    .clone();
                triangles += count;
                placed.push((
                    handle,
                    Transform::from_xyz(corner.x, 0.0, corner.y)
                        .with_scale(Vec3::new(unit, 1.0, unit)),
                ));
            }
        }
        let mut owned_tiles = owned.map(|t| t.0.clone()).unwrap_or_default();
        while owned_tiles.len() < placed.len() {
            owned_tiles.push(
                commands
                    .spawn((
                        ChildOf(entity),
                        TerrainTile,
                        Mesh3d(placed[owned_tiles.len()].0.clone()),
                        MeshMaterial3d(geometry.material.clone()),
                        placed[owned_tiles.len()].1,
                        // Set here too: this runs after transform propagation.
                        GlobalTransform::from(placed[owned_tiles.len()].1),
                        Visibility::Inherited,
                        // The patches are culled by the selection; Bevy's culling would use the
                        // flat mesh's bounds.
                        NoFrustumCulling,
                    ))
                    .id(),
            );
        }
        for (i, &tile) in owned_tiles.iter().enumerate() {
            let Ok((mut mesh, mut material, mut transform, mut global, mut visibility)) =
                tiles.get_mut(tile)
            else {
                continue;
            };
            match placed.get(i) {
                Some((handle, place)) => {
                    if mesh.0 != *handle {
                        mesh.0 = handle.clone();
                    }
                    if material.0 != geometry.material {
                        material.0 = geometry.material.clone();
                    }
                    if *transform != *place {
                        // Set both: this runs after transform propagation.
                        *transform = *place;
                        *global = GlobalTransform::from(*place);
                    }
                    if *visibility != Visibility::Inherited {
                        *visibility = Visibility::Inherited;
                    }
                }
                None => {
                    if *visibility != Visibility::Hidden {
                        *visibility = Visibility::Hidden;
                    }
                }
            }
        }
        diagnostics.add_measurement(&PATCHES, || selection.patches.len() as f64);
        diagnostics.add_measurement(&TRIANGLES, || triangles as f64);
        diagnostics.add_measurement(&SELECTION_US, || selection_us);
        let record = TerrainPatches {
            grid: Some(grid),
            view: Some(view),
            selection,
            triangles,
            selection_us,
        };
        match patches {
            Some(mut p) => *p = record,
            None => {
                commands.entity(entity).insert(record);
            }
        }
        commands.entity(entity).insert(TerrainTiles(owned_tiles));
    }
}

/// Registers the terrain geometry (with the render plugins).
pub(crate) fn build(app: &mut App) {
    for path in [PATCHES, TRIANGLES, SELECTION_US] {
        app.register_diagnostic(Diagnostic::new(path).with_max_history_length(1));
    }
    app.register_type::<TerrainGeometry>()
        .init_resource::<UnitTileMeshes>()
        .add_systems(
            PostUpdate,
            (draw_terrain, update_relief)
                .chain()
                .after(bevy::camera::visibility::VisibilitySystems::UpdateFrusta)
                .before(bevy::camera::visibility::VisibilitySystems::CheckVisibility),
        );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::ProceduralTileSource;
    use crate::stack_gpu::TextureMapping;

    /// A flat height stack of 6 levels of 64² tiles (finest level 11) mapped onto a square
    /// `size_m` wide whose corner is at (−100, 50).
    fn heights_over(size_m: f64, images: &mut Assets<Image>) -> ClipStackTexture {
        let mut heights = ClipStackTexture::heights(
            std::sync::Arc::new(ProceduralTileSource::heights(64, 6, |_, _, _| 0.0)),
            &default(),
            [0.5, 0.5],
            images,
        );
        heights.mapping = Some(TextureMapping {
            origin_m: bevy::math::DVec2::new(-100.0, 50.0),
            size_m,
        });
        heights
    }

    /// The hierarchy follows the height pyramid's depth, and absurd resolutions are clamped
    /// rather than overflowing the lattice.
    #[test]
    fn the_patch_grid_follows_the_heights_and_clamps_absurd_settings() {
        let mut images = Assets::<Image>::default();
        let mut heights = heights_over(2048.0, &mut images);
        let geometry = TerrainGeometry::new(Entity::PLACEHOLDER, Handle::default());
        let here = RenderOrigin::default();
        let mapping = heights.mapping.take();
        assert_eq!(
            patch_grid(&geometry, &heights, &here, Vec3::ZERO),
            None,
            "no mapping, no grid"
        );
        heights.mapping = mapping;
        // 11 virtual levels below 64² tiles × 6: finest level 11; 16 segments: level 7 patches.
        let grid = patch_grid(&geometry, &heights, &here, Vec3::ZERO).unwrap();
        assert_eq!((grid.max_level, grid.r_high), (7, 16));
        assert_eq!(grid.origin, Vec2::new(-100.0, 50.0));
        assert_eq!(grid.anchor, [0, 0], "a lattice smaller than an anchor cell");
        for resolution in [0, 3, 1 << 25, u32::MAX] {
            let g = patch_grid(
                &TerrainGeometry {
                    resolution,
                    ..geometry.clone()
                },
                &heights,
                &here,
                Vec3::ZERO,
            )
            .unwrap();
            assert!((4..=1024).contains(&g.r_high) && g.r_high.is_power_of_two());
        }
    }

    /// Far from the world's origin the grid is anchored at the lattice point of the anchor grid
    /// nearest the eye, whose render position is computed in f64: lattice points near the eye
    /// land where they are, to a millimetre, 10^5 m out.
    #[test]
    fn the_patch_grid_is_anchored_near_the_eye_in_render_space() {
        let mut images = Assets::<Image>::default();
        // 2^18 lattice steps of 1 m.
        let heights = heights_over(262_144.0, &mut images);
        let geometry = TerrainGeometry {
            max_level: Some(14),
            ..TerrainGeometry::new(Entity::PLACEHOLDER, Handle::default())
        };
        let origin = RenderOrigin(bevy::math::DVec3::new(100_000.25, 0.0, 200_000.0));
        let eye = Vec3::new(3.0, 10.0, -2.0);
        let grid = patch_grid(&geometry, &heights, &origin, eye).unwrap();
        assert_eq!(grid.lattice_side(), 1 << 18);
        // The eye's lattice point (100,103.25, 199,948) rounds to cell (24, 49) of 4,096 steps.
        assert_eq!(grid.anchor, [24 * 4096, 49 * 4096]);
        assert_eq!(grid.origin, Vec2::new(-1796.25, 754.0));
        let near = grid.world([100_103, 199_948]);
        assert!(
            (near - Vec2::new(2.75, -2.0)).abs().max_element() < 1e-3,
            "{near}"
        );
    }
}
