// Ray queries with traversal and intersection in separate kernels, as the paper lays them out
// (`--kernels split`). Follows kdtree.wgsl (group 0 bindings 0-4: the tree).
//
//   split_init:      clip every ray to the scene; those that enter go to the next list
//   split_traverse:  descend each active ray to its next leaf → a (ray, leaf) work item
//   split_intersect: test the leaf's triangles, follow the rope; unfinished rays go back to
//                    the other active list
//   split_advance:   the other list becomes the active one; dispatch arguments for it
//
// The host repeats traverse → intersect → advance, swapping the two lists, until no ray is
// active (steps recorded after that dispatch nothing). Each active ray yields exactly one work
// item, so item k belongs to list entry k.

struct RayState {
    t_entry: f32,
    node: u32,
}

struct WorkItem {
    ray: u32,
    leaf: u32,
}

@group(0) @binding(5) var<storage, read> rays: array<RayIn>;
@group(0) @binding(6) var<storage, read_write> hits: array<HitOut>;
@group(1) @binding(0) var<storage, read_write> state: array<RayState>;
@group(1) @binding(1) var<storage, read_write> live: array<u32>;
@group(1) @binding(2) var<storage, read_write> items: array<WorkItem>;
@group(1) @binding(3) var<storage, read_write> next_live: array<u32>;
// [0] active rays, [1] rays appended to next_live, [2] leaf steps with rays in them.
@group(1) @binding(4) var<storage, read_write> counts: array<atomic<u32>, 3>;
// Only split_advance binds it: the other kernels are dispatched from it.
@group(2) @binding(0) var<storage, read_write> args: array<u32, 3>;

// 0 = closest hit, 1 = any hit.
override ANY_HIT: u32 = 0u;
// The device's largest workgroup count per dispatch dimension.
override MAX_GROUPS: u32 = 65535u;

@compute @workgroup_size(WORKGROUP_SIZE)
fn split_init(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i >= params.ray_count {
        return;
    }
    let r = rays[i];
    hits[i] = miss_record();
    let w = walk_of(r);
    let span = clip_to_scene(r, w);
    // Into the list that the first split_advance makes the active one (`append`, from the
    // Rust prelude, may reserve a subgroup's slots at once: every lane calls it).
    let enters = span.x <= span.y;
    let at = append(1u, select(0u, 1u, enters));
    if enters {
        state[i] = RayState(span.x, entry_node(w, span.x));
        next_live[at] = i;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn split_traverse(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = ray_index(gid, groups);
    if k >= atomicLoad(&counts[0]) {
        return;
    }
    let i = live[k];
    let s = state[i];
    items[k] = WorkItem(i, descend(s.node, walk_of(rays[i]), s.t_entry));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn split_intersect(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = ray_index(gid, groups);
    if k >= atomicLoad(&counts[0]) {
        return;
    }
    let item = items[k];
    let i = item.ray;
    let r = rays[i];
    let w = walk_of(r);
    let li = item.leaf & ~LEAF_BIT;
    var best = hits[i];
    let any_hit = ANY_HIT != 0u;
    // An any-hit query ends at its first hit.
    var done = false;
    if intersect_leaf(li, r, w, any_hit, &best) {
        hits[i] = best;
        done = any_hit;
    }
    var exit = Exit(0.0, NO_ROPE);
    if !done {
        exit = leaf_exit(li, w, best, r.t_max);
    }
    // Unfinished rays back to the other list; every lane calls `append` (see split_init).
    let goes_on = exit.next != NO_ROPE;
    let at = append(1u, select(0u, 1u, goes_on));
    if goes_on {
        state[i] = RayState(max(state[i].t_entry, exit.t), exit.next);
        next_live[at] = i;
    }
}

@compute @workgroup_size(1)
fn split_advance() {
    let n = atomicLoad(&counts[1]);
    atomicStore(&counts[0], n);
    atomicStore(&counts[1], 0u);
    if n > 0u {
        atomicAdd(&counts[2], 1u);
    }
    let g = (n + WORKGROUP_SIZE - 1u) / WORKGROUP_SIZE;
    let gx = min(g, MAX_GROUPS);
    var gy = 0u;
    if gx > 0u {
        gy = (g + gx - 1u) / gx;
    }
    args[0] = gx;
    args[1] = gy;
    args[2] = 1u;
}
