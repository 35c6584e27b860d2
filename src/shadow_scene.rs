//! The soft-shadow scene of the `soft_shadows` example and benchmark: a ground with posts of
//! several heights, a table-like panel on legs and a sphere under a low sun or a lamp (spot
//! light) above them, so penumbrae start hard at every contact and widen with the distance to
//! the blocker — and a switch between Bevy's hard shadows, Bevy's PCSS, Screen Space Soft
//! Shadows and the filterable shadow maps for the same light.

use bevy::light::{CascadeShadowConfigBuilder, DirectionalLightShadowMap, ShadowFilteringMethod};
use bevy::prelude::*;
use bevy_soft_shadows::ScreenSpaceSoftShadows;
use bevy_soft_shadows::filterable::FilteredShadowMap;
use bevy_soft_shadows::filterable::filter::FilterableMethod;

/// The shadowing technique of the scene's sun.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Reflect)]
pub enum ShadowTechnique {
    /// Bevy's shadow map with 2×2 hardware PCF.
    Hard,
    /// Bevy's percentage-closer soft shadows (`DirectionalLight::soft_shadow_size`,
    /// `SpotLight::soft_shadows_enabled`).
    Pcss,
    /// Screen Space Soft Shadows ([`ScreenSpaceSoftShadows`]).
    #[default]
    Ssss,
    /// A filterable shadow map ([`FilteredShadowMap`]) on the sun or the lamp.
    Filtered,
}

impl ShadowTechnique {
    /// All four, in switching order.
    pub const ALL: [Self; 4] = [Self::Hard, Self::Pcss, Self::Ssss, Self::Filtered];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Hard => "hard",
            Self::Pcss => "pcss",
            Self::Ssss => "ssss",
            Self::Filtered => "filtered",
        }
    }
}

/// What the scene shows; edit it (panel, keys 1/2/3) to switch.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource)]
pub struct ShadowDemo {
    /// 0: hard, 1: Bevy's PCSS, 2: SSSS, 3: a filterable shadow map (keys 1, 2, 3, 6).
    pub technique: u32,
    /// Angular diameter of the light seen from the scene (rad): the sun's, or the lamp's from
    /// [`LAMP_DISTANCE`] away (its diameter is [`lamp_diameter`]).
    pub light_size: f32,
    /// Light the scene with the lamp (a spot light) instead of the sun (key 4 toggles).
    pub spot: bool,
    /// Which blockers stand on the ground ([`SCENE_NAMES`]): 0 the posts, panel and sphere
    /// ([`PoleScenePart`]), 1 a canopy of three trees of small leaf quads ([`CanopyPart`]: many
    /// penumbra tiles, the worst case of tiled soft shadows), 2 a palm on a beach
    /// ([`PalmPart`]: a thin trunk and fronds high over the sand, large penumbrae). Key 5
    /// cycles.
    pub scene: u32,
    /// SSSS blurs every screen tile instead of the classified ones (same image, for comparing
    /// costs).
    pub ssss_all_tiles: bool,
    /// Bevy's PCSS size per radian of light size: PCSS's `soft_shadow_size` has no physical unit
    /// shared with an angular size; this factor gave PCSS its lowest error against the
    /// area-light reference on the pole scene (`ssss_vs_pcss` test sweep).
    pub pcss_size_per_radian: f32,
    /// The filterable shadow map of technique 3: its method (key 7 cycles through them) and
    /// pre-filter.
    pub filtered: FilteredShadowMap,
}

/// The filterable methods, in the order key 7 cycles through them.
pub const FILTERED_METHODS: [FilterableMethod; 5] = [
    FilterableMethod::GaussianCdf,
    FilterableMethod::PowerCdf,
    FilterableMethod::Variance,
    FilterableMethod::Exponential { c: 80.0 },
    FilterableMethod::Moments4,
];

impl Default for ShadowDemo {
    fn default() -> Self {
        Self {
            technique: 2,
            light_size: 0.1,
            spot: false,
            scene: 0,
            ssss_all_tiles: false,
            pcss_size_per_radian: PCSS_SIZE_PER_RADIAN,
            filtered: FilteredShadowMap {
                blur_sigma: 3.0,
                ..default()
            },
        }
    }
}

/// See [`ShadowDemo::pcss_size_per_radian`].
pub const PCSS_SIZE_PER_RADIAN: f32 = 4.0 / 0.15;

impl ShadowDemo {
    /// The technique selected.
    pub fn technique(&self) -> ShadowTechnique {
        ShadowTechnique::ALL[(self.technique as usize).min(ShadowTechnique::ALL.len() - 1)]
    }

    /// The sun's SSSS `max_occluder_distance` for the scene shown: 5 m covers the posts, the
    /// panel and the canopy; the palm's fronds are up to ~9 m from the sand along the light
    /// (12 m leaves a margin for larger or lower suns).
    pub fn sun_occluder_distance(&self) -> f32 {
        if self.scene == 2 { 12.0 } else { 5.0 }
    }
}

/// Bevy's spot PCSS `radius` per metre of lamp radius: its kernel is in units of a fixed texel
/// size times an empirical factor, not metres; 30× gave it its lowest error against the
/// area-light reference (`ssss_spot` test sweep).
pub const PCSS_SPOT_RADIUS_SCALE: f32 = 30.0;

/// The scene's sun.
#[derive(Component)]
pub struct DemoSun;

/// A blocker of the pole scene ([`ShadowDemo::scene`] 0).
#[derive(Component)]
pub struct PoleScenePart;

/// A part of the canopy scene ([`ShadowDemo::scene`] 1).
#[derive(Component)]
pub struct CanopyPart;

/// A part of the palm-on-a-beach scene ([`ShadowDemo::scene`] 2).
#[derive(Component, Clone, Copy)]
pub struct PalmPart;

/// The scenes [`ShadowDemo::scene`] picks from, by index.
pub const SCENE_NAMES: [&str; 3] = ["poles", "canopy", "palm"];

/// Where the palm of the beach scene stands.
pub const PALM_BASE: Vec3 = Vec3::new(2.5, 0.0, 2.5);
/// Height of the palm's crown over the sand (m).
pub const PALM_HEIGHT: f32 = 6.0;

/// Leaves per crown of the canopy scene.
pub const CANOPY_LEAVES: usize = 1500;

/// A triangle list of `positions` and `normals`.
fn triangle_mesh(positions: Vec<[f32; 3]>, normals: Vec<[f32; 3]>, indices: Vec<u32>) -> Mesh {
    Mesh::new(
        bevy::mesh::PrimitiveTopology::TriangleList,
        bevy::asset::RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_indices(bevy::mesh::Indices::U32(indices))
}

/// One crown of the canopy scene: `leaves` square leaves of side `leaf` m, centres uniform in an
/// ellipsoid of radii `radii` around the origin, randomly turned (a fixed seed: the same crown
/// every run).
pub fn crown_mesh(leaves: usize, radii: Vec3, leaf: f32, seed: u64) -> Mesh {
    // SplitMix64: a tiny deterministic generator is enough for leaf placement.
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut positions, mut normals, mut indices) = (Vec::new(), Vec::new(), Vec::new());
    while positions.len() < leaves * 4 {
        let p = Vec3::new(next(), next(), next()) * 2.0 - 1.0;
        if p.length_squared() > 1.0 {
            continue;
        }
        let centre = p * radii;
        let rotation = Quat::from_euler(
            EulerRot::YXZ,
            next() * std::f32::consts::TAU,
            next() * std::f32::consts::PI,
            next() * std::f32::consts::TAU,
        );
        let (u, v, n) = (
            rotation * Vec3::X * leaf * 0.5,
            rotation * Vec3::Z * leaf * 0.5,
            rotation * Vec3::Y,
        );
        let base = positions.len() as u32;
        for corner in [-u - v, u - v, u + v, -u + v] {
            positions.push((centre + corner).to_array());
            normals.push(n.to_array());
        }
        indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    triangle_mesh(positions, normals, indices)
}

/// Centre of the palm trunk at height fraction `t` ∈ [0, 1] (relative to [`PALM_BASE`]): a
/// trunk leaning away from the sun in a gentle curve, as beach palms grow.
pub fn palm_trunk_centre(t: f32) -> Vec3 {
    Vec3::new(-0.9 * t * t, PALM_HEIGHT * t, 0.35 * t * t)
}

/// A palm trunk around the origin: a tube of `sides` sides along [`palm_trunk_centre`], 0.16 m
/// in radius at the foot narrowing to 0.11 m under the crown — thin against a large light, so its
/// shadow is all penumbra a few metres from the foot.
pub fn palm_trunk_mesh(sides: usize, rings: usize) -> Mesh {
    let (mut positions, mut normals, mut indices) = (Vec::new(), Vec::new(), Vec::new());
    for ring in 0..=rings {
        let t = ring as f32 / rings as f32;
        let centre = palm_trunk_centre(t);
        let tangent = (palm_trunk_centre((t + 1e-3).min(1.0))
            - palm_trunk_centre((t - 1e-3).max(0.0)))
        .normalize();
        let side = tangent.cross(Vec3::Z).normalize();
        let other = side.cross(tangent);
        let radius = 0.16 - 0.05 * t;
        for k in 0..sides {
            let a = k as f32 / sides as f32 * std::f32::consts::TAU;
            let n = side * a.cos() + other * a.sin();
            positions.push((centre + n * radius).to_array());
            normals.push(n.to_array());
        }
    }
    for ring in 0..rings {
        for k in 0..sides {
            let (a, b) = (ring * sides + k, ring * sides + (k + 1) % sides);
            let (c, d) = (a + sides, b + sides);
            indices.extend([a, c, b, b, c, d].map(|i| i as u32));
        }
    }
    triangle_mesh(positions, normals, indices)
}

/// The palm's crown, relative to the top of its trunk: `fronds` arching fronds, each a rachis
/// rising then drooping over 3 m with narrow leaflets (0.06 m wide) on both sides, longest at
/// the middle of the frond — many thin blockers far above the sand.
pub fn palm_fronds_mesh(fronds: usize) -> Mesh {
    const LENGTH: f32 = 3.0;
    const LEAFLET_WIDTH: f32 = 0.06;
    let (mut positions, mut normals, mut indices) = (Vec::new(), Vec::new(), Vec::new());
    let mut quad = |corners: [Vec3; 4]| {
        let n = (corners[1] - corners[0])
            .cross(corners[3] - corners[0])
            .normalize_or(Vec3::Y);
        let base = positions.len() as u32;
        for c in corners {
            positions.push(c.to_array());
            normals.push(n.to_array());
        }
        indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    };
    for f in 0..fronds {
        // Golden-angle azimuths: fronds spread evenly without lining up.
        let azimuth = f as f32 * 2.399_963;
        let out = Vec3::new(azimuth.cos(), 0.0, azimuth.sin());
        let across = Vec3::Y.cross(out).normalize();
        let rise = 0.45 - 0.25 * (f % 3) as f32;
        let rachis = |s: f32| out * (s * LENGTH) + Vec3::Y * (LENGTH * (rise * s - 0.55 * s * s));
        let steps = 24;
        for i in 0..steps {
            let (s0, s1) = (i as f32 / steps as f32, (i + 1) as f32 / steps as f32);
            // The rachis itself, a 4 cm strip.
            let (p0, p1) = (rachis(s0), rachis(s1));
            let w = across * 0.02;
            quad([p0 - w, p1 - w, p1 + w, p0 + w]);
            if s0 < 0.08 {
                continue;
            }
            let leaflet = 0.1 + 0.65 * (std::f32::consts::PI * s0).sin();
            let along = (p1 - p0).normalize();
            for side in [-1.0f32, 1.0] {
                // Leaflets sweep forward and hang 35° below the frond's plane.
                let dir = (across * side * 0.82 + along * 0.3 - Vec3::Y * 0.57).normalize();
                let half = along * (0.5 * LEAFLET_WIDTH);
                let tip = p0 + dir * leaflet;
                quad([p0 - half, tip - half, tip + half, p0 + half]);
            }
        }
    }
    triangle_mesh(positions, normals, indices)
}

/// Spawns the palm of the beach scene at [`PALM_BASE`] with `parts` (visibility, markers)
/// on each of its two meshes.
pub fn spawn_palm(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    trunk: Handle<StandardMaterial>,
    fronds: Handle<StandardMaterial>,
    parts: impl Bundle + Clone,
) {
    commands.spawn((
        parts.clone(),
        Mesh3d(meshes.add(palm_trunk_mesh(12, 16))),
        MeshMaterial3d(trunk),
        Transform::from_translation(PALM_BASE),
    ));
    commands.spawn((
        parts,
        Mesh3d(meshes.add(palm_fronds_mesh(11))),
        MeshMaterial3d(fronds),
        Transform::from_translation(PALM_BASE + palm_trunk_centre(1.0)),
    ));
}

/// The scene's lamp (a spot light), used instead of the sun when [`ShadowDemo::spot`] is on.
#[derive(Component)]
pub struct DemoLamp;

/// Where the lamp hangs and what it points at.
pub const LAMP_POSITION: Vec3 = Vec3::new(1.0, 7.0, 3.0);
/// See [`LAMP_POSITION`].
pub const LAMP_AIM: Vec3 = Vec3::new(-0.5, 0.0, 0.3);
/// The distance from which the lamp's diameter subtends [`ShadowDemo::light_size`].
pub const LAMP_DISTANCE: f32 = 7.0;

/// The lamp's diameter (m) for an angular size `light_size` seen from [`LAMP_DISTANCE`].
pub fn lamp_diameter(light_size: f32) -> f32 {
    2.0 * LAMP_DISTANCE * (0.5 * light_size).tan()
}

/// The lamp's transform at `position` (always pointing the same way, so a jittered lamp keeps
/// its orientation).
pub fn lamp_transform(position: Vec3) -> Transform {
    Transform::from_translation(position).looking_to(LAMP_AIM - LAMP_POSITION, Vec3::Y)
}

/// Direction from the ground towards the sun (35° up).
pub fn sun_direction() -> Vec3 {
    Vec3::new(0.6, 0.7, 0.4).normalize()
}

/// Spawns the scene and its camera (MSAA off: the software rasteriser pays for it).
pub fn spawn_shadow_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    commands.insert_resource(DirectionalLightShadowMap { size: 2048 });
    let ground = materials.add(StandardMaterial {
        base_color: Color::srgb(0.75, 0.72, 0.66),
        perceptual_roughness: 1.0,
        ..default()
    });
    let props = materials.add(StandardMaterial {
        base_color: Color::srgb(0.55, 0.38, 0.25),
        perceptual_roughness: 0.8,
        ..default()
    });
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(60.0, 60.0))),
        MeshMaterial3d(ground),
    ));
    // Posts of increasing height: longer posts cast shadows whose tips are wider.
    for (i, h) in [1.0f32, 2.0, 3.0, 4.0].into_iter().enumerate() {
        commands.spawn((
            PoleScenePart,
            Mesh3d(meshes.add(Cuboid::new(0.25, h, 0.25))),
            MeshMaterial3d(props.clone()),
            Transform::from_xyz(-3.0 + 1.6 * i as f32, h / 2.0, -1.5),
        ));
    }
    // A panel on four legs: a shadow hard at the legs and soft under the top's edge.
    commands.spawn((
        PoleScenePart,
        Mesh3d(meshes.add(Cuboid::new(2.0, 0.08, 1.2))),
        MeshMaterial3d(props.clone()),
        Transform::from_xyz(1.5, 1.2, 1.8),
    ));
    for (x, z) in [(-0.9, -0.5), (0.9, -0.5), (-0.9, 0.5), (0.9, 0.5)] {
        commands.spawn((
            PoleScenePart,
            Mesh3d(meshes.add(Cuboid::new(0.08, 1.2, 0.08))),
            MeshMaterial3d(props.clone()),
            Transform::from_xyz(1.5 + x, 0.6, 1.8 + z),
        ));
    }
    commands.spawn((
        PoleScenePart,
        Mesh3d(meshes.add(Sphere::new(0.6).mesh().uv(32, 16))),
        MeshMaterial3d(props.clone()),
        Transform::from_xyz(-2.0, 0.6, 2.0),
    ));
    // The canopy: three trees whose crowns of small leaves fill the view with penumbrae.
    let leaves = materials.add(StandardMaterial {
        base_color: Color::srgb(0.25, 0.45, 0.15),
        perceptual_roughness: 0.9,
        cull_mode: None,
        double_sided: true,
        ..default()
    });
    for (i, (x, z, height)) in [
        (-2.2f32, -0.8f32, 3.2f32),
        (0.6, -1.6, 3.6),
        (1.8, 1.4, 2.8),
    ]
    .into_iter()
    .enumerate()
    {
        commands.spawn((
            CanopyPart,
            Mesh3d(meshes.add(Cylinder::new(0.12, height))),
            MeshMaterial3d(props.clone()),
            Transform::from_xyz(x, height / 2.0, z),
            Visibility::Hidden,
        ));
        commands.spawn((
            CanopyPart,
            Mesh3d(meshes.add(crown_mesh(
                CANOPY_LEAVES,
                Vec3::new(1.4, 1.0, 1.4),
                0.22,
                i as u64 + 1,
            ))),
            MeshMaterial3d(leaves.clone()),
            Transform::from_xyz(x, height + 0.6, z),
            Visibility::Hidden,
        ));
    }
    // The beach: one palm over the sand.
    spawn_palm(
        &mut commands,
        &mut meshes,
        props.clone(),
        leaves.clone(),
        (PalmPart, Visibility::Hidden),
    );
    commands.spawn((
        DemoSun,
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        CascadeShadowConfigBuilder {
            num_cascades: 1,
            minimum_distance: 0.1,
            maximum_distance: 30.0,
            first_cascade_far_bound: 30.0,
            ..default()
        }
        .build(),
        Transform::default().looking_to(-sun_direction(), Vec3::Y),
    ));
    commands.spawn((
        DemoLamp,
        SpotLight {
            intensity: 3.0e6,
            range: 40.0,
            shadow_maps_enabled: true,
            outer_angle: 0.75,
            inner_angle: 0.6,
            ..default()
        },
        lamp_transform(LAMP_POSITION),
        Visibility::Hidden,
    ));
    commands.spawn((
        Camera3d::default(),
        Msaa::Off,
        ShadowFilteringMethod::Hardware2x2,
        Transform::from_xyz(-1.0, 6.5, 10.0).looking_at(Vec3::new(0.0, 0.5, 0.5), Vec3::Y),
    ));
}

/// The SSSS settings of the demo for a light of `light_size` (rad, or m for the lamp).
fn ssss_settings(
    light_size: f32,
    max_occluder_distance: f32,
    all_tiles: bool,
) -> ScreenSpaceSoftShadows {
    ScreenSpaceSoftShadows {
        light_size,
        max_occluder_distance,
        taps_per_side: 11,
        // Wide enough for the palm's fronds under a large sun at 640×360 (a 2 m penumbra is
        // ~100 px there); the taps a side stay 11 whatever the reach.
        max_kernel_px: 96.0,
        tile_classification: !all_tiles,
        ..default()
    }
}

/// Applies [`ShadowDemo`] to the sun and the lamp when it changes: the light in use is visible
/// and shadowed with the technique chosen, the other hidden.
#[allow(clippy::type_complexity)]
pub fn apply_shadow_demo(
    demo: Res<ShadowDemo>,
    mut commands: Commands,
    mut sun: Query<(Entity, &mut DirectionalLight, &mut Visibility), With<DemoSun>>,
    mut lamp: Query<(Entity, &mut SpotLight, &mut Visibility), Without<DemoSun>>,
    mut parts: Query<
        (&mut Visibility, Has<CanopyPart>, Has<PalmPart>),
        (
            Or<(With<PoleScenePart>, With<CanopyPart>, With<PalmPart>)>,
            Without<DemoSun>,
            Without<SpotLight>,
        ),
    >,
) {
    if !demo.is_changed() {
        return;
    }
    for (mut visibility, canopy, palm) in &mut parts {
        let scene = if canopy {
            1
        } else if palm {
            2
        } else {
            0
        };
        let shown = scene == demo.scene.min(2);
        let v = if shown {
            Visibility::Inherited
        } else {
            Visibility::Hidden
        };
        if *visibility != v {
            *visibility = v;
        }
    }
    let technique = demo.technique();
    for (entity, mut light, mut visibility) in &mut sun {
        *visibility = if demo.spot {
            Visibility::Hidden
        } else {
            Visibility::Inherited
        };
        light.soft_shadow_size = (technique == ShadowTechnique::Pcss)
            .then(|| demo.light_size * demo.pcss_size_per_radian);
        if technique == ShadowTechnique::Ssss && !demo.spot {
            commands.entity(entity).insert(ssss_settings(
                demo.light_size,
                demo.sun_occluder_distance(),
                demo.ssss_all_tiles,
            ));
        } else {
            commands.entity(entity).remove::<ScreenSpaceSoftShadows>();
        }
        if technique == ShadowTechnique::Filtered && !demo.spot {
            commands.entity(entity).insert(demo.filtered);
        } else {
            commands.entity(entity).remove::<FilteredShadowMap>();
        }
    }
    for (entity, mut light, mut visibility) in &mut lamp {
        *visibility = if demo.spot {
            Visibility::Inherited
        } else {
            Visibility::Hidden
        };
        let diameter = lamp_diameter(demo.light_size);
        light.soft_shadows_enabled = technique == ShadowTechnique::Pcss;
        light.radius = if technique == ShadowTechnique::Pcss {
            0.5 * diameter * PCSS_SPOT_RADIUS_SCALE
        } else {
            0.0
        };
        // Blockers at least 3.5 m from the lamp and up to 3.5 m above their receivers get
        // their whole penumbra (`min_filter::spot_coarse_radius`): the posts and the panel.
        if technique == ShadowTechnique::Ssss && demo.spot {
            commands
                .entity(entity)
                .insert(ssss_settings(diameter, 3.5, demo.ssss_all_tiles));
        } else {
            commands.entity(entity).remove::<ScreenSpaceSoftShadows>();
        }
        if technique == ShadowTechnique::Filtered && demo.spot {
            commands.entity(entity).insert(demo.filtered);
        } else {
            commands.entity(entity).remove::<FilteredShadowMap>();
        }
    }
}

/// Keys 1, 2, 3, 6 pick hard shadows, PCSS, SSSS or a filterable shadow map; key 7 cycles the
/// filterable map's method; key 4 switches between the sun and the lamp, key 5 cycles through the
/// pole, canopy and palm scenes.
pub fn switch_with_keys(keys: Option<Res<ButtonInput<KeyCode>>>, mut demo: ResMut<ShadowDemo>) {
    let Some(keys) = keys else { return };
    if keys.just_pressed(KeyCode::Digit4) {
        demo.spot = !demo.spot;
    }
    if keys.just_pressed(KeyCode::Digit5) {
        demo.scene = (demo.scene.min(2) + 1) % 3;
    }
    if keys.just_pressed(KeyCode::Digit7) {
        let next = FILTERED_METHODS
            .iter()
            .position(|m| *m == demo.filtered.method)
            .map_or(0, |i| (i + 1) % FILTERED_METHODS.len());
        demo.filtered.method = FILTERED_METHODS[next];
    }
    for (key, technique) in [
        (KeyCode::Digit1, 0),
        (KeyCode::Digit2, 1),
        (KeyCode::Digit3, 2),
        (KeyCode::Digit6, 3),
    ] {
        if keys.just_pressed(key) && demo.technique != technique {
            demo.technique = technique;
        }
    }
}

/// Registers the demo's resource and systems (the scene itself is spawned by
/// [`spawn_shadow_scene`]).
pub fn add_shadow_demo(app: &mut App) {
    app.init_resource::<ShadowDemo>()
        .register_type::<ShadowDemo>()
        .add_systems(Update, (switch_with_keys, apply_shadow_demo).chain());
}
