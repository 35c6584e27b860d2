//! The `bevy_egui` panel of windowed example runs: live frame time, every diagnostic the plugins
//! publish, and reflected settings that can be edited in place.
//!
//! Settings are edited through `Reflect`, so any plugin settings type that derives it shows up
//! without the panel knowing the type: numbers get drag fields, booleans checkboxes, nested
//! structs are indented, enums show their variant.

use crate::stats::{FrameStats, RunStats, collect_diagnostics};
use bevy::diagnostic::DiagnosticsStore;
use bevy::prelude::*;
use bevy::reflect::{PartialReflect, ReflectMut};
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use bevy_egui::{EguiContext, EguiPlugin, EguiPrimaryContextPass, PrimaryEguiContext, egui};
use std::path::PathBuf;

/// What a windowed run was asked to do (from the example flags).
#[derive(Resource, Clone, Debug)]
pub struct PanelRun {
    /// Example name.
    pub name: String,
    /// Exit after this many frames.
    pub frames: Option<u32>,
    /// Save the last frame here.
    pub screenshot: Option<PathBuf>,
    /// Write the JSON statistics here.
    pub stats: Option<PathBuf>,
    /// Window size.
    pub size: UVec2,
}

/// Frame times (ms) of the windowed run, from `Time<Real>`.
#[derive(Resource, Default, Debug)]
pub struct WindowedFrameTimes {
    /// All frame times so far.
    pub all_ms: Vec<f64>,
}

type InspectorUi = fn(&mut World, &mut egui::Ui);

/// The settings shown in the panel.
#[derive(Resource, Default)]
struct Inspectors(Vec<(&'static str, InspectorUi)>);

/// Adds egui, the panel and the frame bookkeeping to a windowed app.
pub fn add_panel(app: &mut App, run: PanelRun) {
    app.add_plugins(EguiPlugin::default())
        .insert_resource(run)
        .init_resource::<WindowedFrameTimes>()
        .init_resource::<Inspectors>()
        .add_systems(Update, count_frames)
        .add_systems(EguiPrimaryContextPass, draw_panel);
}

/// Registers the editor of a settings resource.
pub fn inspect_resource<
    R: Resource + Component<Mutability = bevy::ecs::component::Mutable> + Reflect,
>(
    app: &mut App,
) {
    app.init_resource::<Inspectors>();
    app.world_mut()
        .resource_mut::<Inspectors>()
        .0
        .push((short_type_name::<R>(), resource_ui::<R>));
}

/// Registers the editor of a settings component (every entity that has it).
pub fn inspect_component<C: Component<Mutability = bevy::ecs::component::Mutable> + Reflect>(
    app: &mut App,
) {
    app.init_resource::<Inspectors>();
    app.world_mut()
        .resource_mut::<Inspectors>()
        .0
        .push((short_type_name::<C>(), component_ui::<C>));
}

fn short_type_name<T>() -> &'static str {
    let full = std::any::type_name::<T>();
    full.rsplit("::").next().unwrap_or(full)
}

fn resource_ui<R: Resource + Component<Mutability = bevy::ecs::component::Mutable> + Reflect>(
    world: &mut World,
    ui: &mut egui::Ui,
) {
    let Some(mut resource) = world.get_resource_mut::<R>() else {
        ui.label("(not present)");
        return;
    };
    if reflect_ui(
        resource.bypass_change_detection().as_partial_reflect_mut(),
        ui,
    ) {
        resource.set_changed();
    }
}

fn component_ui<C: Component<Mutability = bevy::ecs::component::Mutable> + Reflect>(
    world: &mut World,
    ui: &mut egui::Ui,
) {
    let mut query = world.query::<(Entity, &mut C)>();
    for (entity, mut component) in query.iter_mut(world) {
        ui.label(format!("entity {entity}"));
        if reflect_ui(
            component.bypass_change_detection().as_partial_reflect_mut(),
            ui,
        ) {
            component.set_changed();
        }
    }
}

/// Draws an editor for a reflected value. Returns whether it was edited.
pub fn reflect_ui(value: &mut dyn PartialReflect, ui: &mut egui::Ui) -> bool {
    macro_rules! number {
        ($($t:ty),*) => {$(
            if let Some(v) = value.try_downcast_mut::<$t>() {
                return ui.add(egui::DragValue::new(v).speed(0.01)).changed();
            }
        )*};
    }
    if let Some(v) = value.try_downcast_mut::<bool>() {
        return ui.checkbox(v, "").changed();
    }
    number!(f32, f64, u8, u16, u32, u64, usize, i32, i64);
    let mut changed = false;
    match value.reflect_mut() {
        ReflectMut::Struct(s) => {
            for i in 0..s.field_len() {
                let name = s.name_at(i).unwrap_or("?").to_string();
                if let Some(field) = s.field_at_mut(i) {
                    ui.horizontal(|ui| {
                        ui.label(name);
                        ui.vertical(|ui| changed |= reflect_ui(field, ui));
                    });
                }
            }
        }
        ReflectMut::TupleStruct(s) => {
            for i in 0..s.field_len() {
                if let Some(field) = s.field_mut(i) {
                    changed |= reflect_ui(field, ui);
                }
            }
        }
        ReflectMut::Enum(e) => {
            ui.label(e.variant_name().to_string());
            for i in 0..e.field_len() {
                if let Some(field) = e.field_at_mut(i) {
                    changed |= reflect_ui(field, ui);
                }
            }
        }
        _ => {
            ui.label(format!("{value:?}"));
        }
    }
    changed
}

fn count_frames(
    time: Res<Time<Real>>,
    mut times: ResMut<WindowedFrameTimes>,
    run: Res<PanelRun>,
    store: Res<DiagnosticsStore>,
    mut commands: Commands,
    mut exit: MessageWriter<AppExit>,
) {
    let dt = time.delta_secs_f64() * 1e3;
    if dt > 0.0 {
        times.all_ms.push(dt);
    }
    let Some(frames) = run.frames else { return };
    let n = times.all_ms.len() as u32;
    if n == frames
        && let Some(path) = &run.screenshot
    {
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(path.clone()));
    }
    // Give the asynchronous screenshot a few frames to be written before exiting.
    if n == frames + 5 {
        if let Some(path) = &run.stats {
            let (gpu_pass_ms, diagnostics) = collect_diagnostics(&store);
            let stats = RunStats {
                name: run.name.clone(),
                size: [run.size.x, run.size.y],
                mode: "windowed".into(),
                adapter: crate::adapter::probe_adapter(),
                warmup_frames: 0,
                frame_time: FrameStats::from_millis(&times.all_ms[..frames as usize]),
                gpu_pass_ms,
                diagnostics,
            };
            if let Err(e) = crate::stats::write_atomically(path, &stats.to_json()) {
                error!("{e}");
            }
        }
        exit.write(AppExit::Success);
    }
}

fn draw_panel(world: &mut World) {
    let ctx = {
        let mut query = world.query_filtered::<&mut EguiContext, With<PrimaryEguiContext>>();
        match query.iter_mut(world).next() {
            Some(mut context) => context.get_mut().clone(),
            None => return,
        }
    };
    let name = world.resource::<PanelRun>().name.clone();
    let recent: Vec<f64> = {
        let times = world.resource::<WindowedFrameTimes>();
        let start = times.all_ms.len().saturating_sub(120);
        times.all_ms[start..].to_vec()
    };
    let frame = FrameStats::from_millis(&recent);
    let (gpu, diagnostics) = world
        .get_resource::<DiagnosticsStore>()
        .map(collect_diagnostics)
        .unwrap_or_default();
    world.resource_scope(|world, inspectors: Mut<Inspectors>| {
        egui::Window::new(format!("bevy_nature — {name}"))
            .default_width(320.0)
            .show(&ctx, |ui| {
                ui.label(format!(
                    "frame {:.2} ms median, {:.2} ms p95 ({:.0} fps)",
                    frame.median_ms,
                    frame.p95_ms,
                    if frame.median_ms > 0.0 {
                        1e3 / frame.median_ms
                    } else {
                        0.0
                    }
                ));
                egui::CollapsingHeader::new("plugin counters")
                    .default_open(true)
                    .show(ui, |ui| {
                        for (path, value) in diagnostics
                            .iter()
                            .filter(|(p, _)| !p.starts_with("render/"))
                        {
                            ui.label(format!("{path}: {value:.3}"));
                        }
                    });
                egui::CollapsingHeader::new("GPU pass times (ms)").show(ui, |ui| {
                    if gpu.is_empty() {
                        ui.label("no timestamp queries on this adapter");
                    }
                    for (pass, ms) in &gpu {
                        ui.label(format!("{pass}: {ms:.3}"));
                    }
                });
                for (title, draw) in &inspectors.0 {
                    egui::CollapsingHeader::new(*title)
                        .default_open(true)
                        .show(ui, |ui| draw(world, ui));
                }
            });
    });
}
