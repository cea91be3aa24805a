// Ray queries: one hit record per ray of a queue (RAYS.bin in, HITS.bin out), closest or any.
// Follows kdtree.wgsl, whose group 0 bindings 0-4 hold the tree.

@group(0) @binding(5) var<storage, read> rays: array<RayIn>;
@group(0) @binding(6) var<storage, read_write> hits: array<HitOut>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_closest(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < params.ray_count {
        hits[i] = trace(rays[i], false);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_any(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < params.ray_count {
        hits[i] = trace(rays[i], true);
    }
}

// The "if-if" loop (kdtree.wgsl's `trace_ifif`), one thread per ray.
@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_closest_ifif(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < params.ray_count {
        hits[i] = trace_ifif(rays[i], false);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_any_ifif(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < params.ray_count {
        hits[i] = trace_ifif(rays[i], true);
    }
}

// Persistent threads (Aila & Laine 2009): a fixed grid, sized to fill the GPU rather than one
// thread per ray, whose threads fetch the next ray from a global counter whenever they finish
// one, so that no thread idles behind a long ray of its workgroup while rays remain.
@group(0) @binding(7) var<storage, read_write> next_ray: atomic<u32>;

fn fetch_and_trace(any_hit: bool) {
    loop {
        let i = atomicAdd(&next_ray, 1u);
        if i >= params.ray_count {
            break;
        }
        hits[i] = trace(rays[i], any_hit);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_closest_persistent() {
    fetch_and_trace(false);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_any_persistent() {
    fetch_and_trace(true);
}

// The floor under every query kernel on these rays: no traversal, each thread reads its ray
// and writes a miss (u = 1 for an invalid ray, so that the whole ray is read). Bound with the
// query's bind group (the pipeline takes `intersect_closest`'s layout); its wall, kernel and
// streamed times are what a dispatch over the grid and its memory traffic cost, the rest of a
// query's time is the traversal's (`trace --stats` reports them as `floor`).
@compute @workgroup_size(WORKGROUP_SIZE)
fn query_floor(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < params.ray_count {
        var h = miss_record();
        h.u = select(0.0, 1.0, !ray_is_valid(rays[i]));
        hits[i] = h;
    }
}
