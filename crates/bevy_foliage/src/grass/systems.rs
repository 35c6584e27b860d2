//! The main-world grass systems: each [`GrassField`] gets its base patch, mesh, density map and
//! material once (and again when it changes); every frame the cell quadtree is walked from the
//! field's camera (§4.2.7.2) and the cells near enough for blade geometry are kept as entities —
//! one per cell, the patch mesh placed by a transform that mirrors it (eq. 4.9) — spawned and
//! despawned as the camera moves, so Bevy batches them as instances of one mesh and material.

use super::bake::{GrassSliceBakeRequest, GrassSliceBakeResult, source_hash};
use super::density::DensityMap;
use super::field::{GrassField, GrassFieldError, GrassSettings};
use super::ground::GroundGrid;
use super::ground_map::{
    GrassWindMap, GroundWindUniform, HeightMap, flat_ground_image, ground_image,
};
use super::lighting::ShadowMask;
use super::material::{
    GrassBladeExtension, GrassBladeMaterial, GrassBladeParams, blade_material, density_image,
    density_map_from_image, shadow_mask_image,
};
use super::mesh::{horizontal_slice_mesh, patch_mesh, slice_block_mesh};
use super::patch::{BasePatch, Mirror};
use super::quadtree::{CellDraw, CellGrid, CellNode, CellView, GroundBounds, select_cells};
use super::slice_material::{GrassSliceMaterial, GrassSliceParams, slice_image};
use super::slices::SliceTextures;
use super::transition::TransitionDistances;
use bevy::camera::primitives::{Aabb, Frustum, MeshAabb};
use bevy::camera::visibility::NoAutoAabb;
use bevy::diagnostic::{DiagnosticPath, Diagnostics};
use bevy::light::NotShadowCaster;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use std::time::Instant;

/// Blades drawn as geometry this frame (the patch's blades times the cells drawn; the density
/// test discards some of them on the GPU).
pub const GEOMETRY_BLADES: DiagnosticPath = DiagnosticPath::const_new("grass/geometry_blades");
/// Cells drawn with blade geometry this frame.
pub const GEOMETRY_CELLS: DiagnosticPath = DiagnosticPath::const_new("grass/geometry_cells");
/// Blocks of cells drawn with their vertical and horizontal slices this frame.
pub const SLICE_BLOCKS: DiagnosticPath = DiagnosticPath::const_new("grass/slice_blocks");
/// Nodes drawn as horizontal slice alone this frame: macro-cells, and blocks where the vertical
/// slices' weight is zero throughout.
pub const MACRO_CELLS: DiagnosticPath = DiagnosticPath::const_new("grass/macro_cells");
/// Milliseconds the cell walk and the entity updates took this frame (CPU).
pub const SELECT_MS: DiagnosticPath = DiagnosticPath::const_new("grass/select_ms");

/// Picks the camera a grass field is walked from (else: the active 3D camera of lowest order).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct GrassCamera;

/// What a field was built into.
#[derive(Component)]
pub struct GrassFieldState {
    /// The field's species, with unusable values replaced.
    pub species: super::field::GrassSpecies,
    /// The base patch.
    pub patch: BasePatch,
    /// The cell grid over the field.
    pub grid: CellGrid,
    /// The field's rectangle (min corner x, z; size).
    pub rect: Vec4,
    /// The density map in use.
    pub density: DensityMap,
    /// The density image the map was read from (none: full density).
    density_source: Option<AssetId<Image>>,
    /// The density map as the shaders read it.
    density_image: Handle<Image>,
    /// The ground under the field (`None`: flat), and the height image it was read from.
    pub ground: Option<std::sync::Arc<GroundGrid>>,
    ground_source: Option<AssetId<Image>>,
    /// The ground's samples as the shaders read them.
    ground_image: Handle<Image>,
    /// The terrain's ambient occlusion as the shaders read it, and the image it was read from.
    occlusion_image: Handle<Image>,
    occlusion_source: Option<AssetId<Image>>,
    /// The patch mesh's bounds (m, in a cell's frame, on flat ground).
    mesh_bounds: (Vec3, Vec3),
    /// The blade shadow mask's image and (slab height, radius, 0, 0), once the slices are
    /// baked (the mask is read from them).
    shadow_mask: (Handle<Image>, Vec4),
    mesh: Handle<Mesh>,
    material: Handle<GrassBladeMaterial>,
    cells: HashMap<(u32, u32), Entity>,
    /// Whether the cells in `cells` cast into shadow maps ([`GrassSettings::cast_shadow_maps`]
    /// when they were last updated).
    cells_cast_shadow_maps: bool,
    /// Cells drawn as blade geometry in the last frame.
    pub geometry_cells: u32,
    /// The slice bake's request entity (a child of the field).
    slice_bake: Entity,
    /// The slices, once baked.
    slices: Option<FieldSlices>,
    /// Slice blocks and horizontal-only nodes (macro-cells and blocks) drawn in the last frame.
    pub slice_nodes: (u32, u32),
    /// Why the slices could not be baked (the field then draws blade geometry only).
    pub slice_error: Option<String>,
}

impl GrassFieldState {
    /// Whether the field's slices are baked and drawn, or have failed for good.
    pub fn slices_settled(&self) -> bool {
        self.slices.is_some() || self.slice_error.is_some()
    }
}

/// Whether every grass field in `world` has its slices (or has given up on them): for headless
/// runs that should not start measuring, or take a screenshot, before the slices are there.
pub fn grass_ready(world: &mut World) -> bool {
    world
        .query::<&GrassFieldState>()
        .iter(world)
        .all(GrassFieldState::slices_settled)
}

/// A field's baked slices and what draws them.
struct FieldSlices {
    textures: SliceTextures,
    material: Handle<GrassSliceMaterial>,
    block_mesh: Handle<Mesh>,
    /// The block mesh cut at every cell edge, for ground with relief.
    block_mesh_per_cell: Handle<Mesh>,
    quad_mesh: Handle<Mesh>,
    /// The grid of slice blocks (`SLICE_BLOCK` cells a side).
    blocks: CellGrid,
    nodes: HashMap<(CellNode, bool), Entity>,
}

/// Cells a side of a block of slice quads: `2^3`.
const SLICE_BLOCK_LEVELS: u8 = 3;

/// Marks a cell entity of blade geometry (a child of its field).
#[derive(Component, Clone, Copy, Debug)]
pub struct GrassCell {
    /// Cell column.
    pub x: u32,
    /// Cell row (along z).
    pub z: u32,
}

/// A field's ground for the cell walk: its samples, or flat at the field's height.
struct FieldGround<'a>(Option<&'a GroundGrid>);

impl GroundBounds for FieldGround<'_> {
    fn height_range(&self, grid: &CellGrid, node: CellNode) -> (f32, f32) {
        self.0.map_or((0.0, 0.0), |g| g.height_range(grid, node))
    }
    fn is_flat(&self, grid: &CellGrid, node: CellNode) -> bool {
        self.0.is_none_or(|g| g.is_flat(grid, node))
    }
}

impl FieldGround<'_> {
    fn height_at(&self, xz: Vec2) -> f32 {
        self.0.map_or(0.0, |g| g.height_at(xz))
    }
}

/// `bounds` (a mesh's, in its entity's frame) raised over ground from `low` to `high` and widened
/// by the wind's `reach`, as the entity's fixed `Aabb`.
fn lifted_aabb(bounds: (Vec3, Vec3), low: f32, high: f32, reach: f32) -> Aabb {
    let reach = Vec3::new(reach, 0.0, reach);
    Aabb::from_min_max(
        bounds.0 + Vec3::Y * low - reach,
        bounds.1 + Vec3::Y * high + reach,
    )
}

/// Most cells a side of a field's grid (2^16: 32 km of 0.5 m patches).
const MAX_LEVELS: u8 = 16;

/// The grid over a field of `size` centred on `centre` (x, z) with patches of side `cell`.
pub fn field_grid(centre: Vec2, size: Vec2, cell: f32) -> CellGrid {
    let across = (size.max_element() / cell).ceil().max(1.0);
    let levels = (across.log2().ceil() as u8).min(MAX_LEVELS);
    CellGrid {
        origin: centre - size / 2.0,
        cell,
        levels,
    }
}

/// Where a cell of corner `corner` (x, z) and `side` showing `mirror` puts the base patch mesh:
/// [`Mirror::place`] as a transform, `p ↦ corner + (x ? side − p.x : p.x, y, z ? side − p.z :
/// p.z)` — a negative scale on each mirrored axis.
pub fn cell_transform(corner: Vec2, side: f32, mirror: Mirror) -> Transform {
    let sign = |m: bool| if m { -1.0 } else { 1.0 };
    Transform::from_translation(Vec3::new(
        corner.x + if mirror.x { side } else { 0.0 },
        0.0,
        corner.y + if mirror.z { side } else { 0.0 },
    ))
    .with_scale(Vec3::new(sign(mirror.x), 1.0, sign(mirror.z)))
}

/// Builds (or rebuilds) a field's patch, mesh, grid and material when it is added or changed.
pub fn prepare_grass_fields(
    mut commands: Commands,
    mut fields: Query<
        (
            Entity,
            &GrassField,
            &GlobalTransform,
            Option<&mut GrassFieldState>,
        ),
        Changed<GrassField>,
    >,
    settings: Res<GrassSettings>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut images: ResMut<Assets<Image>>,
    mut materials: ResMut<Assets<GrassBladeMaterial>>,
    wind_map: Option<Res<GrassWindMap>>,
) {
    let Some(wind_map) = wind_map else {
        return;
    };
    for (entity, field, transform, state) in &mut fields {
        let (species, fixes) = field.species.sanitized();
        for fix in fixes {
            warn!("grass field {entity}: {fix}");
        }
        let size = if field.size.is_finite() && field.size.min_element() > 0.0 {
            field.size
        } else {
            warn!(
                "grass field {entity}: size {} must be positive: using 1 m",
                field.size
            );
            Vec2::ONE
        };
        let centre = transform.translation().xz();
        let min = centre - size / 2.0;
        let rect = Vec4::new(min.x, min.y, size.x, size.y);
        let patch = BasePatch::generate(&species.patch);
        let grid = field_grid(centre, size, species.patch.size);
        let density = DensityMap::uniform(1.0, min.to_array(), size.to_array())
            .expect("a positive finite rectangle");
        let mesh = patch_mesh(&patch, species.patch.width, species.patch.segments);
        let mesh_bounds = mesh.compute_aabb().map_or((Vec3::ZERO, Vec3::ZERO), |b| {
            (b.min().into(), b.max().into())
        });
        let mesh = meshes.add(mesh);
        let ground_image = images.add(flat_ground_image());
        let density_gpu = images.add(density_image(&density));
        let occlusion_image = images.add(density_image(
            &DensityMap::uniform(1.0, min.to_array(), size.to_array())
                .expect("a positive finite rectangle"),
        ));
        let shadow_mask = images.add(shadow_mask_image(&ShadowMask::clear()));
        let ground_wind = GroundWindUniform::new(
            &grid,
            None,
            transform.translation().y,
            &settings.wind,
            species.patch.height.1,
            0.0,
        );
        let material = materials.add(blade_material(
            &species,
            GrassBladeExtension {
                params: GrassBladeParams::new(&settings, &species, rect, Vec3::ZERO, ground_wind),
                density: density_gpu.clone(),
                ground: ground_image.clone(),
                wind: wind_map.image.clone(),
                shadow_mask: shadow_mask.clone(),
                terrain_occlusion: occlusion_image.clone(),
                soft_visibility: None,
            },
        ));
        // A rebuilt field starts with no cells: the old ones go.
        if let Some(old) = state {
            for &cell in old.cells.values() {
                commands.entity(cell).despawn();
            }
            if let Some(slices) = &old.slices {
                for &node in slices.nodes.values() {
                    commands.entity(node).despawn();
                }
            }
            commands.entity(old.slice_bake).despawn();
        }
        let per_axis = settings.slice_per_axis;
        let resolution = settings.slice_resolution;
        let slice_bake = commands
            .spawn((
                GrassSliceBakeRequest {
                    label: format!("grass field {entity}"),
                    species: species.clone(),
                    per_axis,
                    resolution,
                    save_to: settings.slice_cache.as_ref().map(|dir| {
                        dir.join(format!(
                            "{:016x}.grassslices",
                            source_hash(&species, per_axis, resolution)
                        ))
                    }),
                },
                ChildOf(entity),
            ))
            .id();
        commands
            .entity(entity)
            .remove::<GrassFieldError>()
            .insert(GrassFieldState {
                species: species.clone(),
                patch,
                grid,
                rect,
                density,
                density_source: None,
                density_image: density_gpu,
                ground: None,
                ground_source: None,
                ground_image,
                occlusion_image,
                occlusion_source: None,
                mesh_bounds,
                shadow_mask: (shadow_mask, Vec4::ZERO),
                mesh,
                material,
                cells: HashMap::default(),
                cells_cast_shadow_maps: true,
                geometry_cells: 0,
                slice_bake,
                slices: None,
                slice_nodes: (0, 0),
                slice_error: None,
            });
    }
}

/// The map image `handle` names, once it has loaded and if it is not the one already read
/// (`source`, which then names it).
fn newly_loaded<'a>(
    handle: Option<&Handle<Image>>,
    source: &mut Option<AssetId<Image>>,
    images: &'a Assets<Image>,
) -> Option<&'a Image> {
    let handle = handle?;
    if *source == Some(handle.id()) {
        return None;
    }
    let image = images.get(handle)?;
    *source = Some(handle.id());
    Some(image)
}

/// Reads each field's density map once its image has loaded; a map that cannot be read is an
/// error on the entity (and in the log), and the field keeps full density.
pub fn resolve_density_maps(
    mut commands: Commands,
    mut fields: Query<(Entity, &GrassField, &mut GrassFieldState)>,
    mut images: ResMut<Assets<Image>>,
) {
    for (entity, field, mut state) in &mut fields {
        let (min, size) = ([state.rect.x, state.rect.y], [state.rect.z, state.rect.w]);
        let state = &mut *state;
        let Some(image) = newly_loaded(field.density.as_ref(), &mut state.density_source, &images)
        else {
            continue;
        };
        match density_map_from_image(image, min, size) {
            Ok(map) => {
                // Written into the image the materials already hold (a new handle would leave
                // them without a bind group for a frame).
                if let Some(mut target) = images.get_mut(&state.density_image) {
                    *target = density_image(&map);
                }
                state.density = map;
            }
            Err(e) => {
                let why = format!("grass field {entity}: density map not used: {e}");
                error!("{why}; the field grows at full density");
                commands.entity(entity).insert(GrassFieldError(why));
            }
        }
    }
}

/// Reads each field's terrain ambient-occlusion map once its image has loaded, into the image its
/// materials already hold; a map that cannot be read is an error on the entity (and in the log),
/// and the grass stays unoccluded.
pub fn resolve_occlusion_maps(
    mut commands: Commands,
    mut fields: Query<(Entity, &GrassField, &mut GrassFieldState)>,
    mut images: ResMut<Assets<Image>>,
) {
    for (entity, field, mut state) in &mut fields {
        let (min, size) = ([state.rect.x, state.rect.y], [state.rect.z, state.rect.w]);
        let state = &mut *state;
        let Some(image) = newly_loaded(
            field.ambient_occlusion.as_ref(),
            &mut state.occlusion_source,
            &images,
        ) else {
            continue;
        };
        match density_map_from_image(image, min, size) {
            Ok(map) => {
                if let Some(mut target) = images.get_mut(&state.occlusion_image) {
                    *target = density_image(&map);
                }
            }
            Err(e) => {
                let why = format!("grass field {entity}: ambient occlusion map not used: {e}");
                error!("{why}; the grass stays unoccluded");
                commands.entity(entity).insert(GrassFieldError(why));
            }
        }
    }
}

/// Reads each field's height map once its image has loaded, samples it at the cell corners and
/// hands the samples to the field's materials; a map that cannot be read is an error on the
/// entity (and in the log), and the field stays flat.
pub fn resolve_ground_maps(
    mut commands: Commands,
    mut fields: Query<(Entity, &GrassField, &mut GrassFieldState)>,
    mut images: ResMut<Assets<Image>>,
) {
    for (entity, field, mut state) in &mut fields {
        let state = &mut *state;
        let Some(image) = newly_loaded(field.ground.as_ref(), &mut state.ground_source, &images)
        else {
            continue;
        };
        let (min, size) = (state.rect.xy(), state.rect.zw());
        match HeightMap::from_image(image, min, size) {
            Ok(map) => {
                let (ground, _) = GroundGrid::sample(&state.grid, |p| map.height_at(p));
                // Written into the image the materials already hold (a new handle would leave
                // them without a bind group for a frame).
                if let Some(mut image) = images.get_mut(&state.ground_image) {
                    *image = ground_image(&ground);
                }
                state.ground = Some(std::sync::Arc::new(ground));
                // Cells and slices spawned on the flat ground go, to come back with the
                // ground's bounds.
                for (_, cell) in state.cells.drain() {
                    commands.entity(cell).despawn();
                }
                if let Some(slices) = state.slices.as_mut() {
                    for (_, node) in slices.nodes.drain() {
                        commands.entity(node).despawn();
                    }
                }
            }
            Err(e) => {
                let why = format!("grass field {entity}: height map not used: {e}");
                error!("{why}; the field stays flat");
                commands.entity(entity).insert(GrassFieldError(why));
            }
        }
    }
}

/// Takes each field's finished slice bake into a slice material; a failed bake is logged and the
/// field draws blade geometry only.
#[allow(clippy::too_many_arguments)]
pub fn attach_slice_bakes(
    mut commands: Commands,
    mut fields: Query<(Entity, &GlobalTransform, &mut GrassFieldState)>,
    results: Query<&GrassSliceBakeResult>,
    settings: Res<GrassSettings>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut images: ResMut<Assets<Image>>,
    mut materials: ResMut<Assets<GrassSliceMaterial>>,
    blade_materials: Res<Assets<GrassBladeMaterial>>,
    wind_map: Option<Res<GrassWindMap>>,
) {
    let Some(wind_map) = wind_map else {
        return;
    };
    for (entity, transform, mut state) in &mut fields {
        if state.slices.is_some() {
            continue;
        }
        let Ok(result) = results.get(state.slice_bake) else {
            continue;
        };
        let bake = match &result.0 {
            Ok(bake) => bake.clone(),
            Err(e) => {
                error!("grass field {entity}: no slices ({e}); blade geometry only");
                commands
                    .entity(state.slice_bake)
                    .remove::<GrassSliceBakeResult>();
                continue;
            }
        };
        let Some(density) = blade_materials
            .get(&state.material)
            .map(|m| m.extension.density.clone())
        else {
            continue;
        };
        let textures = bake.textures.clone();
        let species = state.species.clone();
        // The blade shadow mask, read from the slices (§4.2.6).
        // Written into the image the materials already hold: a new handle would leave the
        // blades without a bind group for the frame its image takes to upload.
        let mask = textures.shadow_mask();
        let mask_image = state.shadow_mask.0.clone();
        match images.get_mut(&mask_image) {
            Some(mut image) => *image = shadow_mask_image(&mask),
            None => continue,
        }
        state.shadow_mask.1 = Vec4::new(mask.slab_height, mask.radius, 0.0, 0.0);
        let material = materials.add(GrassSliceMaterial {
            params: GrassSliceParams::new(
                &settings,
                &species,
                &textures,
                &state.grid,
                transform.translation().y,
                state.rect,
                Vec3::ZERO,
                GroundWindUniform::default(),
            ),
            slices: images.add(slice_image(&textures, settings.slice_mip_alpha)),
            density,
            ground: state.ground_image.clone(),
            wind: wind_map.image.clone(),
            shadow_mask: mask_image,
            soft_visibility: None,
            terrain_occlusion: state.occlusion_image.clone(),
        });
        let block_cells = 1u32 << SLICE_BLOCK_LEVELS.min(state.grid.levels);
        let blocks = CellGrid {
            origin: state.grid.origin,
            cell: state.grid.cell * block_cells as f32,
            levels: state.grid.levels - SLICE_BLOCK_LEVELS.min(state.grid.levels),
        };
        state.slices = Some(FieldSlices {
            block_mesh: meshes.add(slice_block_mesh(&textures.layout, block_cells, false)),
            block_mesh_per_cell: meshes.add(slice_block_mesh(&textures.layout, block_cells, true)),
            quad_mesh: meshes.add(horizontal_slice_mesh(
                1.0,
                1 << super::ground::MACRO_FACET_LEVELS,
            )),
            textures,
            material,
            blocks,
            nodes: HashMap::default(),
        });
    }
}

/// Whether the vertical slices can show anywhere over `node` of the slice blocks, seen from
/// `eye` (the field's frame): its box (ground to `height` above it) spans distances `near` to
/// `far`; over horizontal ground `|N·V̂|` is at least the eye's height over the box's top over
/// `far`, and anywhere else (relief: the slope turns the normal) it may reach zero.
fn vertical_slices_may_show(
    transitions: &TransitionDistances,
    blocks: &CellGrid,
    ground: &FieldGround,
    node: CellNode,
    eye: Vec3,
    height: f32,
) -> bool {
    let (corner, side) = blocks.rect(node);
    let (low, high) = ground.height_range(blocks, node);
    let (min, max) = (
        Vec3::new(corner.x, low, corner.y),
        Vec3::new(corner.x + side, high + height, corner.y + side),
    );
    let near = eye.clamp(min, max).distance(eye);
    let far = Vec3::new(
        (eye.x - min.x).abs().max((eye.x - max.x).abs()),
        (eye.y - min.y).abs().max((eye.y - max.y).abs()),
        (eye.z - min.z).abs().max((eye.z - max.z).abs()),
    )
    .length();
    let min_n_dot_v = if ground.0.is_none() && eye.y > max.y && far > 0.0 {
        (eye.y - max.y) / far
    } else {
        0.0
    };
    transitions.vertical_may_show(near, far, min_n_dot_v)
}

/// The camera fields are walked from: one marked [`GrassCamera`], else the active 3D camera of
/// lowest order.
fn field_camera<'a>(
    cameras: &'a Query<(&Camera, &GlobalTransform, &Frustum, Has<GrassCamera>), With<Camera3d>>,
) -> Option<(&'a GlobalTransform, &'a Frustum)> {
    cameras
        .iter()
        .filter(|(camera, ..)| camera.is_active)
        .min_by_key(|(camera, _, _, marked)| (!*marked, camera.order))
        .map(|(_, transform, frustum, _)| (transform, frustum))
}

/// Walks every field's cells from its camera and keeps one entity per cell drawn as blade
/// geometry.
#[allow(clippy::too_many_arguments)]
pub fn update_grass_cells(
    mut commands: Commands,
    mut fields: Query<(Entity, &GrassField, &GlobalTransform, &mut GrassFieldState)>,
    cameras: Query<(&Camera, &GlobalTransform, &Frustum, Has<GrassCamera>), With<Camera3d>>,
    settings: Res<GrassSettings>,
    mut materials: ResMut<Assets<GrassBladeMaterial>>,
    mut slice_materials: ResMut<Assets<GrassSliceMaterial>>,
    wind_map: Option<Res<GrassWindMap>>,
    time: Res<Time>,
    mut diagnostics: Diagnostics,
) {
    let started = Instant::now();
    let wind_reach = wind_map
        .as_ref()
        .map_or(0.0, |w| GroundWindUniform::reach(&settings.wind, &w.map));
    let (mut blocks_drawn, mut macro_drawn) = (0u32, 0u32);
    let Some((camera, frustum)) = field_camera(&cameras) else {
        return;
    };
    let eye = camera.translation();
    let mut blades = 0u64;
    let mut cells_drawn = 0u32;
    for (entity, field, transform, mut state) in &mut fields {
        let ground_y = transform.translation().y;
        let ground_wind = GroundWindUniform::new(
            &state.grid,
            state.ground.as_deref(),
            ground_y,
            &settings.wind,
            state.species.patch.height.1,
            time.elapsed_secs_wrapped(),
        );
        // The walk in the field's frame (ground at y = 0).
        let view = CellView {
            eye: eye - Vec3::Y * ground_y,
            frustum: Some(frustum.half_spaces.map(|h| {
                let nd = h.normal_d();
                Vec4::new(nd.x, nd.y, nd.z, nd.w + nd.y * ground_y)
            })),
            max_distance: settings.max_distance,
            macro_from: settings.transitions.max_btf,
            split_factor: settings.split_factor,
            grass_height: field.species.patch.height.1,
        };
        let reach = settings.transitions.max_geom;
        let mut wanted: Vec<(u32, u32)> = Vec::new();
        let ground_grid = state.ground.clone();
        let ground = FieldGround(ground_grid.as_deref());
        if settings.geometry {
            let selection = select_cells(&state.grid, &ground, &view);
            let (min, max) = (state.rect.xy(), state.rect.xy() + state.rect.zw());
            for (node, _) in selection.drawn {
                if node.level != state.grid.levels {
                    continue;
                }
                let (corner, side) = state.grid.rect(node);
                // Cells wholly outside the field, or beyond the geometry's reach, draw no blade.
                if corner.x >= max.x
                    || corner.y >= max.y
                    || corner.x + side <= min.x
                    || corner.y + side <= min.y
                {
                    continue;
                }
                let nearest = Vec2::new(
                    view.eye.x.clamp(corner.x, corner.x + side),
                    view.eye.z.clamp(corner.y, corner.y + side),
                );
                let distance = (nearest - view.eye.xz())
                    .length()
                    .hypot(view.eye.y - ground.height_at(nearest));
                if distance <= reach {
                    wanted.push((node.x, node.z));
                }
            }
        }
        // The material follows the camera (the shadow pass measures from it too).
        let mask_shape = if settings.shadow_mask {
            state.shadow_mask.1
        } else {
            Vec4::ZERO
        };
        if let Some(material) = materials.get(&state.material) {
            let params = GrassBladeParams {
                mask_shape,
                ..GrassBladeParams::new(
                    &settings,
                    &state.species,
                    material.extension.params.density_rect,
                    eye,
                    ground_wind,
                )
            };
            if (params != material.extension.params
                || material.extension.shadow_mask != state.shadow_mask.0)
                && let Some(mut material) = materials.get_mut(&state.material)
            {
                material.extension.params = params;
                material.extension.shadow_mask = state.shadow_mask.0.clone();
            }
        }
        let state = &mut *state;
        let wanted_set: bevy::platform::collections::HashSet<(u32, u32)> =
            wanted.iter().copied().collect();
        state.cells.retain(|key, cell| {
            let keep = wanted_set.contains(key);
            if !keep {
                commands.entity(*cell).despawn();
            }
            keep
        });
        // The setting changed: the cells already drawn follow it.
        if state.cells_cast_shadow_maps != settings.cast_shadow_maps {
            for &cell in state.cells.values() {
                if settings.cast_shadow_maps {
                    commands.entity(cell).remove::<NotShadowCaster>();
                } else {
                    commands.entity(cell).insert(NotShadowCaster);
                }
            }
            state.cells_cast_shadow_maps = settings.cast_shadow_maps;
        }
        let field_origin = transform.translation();
        for &(x, z) in &wanted {
            if state.cells.contains_key(&(x, z)) {
                continue;
            }
            let (corner, side) = state.grid.rect(CellNode {
                level: state.grid.levels,
                x,
                z,
            });
            let mirror = Mirror::of_cell(x as i64, z as i64, state.species.patch.seed);
            let mut local = cell_transform(corner, side, mirror);
            // The mesh is lifted and swayed in the vertex stage: its bounds are set here.
            let (low, high) = ground.height_range(
                &state.grid,
                CellNode {
                    level: state.grid.levels,
                    x,
                    z,
                },
            );
            let aabb = lifted_aabb(state.mesh_bounds, low, high, wind_reach);
            local.translation -= Vec3::new(field_origin.x, 0.0, field_origin.z);
            let cell = commands
                .spawn((
                    Name::new("grass cell"),
                    GrassCell { x, z },
                    Mesh3d(state.mesh.clone()),
                    MeshMaterial3d(state.material.clone()),
                    aabb,
                    NoAutoAabb,
                    local,
                    // Placed now, not one frame late after the next propagation.
                    transform.mul_transform(local),
                    ChildOf(entity),
                ))
                .id();
            if !settings.cast_shadow_maps {
                commands.entity(cell).insert(NotShadowCaster);
            }
            state.cells.insert((x, z), cell);
        }
        state.geometry_cells = wanted.len() as u32;
        cells_drawn += wanted.len() as u32;
        blades += wanted.len() as u64 * state.patch.blades.len() as u64;

        // The slices: blocks of cells where the vertical slices may show, macro-cells of
        // horizontal slice beyond (§4.2.7.2).
        let density = materials
            .get(&state.material)
            .map(|m| m.extension.density.clone());
        let Some(slices) = state.slices.as_mut() else {
            continue;
        };
        if let (Some(material), Some(density)) = (slice_materials.get(&slices.material), density) {
            let params = GrassSliceParams::new(
                &settings,
                &state.species,
                &slices.textures,
                &state.grid,
                ground_y,
                state.rect,
                eye,
                ground_wind,
            );
            let params = GrassSliceParams {
                mask_shape,
                ..params
            };
            if params != material.params
                || material.density != density
                || material.ground != state.ground_image
            {
                let mut material = slice_materials.get_mut(&slices.material).unwrap();
                material.params = params;
                material.density = density;
                material.ground = state.ground_image.clone();
            }
        }
        let mut wanted_nodes: Vec<(CellNode, bool)> = Vec::new();
        if settings.slices {
            let selection = select_cells(&slices.blocks, &ground, &view);
            let (min, max) = (state.rect.xy(), state.rect.xy() + state.rect.zw());
            for (node, draw) in selection.drawn {
                let (corner, side) = slices.blocks.rect(node);
                if corner.x >= max.x
                    || corner.y >= max.y
                    || corner.x + side <= min.x
                    || corner.y + side <= min.y
                {
                    continue;
                }
                // Wholly nearer than min_geom: the slices' weights are zero there.
                let far = Vec2::new(
                    (view.eye.x - corner.x)
                        .abs()
                        .max((view.eye.x - corner.x - side).abs()),
                    (view.eye.z - corner.y)
                        .abs()
                        .max((view.eye.z - corner.y - side).abs()),
                )
                .length()
                .hypot(view.eye.y - ground.height_range(&slices.blocks, node).1);
                if far < settings.transitions.min_geom {
                    continue;
                }
                // A block where the vertical slices' weight is zero throughout draws its
                // horizontal slice alone, as a macro-cell does.
                let horizontal_only = draw == CellDraw::MacroCell
                    || !vertical_slices_may_show(
                        &settings.transitions,
                        &slices.blocks,
                        &ground,
                        node,
                        view.eye,
                        slices.textures.layout.height,
                    );
                wanted_nodes.push((node, horizontal_only));
            }
        }
        let wanted_set: bevy::platform::collections::HashSet<(CellNode, bool)> =
            wanted_nodes.iter().copied().collect();
        slices.nodes.retain(|key, node| {
            let keep = wanted_set.contains(key);
            if !keep {
                commands.entity(*node).despawn();
            }
            keep
        });
        for &(node, is_macro) in &wanted_nodes {
            if slices.nodes.contains_key(&(node, is_macro)) {
                continue;
            }
            let (corner, side) = slices.blocks.rect(node);
            let local = Transform::from_translation(Vec3::new(
                corner.x - field_origin.x,
                0.0,
                corner.y - field_origin.z,
            ))
            .with_scale(if is_macro {
                Vec3::new(side, 1.0, side)
            } else {
                Vec3::ONE
            });
            let mesh = if is_macro {
                slices.quad_mesh.clone()
            } else {
                if ground_grid.is_some() {
                    slices.block_mesh_per_cell.clone()
                } else {
                    slices.block_mesh.clone()
                }
            };
            let (low, high) = ground.height_range(&slices.blocks, node);
            let aabb = if is_macro {
                // The unit quad, scaled to the node by its transform.
                lifted_aabb(
                    (Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0)),
                    low,
                    high + 0.05,
                    0.0,
                )
            } else {
                let height = slices.textures.layout.height;
                lifted_aabb(
                    (Vec3::ZERO, Vec3::new(side, height, side)),
                    low,
                    high,
                    wind_reach,
                )
            };
            let id = commands
                .spawn((
                    Name::new(if is_macro {
                        "grass macro-cell"
                    } else {
                        "grass slice block"
                    }),
                    Mesh3d(mesh),
                    MeshMaterial3d(slices.material.clone()),
                    aabb,
                    NoAutoAabb,
                    local,
                    transform.mul_transform(local),
                    NotShadowCaster,
                    ChildOf(entity),
                ))
                .id();
            slices.nodes.insert((node, is_macro), id);
        }
        let macros = wanted_nodes.iter().filter(|(_, m)| *m).count() as u32;
        state.slice_nodes = (wanted_nodes.len() as u32 - macros, macros);
        blocks_drawn += state.slice_nodes.0;
        macro_drawn += macros;
    }
    diagnostics.add_measurement(&SLICE_BLOCKS, || blocks_drawn as f64);
    diagnostics.add_measurement(&MACRO_CELLS, || macro_drawn as f64);
    diagnostics.add_measurement(&GEOMETRY_BLADES, || blades as f64);
    diagnostics.add_measurement(&GEOMETRY_CELLS, || cells_drawn as f64);
    diagnostics.add_measurement(&SELECT_MS, || started.elapsed().as_secs_f64() * 1e3);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_covers_the_field_in_a_power_of_two_of_cells() {
        let grid = field_grid(Vec2::new(10.0, -4.0), Vec2::new(6.0, 3.0), 0.5);
        // 12 cells across → 16 = 2^4.
        assert_eq!(grid.levels, 4);
        assert_eq!(grid.origin, Vec2::new(7.0, -5.5));
        let grid = field_grid(Vec2::ZERO, Vec2::splat(0.2), 0.5);
        assert_eq!(grid.levels, 0);
    }
}
