// The statistics query: `trace` as the fused kernel runs it, counting its work per ray and, with
// subgroup operations, how many lanes of each subgroup take part in each step (SIMD efficiency,
// Aila & Laine 2009). Follows kdtree.wgsl. naga takes the subgroup built-ins without `enable
// subgroups;` (it does not know that directive yet); the device needs wgpu's SUBGROUP feature.

@group(0) @binding(5) var<storage, read> rays: array<RayIn>;
@group(0) @binding(6) var<storage, read_write> hits: array<HitOut>;
// Every counter is 64 bits, a (low, high) pair of words carried by `add64`, so that one dispatch
// can count a whole 1080p ray set. Counters 0-2: steps of each kind (inner, leaf, triangle)
// summed over lanes; 3: triangles listed in the visited leaves; 4-6: active lanes summed over
// the subgroups' steps of each kind; 7-9: the subgroup size summed over the same steps (the
// lanes those steps could have used). Then single words at indices from the prelude (lib.rs):
// LIVE, the invocations between their entry and their exit now; PEAK, the most LIVE ever
// reached (the invocations the GPU held at once: achieved occupancy's peak); LANES, the
// subgroup size.
@group(0) @binding(7) var<storage, read_write> stats: array<atomic<u32>, STATS_WORDS>;

var<private> subgroup_lanes: u32;
var<private> lane_steps: array<u32, 4>;
var<private> active_lanes: array<u32, 3>;
var<private> lane_slots: array<u32, 3>;

fn stat(k: u32) {
    lane_steps[k] += 1u;
    // The lanes of this subgroup taking this step; the first of them (the only one before
    // which no lane counts) books the step.
    let taking = subgroupAdd(1u);
    if subgroupExclusiveAdd(1u) == 0u {
        active_lanes[k] += taking;
        lane_slots[k] += subgroup_lanes;
    }
}

fn stat_listed(n: u32) {
    lane_steps[3] += n;
}

// Adds `v` to 64-bit counter `k`: the high word takes the carry when the low one wraps.
fn add64(k: u32, v: u32) {
    if v != 0u {
        let old = atomicAdd(&stats[2u * k], v);
        if old > 0xffffffffu - v {
            atomicAdd(&stats[2u * k + 1u], 1u);
        }
    }
}

fn stats_query(gid: vec3<u32>, groups: vec3<u32>, lanes: u32, any_hit: bool, ifif: bool) {
    subgroup_lanes = lanes;
    // Residency: the lanes that arrive together are booked by the first of them, and booked
    // out likewise when they leave. Lanes that arrive or leave apart (independent thread
    // scheduling) are booked apart, so the count stays exact.
    let arriving = subgroupAdd(1u);
    if subgroupExclusiveAdd(1u) == 0u {
        atomicMax(&stats[PEAK], atomicAdd(&stats[LIVE], arriving) + arriving);
        atomicMax(&stats[LANES], lanes);
    }
    let i = ray_index(gid, groups);
    if i < params.ray_count {
        if ifif {
            hits[i] = trace_ifif(rays[i], any_hit);
        } else {
            hits[i] = trace(rays[i], any_hit);
        }
    }
    for (var k = 0u; k < 4u; k++) {
        add64(k, lane_steps[k]);
    }
    for (var k = 0u; k < 3u; k++) {
        add64(4u + k, active_lanes[k]);
        add64(7u + k, lane_slots[k]);
    }
    let leaving = subgroupAdd(1u);
    if subgroupExclusiveAdd(1u) == 0u {
        atomicSub(&stats[LIVE], leaving);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn stats_closest(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(subgroup_size) lanes: u32) {
    stats_query(gid, groups, lanes, false, false);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn stats_any(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(subgroup_size) lanes: u32) {
    stats_query(gid, groups, lanes, true, false);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn stats_closest_ifif(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(subgroup_size) lanes: u32) {
    stats_query(gid, groups, lanes, false, true);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn stats_any_ifif(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(subgroup_size) lanes: u32) {
    stats_query(gid, groups, lanes, true, true);
}
