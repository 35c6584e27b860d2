//! The render-world side of the blur's cell means: fixed-point prefix sums along rows or columns
//! of what a blur pass reads (`box_sums.wgsl`; CPU reference [`blur::line_sums`](super::blur::line_sums)),
//! so each spread tap reads the mean of its cell in two loads ([`kernel::tap_cell`](super::kernel::tap_cell)).

use bevy::asset::load_embedded_asset;
use bevy::prelude::*;
use bevy::render::render_resource::binding_types::{texture_2d, texture_storage_2d};
use bevy::render::render_resource::*;
use bevy::render::renderer::RenderDevice;
use bevy::render::texture::{CachedTexture, TextureCache};

/// The two compute pipelines and their layout.
#[derive(Resource)]
pub(super) struct BoxSumsPipelines {
    layout: BindGroupLayoutDescriptor,
    rows: CachedComputePipelineId,
    columns: CachedComputePipelineId,
}

pub(super) fn init_box_sums_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "ssss_box_sums_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_storage_2d(TextureFormat::R32Uint, StorageTextureAccess::WriteOnly),
            ),
        ),
    );
    let shader = load_embedded_asset!(asset_server.as_ref(), "box_sums.wgsl");
    let queue = |entry: &'static str| {
        pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("ssss_{entry}").into()),
            layout: vec![layout.clone()],
            shader: shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    };
    let rows = queue("row_sums");
    let columns = queue("column_sums");
    commands.insert_resource(BoxSumsPipelines {
        layout,
        rows,
        columns,
    });
}

/// The prefix sums of one view: along rows, `(width + 1) × height`, for the horizontal pass;
/// along columns, `width × (height + 1)`, for the vertical one.
pub(super) struct LineSums {
    pub rows: CachedTexture,
    pub columns: CachedTexture,
}

/// The sum textures for a `size` screen (cached across frames).
pub(super) fn line_sum_textures(
    device: &RenderDevice,
    cache: &mut TextureCache,
    size: UVec2,
) -> LineSums {
    let mut get = |label: &'static str, width: u32, height: u32| {
        cache.get(
            device,
            TextureDescriptor {
                label: Some(label),
                size: Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: TextureDimension::D2,
                format: TextureFormat::R32Uint,
                usage: TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
        )
    };
    LineSums {
        rows: get("ssss_row_sums", size.x + 1, size.y),
        columns: get("ssss_column_sums", size.x, size.y + 1),
    }
}

/// Records the sums of `source.r` along rows (`horizontal`) or columns into `sums` (one line per
/// row of the row sums, per column of the column sums) as one compute pass. Does nothing while
/// the pipelines compile (then the blur passes wait too).
pub(super) fn encode_line_sums(
    encoder: &mut CommandEncoder,
    device: &RenderDevice,
    pipelines: &BoxSumsPipelines,
    pipeline_cache: &PipelineCache,
    source: &TextureView,
    sums: &CachedTexture,
    horizontal: bool,
) {
    let lines = if horizontal {
        sums.texture.height()
    } else {
        sums.texture.width()
    };
    let id = if horizontal {
        pipelines.rows
    } else {
        pipelines.columns
    };
    let Some(pipeline) = pipeline_cache.get_compute_pipeline(id) else {
        return;
    };
    let group = device.create_bind_group(
        "ssss_box_sums",
        &pipeline_cache.get_bind_group_layout(&pipelines.layout),
        &BindGroupEntries::sequential((source, &sums.default_view)),
    );
    let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
        label: Some(if horizontal {
            "ssss_row_sums"
        } else {
            "ssss_column_sums"
        }),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, &group, &[]);
    pass.dispatch_workgroups(lines.div_ceil(64), 1, 1);
}

/// Whether both pipelines are ready (the blur passes need their sums).
pub(super) fn box_sums_ready(pipelines: &BoxSumsPipelines, pipeline_cache: &PipelineCache) -> bool {
    pipeline_cache
        .get_compute_pipeline(pipelines.rows)
        .is_some()
        && pipeline_cache
            .get_compute_pipeline(pipelines.columns)
            .is_some()
}
