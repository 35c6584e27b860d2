//! The filtered shadow maps' visibility functions on the GPU (`filterable_visibility.wgsl`, run
//! by a compute shader on the adapter at hand) against their CPU references
//! (`filterable::visibility`), over the statistics of random occluder spreads and receivers in
//! front of, inside and behind them.

use bevy::render::RenderApp;
use bevy::render::render_resource::{BufferDescriptor, BufferUsages};
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::headless::read_buffer_now;
use bevy_soft_shadows::filterable::visibility::{
    chebyshev, exponential, exponential_moment, gaussian_cdf, hamburger_msm, mean_range, moments2,
    moments4, power_cdf,
};

const MODULE: &str = include_str!("../src/filterable/filterable_visibility.wgsl");

/// Each case: the statistics one texel would hold and a receiver depth; each result: the five
/// visibilities.
const ENTRY: &str = r#"
struct Case {
    m4: vec4<f32>,
    m2: vec4<f32>,
    // (mean, min, max, E[e^{c·z}])
    range: vec4<f32>,
    // (zr, c, 0, 0)
    params: vec4<f32>,
}
@group(0) @binding(0) var<storage, read> cases: array<Case>;
@group(0) @binding(1) var<storage, read_write> results: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&cases) {
        return;
    }
    let k = cases[i];
    let zr = k.params.x;
    results[2u * i] = vec4(
        chebyshev(k.m2.xy, zr, 1e-6),
        gaussian_cdf(k.m2.xy, zr, 1e-6),
        power_cdf(k.range.xyz, zr),
        exponential(k.range.w, zr, k.params.y),
    );
    results[2u * i + 1u] = vec4(hamburger_msm(k.m4, zr, 3e-5), 0.0, 0.0, 0.0);
}
"#;

/// SplitMix64: seeded uniforms.
fn uniforms(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[test]
fn the_gpu_visibility_functions_match_their_cpu_references() {
    let Some(mut harness) = RenderHarness::for_test("filterable_visibility", 8, 8) else {
        return;
    };
    // The renderer (and its device) is up once the app has run a frame.
    harness.step();
    let c = 80.0f32;
    // Occluder spreads (a few depths, or a normal-ish cluster), receivers swept across them.
    let mut next = uniforms(29);
    let mut cases: Vec<[f32; 16]> = Vec::new();
    let mut expected: Vec<[f32; 5]> = Vec::new();
    for _ in 0..200 {
        let centre = 0.15 + 0.7 * next();
        let spread = 0.2 * next();
        let n = 1 + (next() * 12.0) as usize;
        let depths: Vec<(f32, f32)> = (0..n)
            .map(|_| {
                (
                    (centre + spread * (next() - 0.5)).clamp(0.0, 1.0),
                    0.2 + next(),
                )
            })
            .collect();
        let (m2, m4, s, e) = (
            moments2(&depths),
            moments4(&depths),
            mean_range(&depths),
            exponential_moment(&depths, c),
        );
        for k in 0..24 {
            let zr = (centre - spread + 2.5 * spread * k as f32 / 23.0 + 0.02).clamp(0.0, 1.0);
            cases.push([
                m4[0], m4[1], m4[2], m4[3], m2[0], m2[1], 0.0, 0.0, s[0], s[1], s[2], e, zr, c,
                0.0, 0.0,
            ]);
            expected.push([
                chebyshev(m2, zr, 1e-6),
                gaussian_cdf(m2, zr, 1e-6),
                power_cdf(s, zr),
                exponential(e, zr, c),
                hamburger_msm(m4, zr, 3e-5),
            ]);
        }
    }
    let render_world = harness.app().get_sub_app(RenderApp).unwrap().world();
    let device = render_world.resource::<RenderDevice>();
    let queue = render_world.resource::<RenderQueue>();
    let raw = device.wgpu_device();
    let source = MODULE
        .lines()
        .filter(|l| !l.starts_with("#define_import_path"))
        .collect::<Vec<_>>()
        .join("\n")
        + ENTRY;
    let module = raw.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("filterable_visibility_test"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = raw.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("filterable_visibility_test"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let input: Vec<u8> = cases
        .iter()
        .flat_map(|c| c.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    let cases_buffer = device.create_buffer_with_data(&wgpu::util::BufferInitDescriptor {
        label: Some("filterable_visibility_cases"),
        contents: &input,
        usage: BufferUsages::STORAGE,
    });
    let results = device.create_buffer(&BufferDescriptor {
        label: Some("filterable_visibility_results"),
        size: (cases.len() * 32) as u64,
        usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let bind_group = raw.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("filterable_visibility_test"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: cases_buffer.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: results.as_entire_binding(),
            },
        ],
    });
    let mut encoder = raw.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("filterable_visibility_test"),
    });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((cases.len() as u32).div_ceil(64), 1, 1);
    }
    queue.submit([encoder.finish()]);
    let bytes = read_buffer_now(device, queue, &results).expect("results");
    let got: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let names = [
        "chebyshev",
        "gaussian_cdf",
        "power_cdf",
        "exponential",
        "hamburger_msm",
    ];
    let mut worst = [0.0f32; 5];
    let mut off = [0usize; 5];
    for (i, want) in expected.iter().enumerate() {
        let gpu = [
            got[8 * i],
            got[8 * i + 1],
            got[8 * i + 2],
            got[8 * i + 3],
            got[8 * i + 4],
        ];
        for m in 0..5 {
            let d = (gpu[m] - want[m]).abs();
            worst[m] = worst[m].max(d);
            // f32 on the GPU against the CPU's f32 (f64 for four moments, whose Cholesky
            // factors lose digits in f32 on tight spreads: 0.005 at worst here).
            let tolerance = if m == 4 { 0.01 } else { 5e-5 };
            if d > tolerance {
                off[m] += 1;
            }
        }
    }
    eprintln!(
        "{} cases; worst differences {:?}; over tolerance {:?}",
        expected.len(),
        names.iter().zip(worst).collect::<Vec<_>>(),
        off
    );
    for (m, name) in names.iter().enumerate() {
        assert_eq!(off[m], 0, "{name}: worst {}", worst[m]);
    }
}
