//! `--kernels split`: ray queries with traversal and intersection in separate kernels
//! (`kernels/split.wgsl`), the layout of the paper. Traversal writes one (ray, leaf) work item
//! per active ray; the intersection kernel tests the leaf and sends unfinished rays back to the
//! other active list. The host repeats the pair, [`ITERATIONS_PER_SUBMIT`] leaf steps per
//! submission with indirect dispatch, until no ray is active (or the tree's step bound).

use crate::{GpuContext, GpuError, GpuTracer, kdtree_wgsl, read_words};

const SPLIT_WGSL: &str = include_str!("kernels/split.wgsl");

/// Leaf steps recorded per submission between reads of the active count.
pub const ITERATIONS_PER_SUBMIT: u32 = 16;

/// The WGSL source of the split kernels.
pub fn split_wgsl() -> String {
    format!("{}\n{SPLIT_WGSL}", kdtree_wgsl())
}

/// The split pipelines of one tracer (built on first use).
pub(crate) struct SplitKernels {
    layouts: [wgpu::BindGroupLayout; 3],
    init: wgpu::ComputePipeline,
    traverse: wgpu::ComputePipeline,
    /// Closest, any.
    intersect: [wgpu::ComputePipeline; 2],
    advance: wgpu::ComputePipeline,
}

impl SplitKernels {
    pub(crate) fn new(ctx: &GpuContext) -> SplitKernels {
        use wgpu::BufferBindingType::{Storage, Uniform};
        let ro = Storage { read_only: true };
        let rw = Storage { read_only: false };
        let layouts = [
            ctx.buffer_layout("split tree and rays", &[Uniform, ro, ro, ro, ro, rw]),
            ctx.buffer_layout("split lists", &[rw; 5]),
            ctx.buffer_layout("split args", &[rw]),
        ];
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("split.wgsl"),
                source: wgpu::ShaderSource::Wgsl(split_wgsl().into()),
            });
        let pipeline_layout = |groups: usize| {
            let l: Vec<_> = layouts[..groups].iter().map(Some).collect();
            ctx.device
                .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("split"),
                    bind_group_layouts: &l,
                    immediate_size: 0,
                })
        };
        let (work, control) = (pipeline_layout(2), pipeline_layout(3));
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1) as f64;
        let pipeline = |name: &str, layout: &wgpu::PipelineLayout, any: bool| {
            let constants = [("ANY_HIT", any as u32 as f64), ("MAX_GROUPS", max_groups)];
            ctx.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(name),
                    layout: Some(layout),
                    module: &module,
                    entry_point: Some(name),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &constants,
                        ..Default::default()
                    },
                    cache: None,
                })
        };
        SplitKernels {
            init: pipeline("split_init", &work, false),
            traverse: pipeline("split_traverse", &work, false),
            intersect: [
                pipeline("split_intersect", &work, false),
                pipeline("split_intersect", &work, true),
            ],
            advance: pipeline("split_advance", &control, false),
            layouts,
        }
    }
}

/// What a split query did: leaf steps run, and the kernels' own time (timestamps), summed.
pub(crate) struct SplitRun {
    pub steps: u32,
    pub kernel_gpu_ms: Option<f64>,
}

/// Runs the split kernels over `n` rays in `rays` (with their `params`), writing `hits`.
pub(crate) fn run(
    tracer: &GpuTracer,
    params: &wgpu::Buffer,
    rays: &wgpu::Buffer,
    hits: &wgpu::Buffer,
    n: u32,
    any: bool,
) -> Result<SplitRun, GpuError> {
    let ctx = tracer.ctx;
    let k = tracer.split_kernels();
    let list =
        |what: &'static str, bytes: u64| ctx.work_buffer(what, bytes, wgpu::BufferUsages::empty());
    let state = list("split ray states", n as u64 * 8)?;
    let lists = [
        list("active rays", n as u64 * 4)?,
        list("active rays", n as u64 * 4)?,
    ];
    let items = list("work items", n as u64 * 8)?;
    let counts = list("active counts", 8)?;
    let args = ctx.work_buffer("split dispatch arguments", 12, wgpu::BufferUsages::INDIRECT)?;
    let counts_read = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("active count readback"),
        size: 8 + 16,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let timer = ctx.timer(2);
    let group0 = ctx.bind_buffers(
        "split",
        &k.layouts[0],
        &[
            params,
            &tracer.inners,
            &tracer.leaves,
            &tracer.tris,
            rays,
            hits,
        ],
    );
    // Lists: [active, next] and the swapped pair.
    let group1 = [0, 1].map(|a| {
        ctx.bind_buffers(
            "split",
            &k.layouts[1],
            &[&state, &lists[a], &items, &lists[1 - a], &counts],
        )
    });
    let group2 = ctx.bind_buffers("split args", &k.layouts[2], &[&args]);
    let stamp = |first: bool, last: bool| {
        let t = timer.as_ref().filter(|_| first || last)?;
        Some(t.writes(first.then_some(0), last.then_some(1)))
    };
    let mut steps = 0u32;
    let mut gpu_ms = 0.0;
    let mut timed = timer.is_some();
    let mut cur = 0usize;
    let mut submitted_init = false;
    loop {
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("split"),
            });
        let mut first = true;
        if !submitted_init {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("split_init"),
                timestamp_writes: stamp(true, false),
            });
            pass.set_pipeline(&k.init);
            pass.set_bind_group(0, &group0, &[]);
            pass.set_bind_group(1, &group1[cur], &[]);
            let [gx, gy, _] = ctx.dims(n);
            pass.dispatch_workgroups(gx, gy, 1);
            drop(pass);
            first = false;
            submitted_init = true;
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("split_advance"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&k.advance);
            pass.set_bind_group(0, &group0, &[]);
            pass.set_bind_group(1, &group1[cur], &[]);
            pass.set_bind_group(2, &group2, &[]);
            pass.dispatch_workgroups(1, 1, 1);
            drop(pass);
            cur = 1 - cur;
        }
        let batch = ITERATIONS_PER_SUBMIT.min(tracer.params.max_steps - steps);
        for it in 0..batch {
            for (p, name) in [
                (&k.traverse, "split_traverse"),
                (&k.intersect[any as usize], "split_intersect"),
            ] {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(name),
                    timestamp_writes: stamp(first, false),
                });
                first = false;
                pass.set_pipeline(p);
                pass.set_bind_group(0, &group0, &[]);
                pass.set_bind_group(1, &group1[cur], &[]);
                pass.dispatch_workgroups_indirect(&args, 0);
            }
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("split_advance"),
                timestamp_writes: stamp(false, it + 1 == batch),
            });
            pass.set_pipeline(&k.advance);
            pass.set_bind_group(0, &group0, &[]);
            pass.set_bind_group(1, &group1[cur], &[]);
            pass.set_bind_group(2, &group2, &[]);
            pass.dispatch_workgroups(1, 1, 1);
            drop(pass);
            cur = 1 - cur;
        }
        steps += batch;
        enc.copy_buffer_to_buffer(&counts, 0, &counts_read, 0, 8);
        if let Some(t) = &timer {
            enc.resolve_query_set(&t.set, 0..2, &t.resolve, 0);
            enc.copy_buffer_to_buffer(&t.resolve, 0, &counts_read, 8, 16);
        }
        ctx.queue.submit([enc.finish()]);
        let words = read_words(ctx, &counts_read)?;
        if timed {
            let t0 = words[2] as u64 | (words[3] as u64) << 32;
            let t1 = words[4] as u64 | (words[5] as u64) << 32;
            let ticks = t1.wrapping_sub(t0);
            timed = ticks > 0;
            gpu_ms += ticks as f64 * ctx.queue.get_timestamp_period() as f64 * 1e-6;
        }
        if words[0] == 0 || steps >= tracer.params.max_steps {
            break;
        }
    }
    Ok(SplitRun {
        steps,
        kernel_gpu_ms: timed.then_some(gpu_ms),
    })
}
