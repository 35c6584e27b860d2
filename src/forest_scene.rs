//! The forest scenes of Gumbau 2011, table 3.5, shared by the `forest` example and the
//! `forest_bench` benchmark: a dense forest of 6,450 trees and a sparse one of 210, mixing the
//! four test trees, on a ground plane, the camera standing inside.
//!
//! Each scene sets `far` so that about as many trees are in view (in the frustum and nearer than
//! `far`) as in the thesis: 508 of 6,450 (8 %) and 24 of 210. Trees are drawn with
//! [`ForestTree`] (the manager and its LoD caches); the same trees are also spawned, hidden, as
//! the `VisibilityRange` baseline (three decimated leaf meshes per type) under
//! [`HlodForestRoot`].

use bevy::camera::visibility::VisibilityRange;
use bevy::prelude::*;
use bevy_foliage::forest::hlod::decimated_leaves;
use bevy_foliage::meshes::{bark_mesh, leaf_set_mesh};
use bevy_foliage::pruning::bake::{BakeSettings, bake};
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
}

impl ForestKind {
    /// Parses `dense` or `sparse`.
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "dense" => Some(Self::Dense),
            "sparse" => Some(Self::Sparse),
            _ => None,
        }
    }

    /// Trees in the forest.
    pub fn tree_count(self) -> usize {
        match self {
            Self::Dense => 6450,
            Self::Sparse => 210,
        }
    }

    /// Side of the square the trees stand on (m).
    pub fn side(self) -> f32 {
        match self {
            Self::Dense => 1100.0,
            Self::Sparse => 300.0,
        }
    }

    /// Near and far of the LoD (m): `far` gives about the thesis' count in view (in the frustum
    /// and nearer than `far`) for the 45° 16:9 benchmark camera at the centre (measured: 239
    /// trees with far = 250 m, so 360 m for ~500; sparse: 18 at 100 m, so 115 m for ~24).
    pub fn near_far(self) -> (f32, f32) {
        match self {
            Self::Dense => (15.0, 360.0),
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
                    out.kind = ForestKind::parse(&v)
                        .ok_or_else(|| format!("--forest takes dense or sparse, not '{v}'"))?;
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

/// The forest to build.
#[derive(Resource, Clone, Debug)]
pub struct ForestScene {
    /// Which forest.
    pub kind: ForestKind,
    /// Fraction of the thesis' leaf counts (16,107 / 28,645 / 41,155 / 131,042) per tree type.
    pub leaf_scale: f32,
    /// Also spawn the hidden `VisibilityRange` baseline.
    pub with_hlod: bool,
}

/// Parent of the manager's trees (hide it to show only the baseline).
#[derive(Component)]
pub struct ManagedForestRoot;

/// Parent of the `VisibilityRange` baseline trees (hidden at first).
#[derive(Component)]
pub struct HlodForestRoot;

/// The leaf fractions and distance bands of the baseline's three levels, as fractions of
/// `[near, far]`: full detail to 20 %, 40 % of the leaves to 55 %, 12 % to `far`.
pub const HLOD_LEVELS: [(f32, f32); 3] = [(1.0, 0.2), (0.4, 0.55), (0.12, 1.0)];

/// Builds the forest (a startup system; needs [`ForestScene`] inserted).
pub fn spawn_forest(
    mut commands: Commands,
    scene: Res<ForestScene>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut leaf_materials: ResMut<Assets<LeafMaterial>>,
    mut baked_assets: ResMut<Assets<bevy_foliage::pruning::bake::BakedFoliage>>,
    mut pruning: ResMut<FoliagePruningSettings>,
) {
    let (near, far) = scene.kind.near_far();
    // The thesis' scenes are set in metres (table 3.5): world distances.
    pruning.distances = bevy_foliage::LodDistances::World { near, far };
    let side = scene.kind.side();
    commands.spawn((
        Name::new("ground"),
        Mesh3d(meshes.add(Plane3d::default().mesh().size(side + 400.0, side + 400.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.42, 0.47, 0.32),
            perceptual_roughness: 1.0,
            ..default()
        })),
    ));
    let leaf_look = default_leaf_material();
    let leaf_material = leaf_materials.add(leaf_material(leaf_look.clone()));
    let hlod_leaf_material = materials.add(StandardMaterial {
        double_sided: true,
        cull_mode: None,
        ..leaf_look
    });
    let bark_material = materials.add(default_bark_material());
    struct Type {
        baked: Handle<bevy_foliage::pruning::bake::BakedFoliage>,
        bark: Handle<Mesh>,
        levels: Vec<Handle<Mesh>>,
    }
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
        let levels = if scene.with_hlod {
            HLOD_LEVELS
                .iter()
                .enumerate()
                .map(|(i, (fraction, _))| {
                    meshes.add(leaf_set_mesh(&decimated_leaves(
                        &tree.leaves,
                        *fraction,
                        17 + i as u64,
                    )))
                })
                .collect()
        } else {
            Vec::new()
        };
        types.push(Type {
            baked: baked_assets.add(baked),
            bark: meshes.add(bark_mesh(&tree.bark)),
            levels,
        });
    }
    if types.is_empty() {
        return;
    }
    let managed_root = commands
        .spawn((
            Name::new("forest (manager)"),
            ManagedForestRoot,
            Transform::IDENTITY,
            Visibility::Inherited,
        ))
        .id();
    let hlod_root = scene.with_hlod.then(|| {
        commands
            .spawn((
                Name::new("forest (VisibilityRange baseline)"),
                HlodForestRoot,
                Transform::IDENTITY,
                Visibility::Hidden,
            ))
            .id()
    });
    let mut rng = SplitMix64::new(2011);
    for i in 0..scene.kind.tree_count() {
        let ty = &types[i % types.len()];
        let position = Vec3::new(
            rng.range(-side / 2.0, side / 2.0),
            0.0,
            rng.range(-side / 2.0, side / 2.0),
        );
        // Keep a clearing around the camera's spot.
        if position.length() < 6.0 {
            continue;
        }
        let transform = Transform::from_translation(position)
            .with_rotation(Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)))
            .with_scale(Vec3::splat(rng.range(0.85, 1.15)));
        commands.entity(managed_root).with_child((
            ForestTree {
                baked: ty.baked.clone(),
                material: leaf_material.clone(),
            },
            transform,
            children![(
                Mesh3d(ty.bark.clone()),
                MeshMaterial3d(bark_material.clone())
            )],
        ));
        if let Some(root) = hlod_root {
            let mut start = 0.0;
            let mut levels = Vec::new();
            for (level, (_, end_fraction)) in ty.levels.iter().zip(HLOD_LEVELS) {
                let end = near + end_fraction * (far - near);
                levels.push((
                    Mesh3d(level.clone()),
                    MeshMaterial3d(hlod_leaf_material.clone()),
                    VisibilityRange::abrupt(start, end),
                ));
                start = end;
            }
            commands.entity(root).with_children(|parent| {
                parent
                    .spawn((transform, Visibility::Inherited))
                    .with_children(|tree| {
                        tree.spawn((
                            Mesh3d(ty.bark.clone()),
                            MeshMaterial3d(bark_material.clone()),
                        ));
                        for level in levels {
                            tree.spawn(level);
                        }
                    });
            });
        }
    }
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
