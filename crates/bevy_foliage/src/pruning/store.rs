//! The GPU buffers every pruned tree shares, owned by the main world: the baked data of every
//! tree type concatenated (static), and per-instance regions of the output index buffer,
//! per-cell offsets and indirect draw arguments (written by the GPU each frame). The pruning pass
//! ([`super::render`]) and the leaf material ([`super::material`]) bind the same buffers, so the
//! vertex stage reads exactly what the compute pass wrote.

use super::bake::BakedFoliage;
use super::components::{FoliageShadowLight, PrunedFoliage, PruningParams};
use crate::lighting::bounce_ring::{BounceRing, NO_RING, RING_NODES};
use crate::lighting::gathered_bounce::{BounceRatios, STORED_RATIOS};
use crate::lighting::hotspot::HOTSPOT_NODES;
use crate::settings::FoliagePruningSettings;
use bevy::asset::{AssetId, RenderAssetUsages};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::storage::ShaderBuffer;

/// One extraction's place in the shared buffers: its instance record (and draw arguments), its
/// region of kept indices and its region of per-cell counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Region {
    /// Instance record index.
    pub slot: u32,
    /// First output index.
    pub output_base: u32,
    /// First per-cell entry.
    pub cell_offsets_base: u32,
}

/// Where a pruned tree's data lives in the shared buffers this frame (written by the plugin).
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct FoliageSlot {
    /// Tree type layout.
    pub ty: TypeSlot,
    /// The camera's selection; its slot is the entity's `MeshTag`.
    pub camera: Region,
    /// The shadow light's selection, while there is a shadow light ([`super::selection`]).
    pub light: Option<Region>,
}

/// Offsets of one tree type in the shared buffers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TypeSlot {
    /// First entry in `cell_first_leaf`.
    pub cell_base: u32,
    /// Cells.
    pub cell_count: u32,
    /// Viewpoints.
    pub view_count: u32,
    /// First visibility entry.
    pub visibility_base: u32,
    /// First `leaf_index_start` entry.
    pub leaf_base: u32,
    /// First stored index.
    pub index_base: u32,
    /// Added to every written index (types share one vertex buffer).
    pub vertex_base: u32,
    /// Indices with every leaf kept.
    pub full_index_count: u32,
    /// The type's first leaf in the `leaf_light` buffer.
    pub light_base: u32,
    /// Every leaf is a canonical quad ([`BakedFoliage::quad_leaves`]): drawn with quad slot
    /// meshes.
    pub quads: bool,
    /// The crown's extinction τ per unit of model space ([`BakedFoliage::extinction`]), as `f32`
    /// bits: the tree lighting's s_max = −ln(a)/τ.
    pub extinction_bits: u32,
    /// The crown's bounding sphere in model space (centre xyz, radius), as `f32` bits: where
    /// the sun's light from outside enters the crown.
    pub crown_sphere_bits: [u32; 4],
    /// The crown's hotspot ([`BakedFoliage::hotspot`]) packed as the leaf shaders read it.
    pub hotspot: [u32; crate::lighting::hotspot::HOTSPOT_WORDS],
}

/// Set in a pruned tree's `MeshTag` when it is drawn with a quad slot mesh; the low bits are the
/// instance slot.
pub const QUAD_TAG_BIT: u32 = 1 << 31;

/// The `MeshTag` of a tree drawing instance `slot` of a type laid out as `ty`.
pub fn mesh_tag(slot: u32, ty: &TypeSlot) -> u32 {
    if ty.quads { slot | QUAD_TAG_BIT } else { slot }
}

/// Words per packed leaf vertex in the `leaf_vertices` buffer:
/// `position.xyz, cell, offset.xyz, leaf radius, normal.xyz, leaf, uv.xy, leaf uv centre.xy`,
/// where `leaf` indexes the `leaf_light` buffer (every type's leaves, in turn).
pub const LEAF_VERTEX_WORDS: usize = 16;

/// Words per leaf in the `leaf_light` buffer: its eight attenuations (`BakedFoliage::leaf_light`),
/// then its eight seen-part gains (`BakedFoliage::leaf_seen`), two `u16` a word, direction `2k`
/// in the low half of word `k` of each four; then its 28 bounce ratios
/// (`BakedFoliage::leaf_bounce`), four bytes a word, low byte first; the sun height of its
/// type's ring of re-gathered ratios (`f32` bits; [`NO_RING`] for none,
/// [`crate::lighting::bounce_ring`]); its 28 ring ratios, as the bounce ratios; the first four
/// nodes of the ring's own hotspot on the sun ([`BounceRing::sunlit_hotspot`], a byte each,
/// node `k` at byte `k`; 0 where the ring has none or no shares, the bake's then); its 14
/// sunlit shares on the ring (bytes, node `k` at byte `k`,
/// [`crate::lighting::sunlit_share::quantize_share`]), then a byte 1 where the ring has them
/// (0: none, the bake's blend) and one of padding; the shares' slopes across the leaf
/// ([`BounceRing::sunlit_slopes`], signed bytes, node `k`'s component `c` at byte `3k + c`;
/// 0 where the ring has none), two bytes of padding and the ring's hotspot's last four
/// nodes; last, the leaf's open map ([`LeafOpenMap::words`](crate::lighting::open_map::LeafOpenMap::words): its residual gains, then its
/// cells and axes; all 0 for none, `BakedFoliage::leaf_open`).
pub const LEAF_LIGHT_WORDS: usize = 48;

// `BakedFoliage::gpu_bytes` counts these sizes.
const _: () = assert!(LEAF_VERTEX_WORDS == 16 && LEAF_LIGHT_WORDS == 48);

/// Appends the [`LEAF_LIGHT_WORDS`] words of each of `tree`'s leaves to `out`, with `ring` (its
/// sun height and per leaf its ratios and sunlit shares) as the type's ring; `None`, or a ring
/// for another number of leaves: no ring (and a ring's shares for another number of leaves:
/// no shares; their slopes for another number of leaves: none, the shares alone).
pub fn push_leaf_light(tree: &BakedFoliage, ring: Option<&BounceRing>, out: &mut Vec<u32>) {
    let ring = ring.filter(|r| r.leaves.len() == tree.leaf_count() && r.sun_height.abs() <= 1.0);
    let shares = ring
        .map(|r| r.sunlit.as_slice())
        .filter(|s| s.len() == tree.leaf_count());
    let slopes = ring
        .map(|r| r.sunlit_slopes.as_slice())
        .filter(|s| shares.is_some() && s.len() == tree.leaf_count());
    let no_ratios = BounceRatios::default().quantized();
    let open_maps = tree.leaf_open_maps();
    let ratio_words = |r: &[u8; STORED_RATIOS]| {
        r.chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect::<Vec<u32>>()
    };
    for leaf in 0..tree.leaf_count() {
        // The leaves' attenuations (a bake without them, none stored, lets all light through)
        // and seen-part gains.
        let a = tree.leaf_light.get(leaf).copied().unwrap_or([u16::MAX; 8]);
        out.extend((0..4).map(|k| a[2 * k] as u32 | (a[2 * k + 1] as u32) << 16));
        // A bake without gains: the leaf's mean light as it is.
        let g = tree
            .leaf_seen
            .get(leaf)
            .copied()
            .unwrap_or([crate::lighting::seen_part::quantize_gain(1.0); 8]);
        out.extend((0..4).map(|k| g[2 * k] as u32 | (g[2 * k + 1] as u32) << 16));
        // A bake without ratios: eq. 5.24 as it is.
        out.extend(ratio_words(
            tree.leaf_bounce.get(leaf).unwrap_or(&no_ratios),
        ));
        match ring {
            Some(ring) => {
                out.push(ring.sun_height.to_bits());
                out.extend(ratio_words(&ring.leaves[leaf]));
            }
            None => {
                out.push(NO_RING.to_bits());
                out.extend(ratio_words(&no_ratios));
            }
        }
        // The ring's own hotspot on its shares, where it has one.
        let spot = match (ring, shares) {
            (Some(ring), Some(_)) if ring.sun_hotspot().is_some() => ring.sunlit_hotspot,
            _ => [0; HOTSPOT_NODES],
        };
        out.push(u32::from_le_bytes([spot[0], spot[1], spot[2], spot[3]]));
        let mut sunlit = [0u8; 16];
        if let Some(shares) = shares {
            sunlit[..RING_NODES].copy_from_slice(&shares[leaf]);
            sunlit[RING_NODES] = 1;
        }
        out.extend(
            sunlit
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
        let mut sloped = [0u8; 48];
        if let Some(slopes) = slopes {
            for (k, node) in slopes[leaf].iter().enumerate() {
                for (c, &q) in node.iter().enumerate() {
                    sloped[3 * k + c] = q as u8;
                }
            }
        }
        sloped[44..].copy_from_slice(&spot[4..]);
        out.extend(
            sloped
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
        // The open map (none: all 0, the sky takes the eight gains).
        out.extend(open_maps.get(leaf).copied().unwrap_or_default().words());
    }
}

/// Words per instance record (must match `Instance` in `prune.wgsl` and `leaf_pulling.wgsl`).
pub const INSTANCE_WORDS: usize = 28;

/// Handles of the shared pruning buffers.
#[derive(Clone, Debug, Default)]
pub struct StoreBuffers {
    /// Per type, `cells + 1` leaf starts (per-type relative).
    pub cell_first_leaf: Handle<ShaderBuffer>,
    /// Per type, `cells × views` visibilities, one `u32` each.
    pub visibility: Handle<ShaderBuffer>,
    /// Per type, `leaves + 1` index starts.
    pub leaf_index_start: Handle<ShaderBuffer>,
    /// Per type, stored leaf indices.
    pub stored_indices: Handle<ShaderBuffer>,
    /// Per type, packed leaf vertices.
    pub leaf_vertices: Handle<ShaderBuffer>,
    /// Per type, per stored leaf: the light its neighbours let through in the tree lighting's
    /// eight directions ([`LEAF_LIGHT_WORDS`] words a leaf).
    pub leaf_light: Handle<ShaderBuffer>,
    /// Per-instance records (uploaded each frame).
    pub instances: Handle<ShaderBuffer>,
    /// Kept indices, one region per instance (GPU written).
    pub output: Handle<ShaderBuffer>,
    /// Per instance and cell: kept index count and output offset (GPU written).
    pub cell_offsets: Handle<ShaderBuffer>,
    /// Indexed-indirect draw arguments, five words per instance (GPU written).
    pub draws: Handle<ShaderBuffer>,
}

/// The GPU buffers shared by every pruned tree, owned by the main world.
#[derive(Resource, Default)]
pub struct FoliageStore {
    /// Layout of each uploaded tree type.
    pub types: HashMap<AssetId<BakedFoliage>, TypeSlot>,
    /// The buffers.
    pub buffers: StoreBuffers,
    /// Bumped whenever a buffer is replaced, so materials binding them are refreshed.
    pub generation: u32,
    /// Draw every type with triangle slot meshes, even quad-leaf types (for comparing the two
    /// paths; takes effect for types uploaded afterwards).
    pub force_triangle_slots: bool,
    capacity: Capacity,
    /// Words in the `leaf_light` buffer.
    leaf_light_words: usize,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Capacity {
    instances: u32,
    output: u32,
    cell_offsets: u32,
}

impl FoliageStore {
    /// Rewrites the `leaf_light` buffer with every uploaded type's leaves (in the buffer's
    /// order) and the ring `ring_of` gives each type (`None`: no ring). A type whose asset is
    /// gone is left out (zeros up to the next type's place).
    ///
    /// The words go into the buffer asset in place whenever they fill it exactly (always, while
    /// the types stay the same): Bevy writes them into the same GPU buffer, so the leaf
    /// materials binding it stay as they are. A new buffer asset would make every leaf
    /// material be prepared again, and Bevy prepares a material in the same frame as the
    /// buffers it binds in no fixed order: where the material comes first it waits a frame, and
    /// its leaves are not drawn in that frame — all of them, each time a ring lands. Only
    /// where the length changed is a new asset added (and the generation bumped).
    ///
    /// This buffer, unlike the store's others, keeps its words in the main world
    /// (`RenderAssetUsages::default()`): a buffer asset for the render world alone gives its
    /// words up when extracted, and one rewritten in two frames running is extracted a second
    /// time without them, which Bevy makes into a new, empty GPU buffer that the materials
    /// never bind.
    pub fn rewrite_leaf_light<'a>(
        &mut self,
        buffers: &mut Assets<ShaderBuffer>,
        baked: &'a Assets<BakedFoliage>,
        ring_of: impl Fn(AssetId<BakedFoliage>) -> Option<&'a BounceRing>,
    ) {
        let mut types: Vec<(AssetId<BakedFoliage>, TypeSlot)> =
            self.types.iter().map(|(id, slot)| (*id, *slot)).collect();
        types.sort_by_key(|(_, slot)| slot.light_base);
        let mut light: Vec<u32> = Vec::new();
        for (id, slot) in types {
            // The type's place (already reached while every type's asset lives).
            light.resize(slot.light_base as usize * LEAF_LIGHT_WORDS, 0);
            if let Some(tree) = baked.get(id) {
                push_leaf_light(tree, ring_of(id), &mut light);
            }
        }
        if light.len().max(1) == self.leaf_light_words
            && let Some(mut buffer) = buffers.get_mut(&self.buffers.leaf_light)
        {
            *buffer = leaf_light_buffer(&light);
            return;
        }
        self.leaf_light_words = light.len().max(1);
        self.buffers.leaf_light = buffers.add(leaf_light_buffer(&light));
        self.generation += 1;
    }
}

fn words_buffer(words: &[u32], label: &'static str) -> ShaderBuffer {
    let data: &[u32] = if words.is_empty() { &[0] } else { words };
    let mut buffer = ShaderBuffer::new(bytemuck::cast_slice(data), RenderAssetUsages::RENDER_WORLD);
    buffer.buffer_description.label = Some(label);
    buffer
}

/// The `leaf_light` buffer of `words`, kept in the main world too so that it can be rewritten
/// in place ([`FoliageStore::rewrite_leaf_light`]).
fn leaf_light_buffer(words: &[u32]) -> ShaderBuffer {
    let mut buffer = words_buffer(words, "foliage_leaf_light");
    buffer.asset_usage = RenderAssetUsages::default();
    buffer
}

fn gpu_only_buffer(words: u32, label: &'static str) -> ShaderBuffer {
    let mut buffer =
        ShaderBuffer::with_size(words.max(1) as usize * 4, RenderAssetUsages::RENDER_WORLD);
    buffer.buffer_description.label = Some(label);
    buffer
}

/// Main-world bookkeeping each frame: uploads new tree types, assigns instance slots and regions,
/// grows the buffers when needed.
pub fn update_foliage_store(
    mut commands: Commands,
    mut store: ResMut<FoliageStore>,
    mut buffers: ResMut<Assets<ShaderBuffer>>,
    baked: Res<Assets<BakedFoliage>>,
    shadow_light: Res<FoliageShadowLight>,
    settings: Res<FoliagePruningSettings>,
    trees: Query<(Entity, &PrunedFoliage, Option<&FoliageSlot>), With<PruningParams>>,
) {
    let store = &mut *store;
    let store_force_triangles = store.force_triangle_slots;
    // New tree types.
    let mut new_types: Vec<AssetId<BakedFoliage>> = Vec::new();
    for (_, pruned, _) in &trees {
        let id = pruned.baked.id();
        if !store.types.contains_key(&id) && !new_types.contains(&id) && baked.contains(id) {
            new_types.push(id);
        }
    }
    if !new_types.is_empty() {
        // Re-upload every type in a stable order (types are few; this happens rarely).
        let mut ids: Vec<AssetId<BakedFoliage>> = store.types.keys().copied().collect();
        ids.extend(new_types);
        ids.retain(|id| baked.contains(*id));
        ids.sort_by_key(|id| {
            store
                .types
                .get(id)
                .map(|s| s.vertex_base)
                .unwrap_or(u32::MAX)
        });
        let (mut cfl, mut vis, mut lis, mut idx, mut verts) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut light: Vec<u32> = Vec::new();
        store.types.clear();
        for id in ids {
            let tree = baked.get(id).unwrap();
            let slot = TypeSlot {
                cell_base: cfl.len() as u32,
                cell_count: tree.cell_count() as u32,
                view_count: tree.view_count() as u32,
                visibility_base: vis.len() as u32,
                leaf_base: lis.len() as u32,
                index_base: idx.len() as u32,
                vertex_base: (verts.len() / LEAF_VERTEX_WORDS) as u32,
                full_index_count: tree.indices.len() as u32,
                quads: tree.quad_leaves() && !store_force_triangles,
                light_base: (light.len() / LEAF_LIGHT_WORDS) as u32,
                extinction_bits: tree.extinction.to_bits(),
                hotspot: tree.hotspot.packed(),
                crown_sphere_bits: {
                    let centre = tree.crown_center();
                    let radius = tree
                        .positions
                        .iter()
                        .map(|p| p.distance(centre))
                        .fold(0.0f32, f32::max);
                    [centre.x, centre.y, centre.z, radius].map(f32::to_bits)
                },
            };
            let light_base = (light.len() / LEAF_LIGHT_WORDS) as u32;
            push_leaf_light(tree, None, &mut light);
            cfl.extend_from_slice(&tree.cell_first_leaf);
            vis.extend(tree.visibility.iter().map(|&v| v as u32));
            lis.extend_from_slice(&tree.leaf_index_start);
            idx.extend_from_slice(&tree.indices);
            let mut vertex_cell = vec![0u32; tree.positions.len()];
            for c in 0..tree.cell_count() {
                let (a, b) = (tree.cell_first_leaf[c], tree.cell_first_leaf[c + 1]);
                let (start, end) = (
                    tree.leaf_index_start[a as usize],
                    tree.leaf_index_start[b as usize],
                );
                for &v in &tree.indices[start as usize..end as usize] {
                    vertex_cell[v as usize] = c as u32;
                }
            }
            // Per vertex, its leaf's radius and the centre of its leaf's texture coordinates
            // (for the sub-pixel fade, see `appearance`).
            let mut leaf_radius = vec![0.0f32; tree.positions.len()];
            let mut uv_centre = vec![Vec2::ZERO; tree.positions.len()];
            let mut vertex_leaf = vec![light_base; tree.positions.len()];
            let mut corners: Vec<u32> = Vec::new();
            let radii = tree.leaf_radii();
            for (leaf, &radius) in radii.iter().enumerate() {
                let (start, end) = (
                    tree.leaf_index_start[leaf] as usize,
                    tree.leaf_index_start[leaf + 1] as usize,
                );
                corners.clear();
                corners.extend_from_slice(&tree.indices[start..end]);
                corners.sort_unstable();
                corners.dedup();
                let centre = corners.iter().map(|&v| tree.uvs[v as usize]).sum::<Vec2>()
                    / corners.len().max(1) as f32;
                for &v in &corners {
                    leaf_radius[v as usize] = radius;
                    uv_centre[v as usize] = centre;
                    vertex_leaf[v as usize] = light_base + leaf as u32;
                }
            }
            for v in 0..tree.positions.len() {
                let (p, e, n, uv) = (
                    tree.positions[v],
                    tree.centroid_offsets[v],
                    tree.normals[v],
                    tree.uvs[v],
                );
                verts.extend_from_slice(&[
                    p.x.to_bits(),
                    p.y.to_bits(),
                    p.z.to_bits(),
                    vertex_cell[v],
                    e.x.to_bits(),
                    e.y.to_bits(),
                    e.z.to_bits(),
                    leaf_radius[v].to_bits(),
                    n.x.to_bits(),
                    n.y.to_bits(),
                    n.z.to_bits(),
                    vertex_leaf[v],
                    uv.x.to_bits(),
                    uv.y.to_bits(),
                    uv_centre[v].x.to_bits(),
                    uv_centre[v].y.to_bits(),
                ]);
            }
            store.types.insert(id, slot);
        }
        let b = &mut store.buffers;
        b.cell_first_leaf = buffers.add(words_buffer(&cfl, "foliage_cell_first_leaf"));
        b.visibility = buffers.add(words_buffer(&vis, "foliage_visibility"));
        b.leaf_index_start = buffers.add(words_buffer(&lis, "foliage_leaf_index_start"));
        b.stored_indices = buffers.add(words_buffer(&idx, "foliage_stored_indices"));
        b.leaf_vertices = buffers.add(words_buffer(&verts, "foliage_leaf_vertices"));
        b.leaf_light = buffers.add(leaf_light_buffer(&light));
        store.leaf_light_words = light.len().max(1);
        store.generation += 1;
    }

    // Instance slots in entity order, camera selections first, then (while there is a shadow
    // light) the light selections in the same order; regions sized for every leaf kept.
    let mut entities: Vec<(Entity, AssetId<BakedFoliage>, Option<FoliageSlot>)> = trees
        .iter()
        .filter(|(_, p, _)| store.types.contains_key(&p.baked.id()))
        .map(|(e, p, s)| (e, p.baked.id(), s.copied()))
        .collect();
    entities.sort_by_key(|(e, _, _)| *e);
    let with_light = shadow_light.0.is_some() && settings.shadow_selection;
    let mut need = Capacity::default();
    let region = |ty: &TypeSlot, need: &mut Capacity| {
        let r = Region {
            slot: need.instances,
            output_base: need.output,
            cell_offsets_base: need.cell_offsets,
        };
        need.instances += 1;
        need.output += ty.full_index_count;
        need.cell_offsets += ty.cell_count;
        r
    };
    let cameras: Vec<Region> = entities
        .iter()
        .map(|(_, id, _)| region(&store.types[id], &mut need))
        .collect();
    let lights: Vec<Option<Region>> = entities
        .iter()
        .map(|(_, id, _)| with_light.then(|| region(&store.types[id], &mut need)))
        .collect();
    for (i, (entity, id, old)) in entities.iter().enumerate() {
        let ty = store.types[id];
        let new = FoliageSlot {
            ty,
            camera: cameras[i],
            light: lights[i],
        };
        if *old != Some(new) {
            commands
                .entity(*entity)
                .insert((new, bevy::mesh::MeshTag(mesh_tag(cameras[i].slot, &ty))));
        }
    }
    let cap = store.capacity;
    if need.instances > cap.instances
        || need.output > cap.output
        || need.cell_offsets > cap.cell_offsets
    {
        // Grow by half again so that adding trees one by one does not reallocate every frame.
        let grow = |n: u32, have: u32| if n > have { n + n / 2 } else { have };
        let cap = Capacity {
            instances: grow(need.instances, cap.instances),
            output: grow(need.output, cap.output),
            cell_offsets: grow(need.cell_offsets, cap.cell_offsets),
        };
        let b = &mut store.buffers;
        b.instances = buffers.add(gpu_only_buffer(
            cap.instances * INSTANCE_WORDS as u32,
            "foliage_instances",
        ));
        b.output = buffers.add(gpu_only_buffer(cap.output, "foliage_pruned_indices"));
        b.cell_offsets = buffers.add(gpu_only_buffer(
            cap.cell_offsets * 4,
            "foliage_cell_offsets",
        ));
        let mut draws = gpu_only_buffer(cap.instances * 5, "foliage_pruned_draws");
        draws.buffer_description.usage |= bevy::render::render_resource::BufferUsages::INDIRECT;
        b.draws = buffers.add(draws);
        store.capacity = cap;
        store.generation += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::gathered_bounce::quantize_ratio;

    /// Each leaf's words: the bake's values where they were, then its type's ring height and
    /// ring ratios (low byte first), or no ring's — also for a ring of the wrong size — and the
    /// ring's shares, their slopes and its hotspot on them where it has them; the leaf's open map
    /// last.
    #[test]
    fn the_leaf_light_words_hold_the_types_ring() {
        let tree = crate::pruning::format::tests::sample();
        let n = tree.leaf_count();
        let ring = BounceRing {
            sun_height: 0.25,
            leaves: (0..n)
                .map(|l| std::array::from_fn(|i| (l * 7 + i) as u8))
                .collect(),
            sunlit: (0..n)
                .map(|l| std::array::from_fn(|k| (l * 5 + 3 * k + 1) as u8))
                .collect(),
            sunlit_slopes: (0..n)
                .map(|l| {
                    std::array::from_fn(|k| [k as i8 - 7, -((l % 100) as i8), 3 * k as i8 + 1])
                })
                .collect(),
            sunlit_hotspot: std::array::from_fn(|k| 60 + 9 * k as u8),
            crown_weights: Vec::new(),
        };
        let (mut with, mut without, mut wrong) = (Vec::new(), Vec::new(), Vec::new());
        push_leaf_light(&tree, Some(&ring), &mut with);
        push_leaf_light(&tree, None, &mut without);
        // A bake without open maps, or with them for another number of leaves: all 0 there.
        for open in [Vec::new(), tree.leaf_open[1..].to_vec()] {
            let mut bare = Vec::new();
            let no_maps = BakedFoliage {
                leaf_open: open,
                ..tree.clone()
            };
            push_leaf_light(&no_maps, None, &mut bare);
            for leaf in 0..n {
                let b = &bare[leaf * LEAF_LIGHT_WORDS..(leaf + 1) * LEAF_LIGHT_WORDS];
                assert!(b[40..].iter().all(|&x| x == 0));
            }
        }
        let short = BounceRing {
            sun_height: 0.25,
            leaves: ring.leaves[1..].to_vec(),
            sunlit: ring.sunlit[1..].to_vec(),
            sunlit_slopes: ring.sunlit_slopes[1..].to_vec(),
            sunlit_hotspot: ring.sunlit_hotspot,
            crown_weights: Vec::new(),
        };
        push_leaf_light(&tree, Some(&short), &mut wrong);
        // A ring whose hotspot was not fitted (a node 0): the bake's, words of 0.
        let mut unfitted = Vec::new();
        let mut spotless = ring.clone();
        spotless.sunlit_hotspot[5] = 0;
        push_leaf_light(&tree, Some(&spotless), &mut unfitted);
        // A ring without shares, or with shares for another number of leaves: the ratios, no
        // shares.
        let (mut unshared, mut short_shares) = (Vec::new(), Vec::new());
        let bare = BounceRing {
            sunlit: Vec::new(),
            ..ring.clone()
        };
        // Shares without slopes, or with slopes for another number of leaves: the shares
        // alone.
        let (mut flat, mut short_slopes) = (Vec::new(), Vec::new());
        let unsloped = BounceRing {
            sunlit_slopes: Vec::new(),
            ..ring.clone()
        };
        push_leaf_light(&tree, Some(&unsloped), &mut flat);
        let odd_slopes = BounceRing {
            sunlit_slopes: ring.sunlit_slopes[1..].to_vec(),
            ..ring.clone()
        };
        push_leaf_light(&tree, Some(&odd_slopes), &mut short_slopes);
        assert_eq!(flat, short_slopes);
        push_leaf_light(&tree, Some(&bare), &mut unshared);
        let odd = BounceRing {
            sunlit: ring.sunlit[1..].to_vec(),
            ..ring.clone()
        };
        push_leaf_light(&tree, Some(&odd), &mut short_shares);
        assert_eq!(unshared, short_shares);
        assert_eq!(with.len(), n * LEAF_LIGHT_WORDS);
        assert_eq!(without, wrong);
        let one = u32::from_le_bytes([quantize_ratio(1.0); 4]);
        for leaf in [0, n / 2, n - 1] {
            let w = &with[leaf * LEAF_LIGHT_WORDS..(leaf + 1) * LEAF_LIGHT_WORDS];
            let o = &without[leaf * LEAF_LIGHT_WORDS..(leaf + 1) * LEAF_LIGHT_WORDS];
            assert_eq!(w[..15], o[..15]);
            let b = tree.leaf_bounce[leaf];
            assert_eq!(w[8], u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            assert_eq!(f32::from_bits(w[15]), 0.25);
            assert_eq!(f32::from_bits(o[15]), NO_RING);
            for k in 0..7 {
                let r = &ring.leaves[leaf][4 * k..4 * k + 4];
                assert_eq!(w[16 + k], u32::from_le_bytes([r[0], r[1], r[2], r[3]]));
                assert_eq!(o[16 + k], one);
            }
            // The ring's hotspot: its first four nodes in word 23, its last four in word 39.
            let h = ring.sunlit_hotspot;
            assert_eq!(w[23], u32::from_le_bytes([h[0], h[1], h[2], h[3]]));
            assert_eq!(w[39], u32::from_le_bytes([h[4], h[5], h[6], h[7]]));
            assert_eq!((o[23], o[39]), (0, 0));
            let s = &unfitted[leaf * LEAF_LIGHT_WORDS..(leaf + 1) * LEAF_LIGHT_WORDS];
            assert_eq!((s[23], s[39]), (0, 0));
            assert_eq!((&s[..23], &s[24..39]), (&w[..23], &w[24..39]));
            let s = &ring.sunlit[leaf];
            for k in 0..3 {
                let b = &s[4 * k..4 * k + 4];
                assert_eq!(w[24 + k], u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
                assert_eq!(o[24 + k], 0);
            }
            assert_eq!(w[27], u32::from_le_bytes([s[12], s[13], 1, 0]));
            assert_eq!(o[27], 0);
            // The slopes: node k's components at bytes 3k..3k + 3, two's complement.
            let bytes: Vec<u8> = w[28..40].iter().flat_map(|x| x.to_le_bytes()).collect();
            for k in 0..RING_NODES {
                for c in 0..3 {
                    assert_eq!(bytes[3 * k + c] as i8, ring.sunlit_slopes[leaf][k][c]);
                }
            }
            assert!(bytes[42..44].iter().all(|&b| b == 0));
            assert!(o[28..40].iter().all(|&x| x == 0));
            // The open map last, ring or none: the residual gains, then cells and axes.
            let m = tree.leaf_open[leaf];
            assert!(m.is_map());
            assert_eq!(w[40..48], m.words());
            assert_eq!(o[40..48], m.words());
            assert_eq!(w[40], m.residual[0] as u32 | (m.residual[1] as u32) << 16);
            assert_eq!(
                w[44],
                u32::from_le_bytes(m.map.cells[..4].try_into().unwrap())
            );
            let a = m.map.axes;
            assert_eq!(
                w[46],
                u32::from_le_bytes([m.map.cells[8], a[0][0], a[0][1], a[1][0]])
            );
            assert_eq!(w[47], a[1][1] as u32);
            // Shares without slopes keep the ring's hotspot.
            let f = &flat[leaf * LEAF_LIGHT_WORDS..(leaf + 1) * LEAF_LIGHT_WORDS];
            assert_eq!(f[..28], w[..28]);
            assert!(f[28..39].iter().all(|&x| x == 0));
            assert_eq!(f[39], w[39]);
            // No shares: no hotspot for them either.
            let u = &unshared[leaf * LEAF_LIGHT_WORDS..(leaf + 1) * LEAF_LIGHT_WORDS];
            assert_eq!(u[..23], w[..23]);
            assert!(u[23..40].iter().all(|&x| x == 0));
            assert_eq!(u[40..], w[40..]);
        }
    }
}
