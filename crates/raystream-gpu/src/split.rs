//! `--kernels split`: ray queries with traversal and intersection in separate kernels
//! (`kernels/split.wgsl`), the layout of the paper. Traversal writes one (ray, leaf) work item
//! per active ray; the intersection kernel tests the leaf and sends unfinished rays back to the
//! other active list. The host repeats the pair with indirect dispatch,
//! [`ITERATIONS_PER_SUBMIT`] leaf steps a submission, until no ray is active (or the tree's
//! step bound). It keeps one submission queued ahead of the one whose active count it reads,
//! so that the GPU does not wait for the host between them; steps recorded after the last ray
//! finished dispatch nothing. (Submissions growing twice as long each time, to need fewer, were
//! tried: they record up to 4x the steps needed, and the empty passes made queries 1.3-2.5x
//! slower on lavapipe: BENCHMARKS.md.)

use std::collections::VecDeque;

use crate::{GpuContext, GpuError, GpuTracer, kdtree_wgsl, read_back_after, u64_at};

const SPLIT_WGSL: &str = include_str!("kernels/split.wgsl");

/// Leaf steps recorded per submission.
pub const ITERATIONS_PER_SUBMIT: u32 = 16;

/// The WGSL source of the split kernels; `subgroup_appends`: their lists' slots reserved a
/// subgroup at a time ([`crate::GpuContext::set_subgroup_appends`]; the device needs wgpu's
/// SUBGROUP feature).
pub fn split_wgsl(subgroup_appends: bool) -> String {
    format!(
        "{}\n{SPLIT_WGSL}\n{}",
        kdtree_wgsl(),
        crate::append_wgsl(subgroup_appends, "counts")
    )
}

/// The split pipelines of one tracer (built on first use).
pub(crate) struct SplitKernels {
    layouts: [wgpu::BindGroupLayout; 3],
    init: wgpu::ComputePipeline,
    pub(crate) traverse: wgpu::ComputePipeline,
    /// Closest, any.
    intersect: [wgpu::ComputePipeline; 2],
    advance: wgpu::ComputePipeline,
}

impl SplitKernels {
    pub(crate) fn new(ctx: &GpuContext) -> SplitKernels {
        let rw = wgpu::BufferBindingType::Storage { read_only: false };
        let layouts = [
            ctx.query_layout("split tree and rays"),
            ctx.buffer_layout("split lists", &[rw; 5]),
            ctx.buffer_layout("split args", &[rw]),
        ];
        let module = ctx.tree_module("split.wgsl", split_wgsl(ctx.subgroup_appends()), false);
        let [tree, lists, args] = &layouts;
        let work = ctx.pipeline_layout("split", &[tree, lists]);
        let control = ctx.pipeline_layout("split", &[tree, lists, args]);
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1) as f64;
        let pipeline = |name: &str, layout: &wgpu::PipelineLayout, any: bool| {
            let constants = [("ANY_HIT", any as u32 as f64), ("MAX_GROUPS", max_groups)];
            ctx.layout_pipeline(&module, name, layout, &constants)
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

/// What a split query did: leaf steps run with rays in them (the most leaves any one ray
/// visited), and the kernels' own time (timestamps), summed over the submissions.
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
    let counts = list("active counts", 12)?;
    let args = ctx.work_buffer("split dispatch arguments", 12, wgpu::BufferUsages::INDIRECT)?;
    // The counts (12 bytes, padded to 16), then the two timestamps; two, so that the host reads
    // one submission's while the GPU runs the next.
    let counts_read = [0, 1].map(|_| {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("active count readback"),
            size: 16 + 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
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
            &tracer.entry,
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
    // `split_advance`: the other list becomes the active one.
    let advance = |enc: &mut wgpu::CommandEncoder,
                   cur: &mut usize,
                   timestamp_writes: Option<wgpu::ComputePassTimestampWrites>| {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("split_advance"),
            timestamp_writes,
        });
        pass.set_pipeline(&k.advance);
        pass.set_bind_group(0, &group0, &[]);
        pass.set_bind_group(1, &group1[*cur], &[]);
        pass.set_bind_group(2, &group2, &[]);
        pass.dispatch_workgroups(1, 1, 1);
        *cur = 1 - *cur;
    };
    let max_steps = tracer.params.max_steps;
    let mut steps = 0u32;
    let mut gpu_ms = 0.0;
    // Whether any submission's stamps differ: some adapters write equal ones (no measurement
    // rather than a false 0), and a submission of finished steps may take no time.
    let mut timed = false;
    let mut cur = 0usize;
    let mut recorded = 0u32;
    // Submissions whose counts are not read yet, oldest first: (readback slot, submission).
    let mut in_flight = VecDeque::new();
    let mut slot = 0usize;
    // Set once a readback shows no active ray, or every step the tree allows is recorded.
    let mut done = false;
    while !(done && in_flight.is_empty()) {
        if !done {
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("split"),
                });
            let mut first = true;
            // The first submission starts with `split_init`.
            if recorded == 0 {
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
                advance(&mut enc, &mut cur, None);
            }
            let batch = ITERATIONS_PER_SUBMIT.min(max_steps - recorded);
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
                advance(&mut enc, &mut cur, stamp(false, it + 1 == batch));
            }
            recorded += batch;
            enc.copy_buffer_to_buffer(&counts, 0, &counts_read[slot], 0, 12);
            if let Some(t) = &timer {
                enc.resolve_query_set(&t.set, 0..2, &t.resolve, 0);
                enc.copy_buffer_to_buffer(&t.resolve, 0, &counts_read[slot], 16, 16);
            }
            in_flight.push_back((slot, ctx.queue.submit([enc.finish()])));
            slot = 1 - slot;
            done = recorded >= max_steps;
            // Keep one submission queued ahead of the one read.
            if in_flight.len() < 2 && !done {
                continue;
            }
        }
        let (s, index) = in_flight.pop_front().expect("a submission in flight");
        let words: Vec<u32> = read_back_after(ctx, &counts_read[s], Some(index))?;
        if timer.is_some() {
            // The stamps after the 16 bytes of counts.
            let ticks = u64_at(&words, 3).wrapping_sub(u64_at(&words, 2));
            timed |= ticks > 0;
            gpu_ms += ticks as f64 * ctx.queue.get_timestamp_period() as f64 * 1e-6;
        }
        steps = words[2];
        done |= words[0] == 0;
    }
    Ok(SplitRun {
        steps,
        kernel_gpu_ms: timed.then_some(gpu_ms),
    })
}
