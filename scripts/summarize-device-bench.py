#!/usr/bin/env python3
"""Turns what scripts/device-bench.sh wrote (results.jsonl, render.log) into BENCHMARKS.md's
tables, so that a session with a device spends its minutes measuring, not tabulating.

    scripts/summarize-device-bench.py OUT/results.jsonl [--render OUT/render.log] [--sms 132]

Prints Markdown: the ray-query table against the issue's peers (Grays/s by single-query wall
time, kernel time and streamed queries, with the first bar -- at least half the best GPU peer --
judged by each), the variants (spinning waits, if-if, leaf size, split, sorted sets, bench's
own sets), two binaries alternated (the ab part), where a query's wall time goes (the floor
kernel beside each query run with --stats), divergence and occupancy (peak resident invocations over SMs x 2048), failed
rays.py checks, the render frame rates of each `--submit` mode, the volume modes' orbits
(dvr, mip, cinematic: `bench VOLUME --mode`), and render.log's cinematic pictures (the frame's
time, and what a denoised one's guides and filter took). Only the standard library.
"""

import argparse
import json
import os
import re
import statistics
import sys
from collections import defaultdict

# The issue's peers on the H100 (Grays/s): OptiX via Mitsuba 3, NVIDIA Warp 1.5.
PEERS = {
    "stanford_bunny": {"primary": (3.26, 1.78), "diffuse": (1.10, 0.31), "shadow": (2.05, 0.34)},
    "stanford_lucy_100k": {"primary": (3.62, 5.24), "diffuse": (0.86, 0.74), "shadow": (2.34, 1.29)},
    "turbine_blade": {"primary": (4.12, 6.77), "diffuse": (1.31, 1.29), "shadow": (3.58, 3.48)},
}
KINDS = ["primary", "diffuse", "shadow", "random"]


def grays(rays, ms):
    """Grays/s of `rays` rays in `ms` milliseconds (None where either is missing)."""
    if not rays or not ms:
        return None
    return rays / (ms * 1e-3) / 1e9


def fmt(x):
    """Three significant digits (2.25, 0.109), or a dash for no figure."""
    return "–" if x is None else f"{x:.3g}"


def load(path):
    lines = []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line:
                continue
            try:
                lines.append(json.loads(line))
            except json.JSONDecodeError as e:
                sys.exit(f"{path}:{n}: not a JSON line: {e}")
    return lines


def index(lines):
    """Trace lines by (mesh, kind, variant): variant names the tracer and its options."""
    by = {}
    for o in lines:
        tracer = o.get("tracer")
        if not tracer or "kind" not in o or "rays" not in o or "entry_grid_res" in o or "binary" in o \
                or o.get("part") == "floor":
            continue
        variant = tracer
        if o.get("rays_from") == "bench":
            variant += " (bench's set)"
        elif o.get("order"):
            variant += f" ({o['order']})"
        elif tracer == "raystream-gpu-fused" and o.get("sah_traversal_cost", 1) not in (1, 1.0):
            variant += f" (K={o['sah_traversal_cost']:g})"
        elif tracer == "raystream-gpu-fused" and o.get("query_workgroup", 64) != 64:
            variant += f" ({o['query_workgroup']} threads a workgroup)"
        by[(o["mesh"], o["kind"], variant)] = o
    return by


def query_table(by, out):
    meshes = sorted({m for m, _, _ in by})
    if not meshes:
        return
    out.append("| mesh | rays | count | GPU wall | GPU kernel | GPU streamed | OptiX | Warp | "
               "½ best GPU peer | bar by wall | by streamed | by kernel | CPU | Embree | GPU wall / CPU |")
    out.append("|" + "---|" * 15)
    verdicts = defaultdict(list)
    for m in meshes:
        for k in KINDS:
            g = by.get((m, k, "raystream-gpu-fused"))
            if not g:
                continue
            n = g["rays"]
            wall = grays(n, g.get("trace_ms"))
            kern = grays(n, g.get("gpu_kernel_ms"))
            stream = grays(n, g.get("stream_ms"))
            cpu = by.get((m, k, "raystream-cpu"))
            emb = by.get((m, k, "embree"))
            cpu_g = grays(n, cpu and cpu.get("trace_ms"))
            emb_g = grays(n, emb and emb.get("trace_ms"))
            peers = PEERS.get(m, {}).get(k)
            half = max(peers) / 2 if peers else None
            cells = []
            for name, x in [("wall", wall), ("streamed", stream), ("kernel", kern)]:
                if half is None or x is None:
                    cells.append("–")
                    continue
                ok = x >= half
                verdicts[name].append(ok)
                cells.append("met" if ok else "**missed**")
            ratio = f"{wall / cpu_g:.2g}×" if wall and cpu_g else "–"
            out.append(
                f"| {m} | {k} | {n:,} | {fmt(wall)} | {fmt(kern)} | {fmt(stream)} | "
                f"{fmt(peers and peers[0])} | {fmt(peers and peers[1])} | {fmt(half)} | "
                f"{' | '.join(cells)} | {fmt(cpu_g)} | {fmt(emb_g)} | {ratio} |"
            )
    out.append("")
    for name in ["wall", "streamed", "kernel"]:
        v = verdicts[name]
        if v:
            out.append(f"- First bar by {name} time: met on {sum(v)} of {len(v)} rows.")
    out.append("")


def variants_table(by, out):
    """Each variant's Grays/s (kernel time where stamped, else wall) beside the fused kernel's."""
    base = {(m, k): o for (m, k, v), o in by.items() if v == "raystream-gpu-fused"}
    rows = []
    for (m, k, v), o in sorted(by.items()):
        if v in ("raystream-gpu-fused", "raystream-cpu", "embree") or (m, k) not in base:
            continue
        b = base[(m, k)]
        n = o["rays"]
        row = (m, k, v, grays(n, o.get("trace_ms")), grays(n, o.get("gpu_kernel_ms")),
               grays(b["rays"], b.get("trace_ms")), grays(b["rays"], b.get("gpu_kernel_ms")),
               o.get("split_steps"))
        rows.append(row)
    if not rows:
        return
    out.append("| mesh | rays | variant | wall | kernel | fused wall | fused kernel | wall / fused | "
               "kernel / fused | split steps |")
    out.append("|" + "---|" * 10)
    for m, k, v, w, kn, bw, bk, steps in rows:
        ratio = lambda x, y: f"{x / y:.2f}" if x and y else "–"  # noqa: E731
        out.append(f"| {m} | {k} | {v} | {fmt(w)} | {fmt(kn)} | {fmt(bw)} | {fmt(bk)} | "
                   f"{ratio(w, bw)} | {ratio(kn, bk)} | {'–' if steps is None else steps} |")
    out.append("")


def entry_table(lines, out):
    """The entry grid's sizes side by side (device-bench.sh's entry part): kernel Grays/s of each
    round, wall Grays/s of the fastest round, and traversal steps per ray where counted."""
    runs = defaultdict(lambda: defaultdict(list))
    steps = {}
    for o in lines:
        res = o.get("entry_grid_res")
        if res is None or "rays" not in o:
            continue
        runs[(o["mesh"], o["kind"])][res].append(o)
        st = (o.get("gpu_stats") or {}).get("steps_per_ray", {}).get("traversal")
        if st is not None:
            steps[(o["mesh"], o["kind"], res)] = st
    if not runs:
        return
    out.append("| mesh | rays | entry grid | kernel, each round | wall (best) | inner steps a ray | "
               "kernel / no grid |")
    out.append("|" + "---|" * 7)
    for (m, k), by_res in sorted(runs.items()):
        def best_kernel(res):
            g = [grays(o["rays"], o.get("gpu_kernel_ms")) for o in by_res.get(res, [])]
            g = [x for x in g if x]
            return max(g) if g else None
        base = best_kernel(0)
        for res in sorted(by_res):
            os_ = by_res[res]
            kern = ", ".join(fmt(grays(o["rays"], o.get("gpu_kernel_ms"))) for o in os_)
            wall = max((grays(o["rays"], o.get("trace_ms")) or 0) for o in os_) or None
            b = best_kernel(res)
            ratio = f"{b / base:.2f}" if b and base else "–"
            st = steps.get((m, k, res))
            out.append(f"| {m} | {k} | {res or 'none'} | {kern} | {fmt(wall)} | "
                       f"{'–' if st is None else fmt(st)} | {ratio} |")
    out.append("")


def ab_table(lines, out):
    """Two binaries alternated (device-bench.sh's ab part, lines tagged "binary": "base" or
    "new"): kernel Grays/s of each round, wall Grays/s of the fastest, and new over base by the
    best round of each."""
    runs = defaultdict(lambda: defaultdict(list))
    for o in lines:
        if o.get("binary") in ("base", "new") and o.get("tracer") and "rays" in o and "kind" in o:
            runs[(o["mesh"], o["kind"])][o["binary"]].append(o)
    if not runs:
        return
    out.append("| mesh | rays | base kernel, each round | new kernel, each round | base wall (best) | "
               "new wall (best) | kernel new / base | wall new / base |")
    out.append("|" + "---|" * 8)
    order = lambda mk: (mk[0], KINDS.index(mk[1]) if mk[1] in KINDS else len(KINDS))  # noqa: E731
    for (m, k) in sorted(runs, key=order):
        by_bin = runs[(m, k)]
        def each(which, key):
            return [grays(o["rays"], o.get(key)) for o in by_bin.get(which, [])]
        def best(which, key):
            g = [x for x in each(which, key) if x]
            return max(g) if g else None
        ratio = lambda x, y: f"{x / y:.2f}" if x and y else "–"  # noqa: E731
        kern = {w: ", ".join(fmt(x) for x in each(w, "gpu_kernel_ms")) or "–" for w in ("base", "new")}
        out.append(f"| {m} | {k} | {kern['base']} | {kern['new']} | {fmt(best('base', 'trace_ms'))} | "
                   f"{fmt(best('new', 'trace_ms'))} | "
                   f"{ratio(best('new', 'gpu_kernel_ms'), best('base', 'gpu_kernel_ms'))} | "
                   f"{ratio(best('new', 'trace_ms'), best('base', 'trace_ms'))} |")
    out.append("")


def build_table(lines, out):
    """The kd-tree build by threads (device-bench.sh's build part): the median build_ms of each
    binary, and new over base."""
    runs = defaultdict(lambda: defaultdict(list))
    for o in lines:
        if o.get("part") == "build" and "kdtree" in o:
            runs[(o["mesh"], o["threads"])][o["binary"]].append(o["kdtree"]["build_ms"])
    if not runs:
        return
    out.append("| mesh | threads | base build, ms (median) | new build, ms (median) | new / base |")
    out.append("|" + "---|" * 5)
    for (m, th) in sorted(runs):
        med = {w: statistics.median(v) if v else None for w, v in runs[(m, th)].items()}
        b, n = med.get("base"), med.get("new")
        out.append(f"| {m} | {th} | {fmt(b)} | {fmt(n)} | "
                   + (f"{n / b:.2f}" if b and n else "–") + " |")
    out.append("")


def simplify_table(lines, out):
    """iso --simplify by threads (device-bench.sh's simplify part): the median ms of the whole
    command for each binary, new over base, and the triangles each kept."""
    runs = defaultdict(lambda: defaultdict(list))
    kept = defaultdict(dict)
    for o in lines:
        if o.get("part") == "simplify" and "ms" in o:
            key = (o["smooth"], o["bound_mm"], o["threads"])
            runs[key][o["binary"]].append(o["ms"])
            kept[key][o["binary"]] = o["triangles"]
    if not runs:
        return
    out.append("| smoothing | bound, mm | threads | base, ms (median) | new, ms (median) | new / base | "
               "triangles base | triangles new |")
    out.append("|" + "---|" * 8)
    ms = lambda x: "–" if x is None else f"{x:.0f}"  # noqa: E731
    for key in sorted(runs, key=lambda k: (-k[0], -k[1], k[2])):
        med = {w: statistics.median(v) if v else None for w, v in runs[key].items()}
        b, n = med.get("base"), med.get("new")
        out.append(f"| {key[0]} | {key[1]} | {key[2]} | {ms(b)} | {ms(n)} | "
                   + (f"{n / b:.2f}" if b and n else "–")
                   + f" | {kept[key].get('base', '–')} | {kept[key].get('new', '–')} |")
    out.append("")


def floor_table(lines, out):
    """Where a query's wall time goes (trace lines with --stats carry "floor": the same rays
    through a kernel that reads each ray and writes a miss): ms of the query and of the floor by
    wall, kernel (timestamps) and streamed time, an empty submission's round trip, and the
    traversal's own share of the kernel (query kernel - floor kernel); the wall of untimed
    queries, each run after a timed one ("untimed_ms"), and the floor part's lines also with
    timestamps off for the whole run (no kernel times), by round."""
    rows = [o for o in lines if isinstance(o.get("floor"), dict) and "kind" in o and "binary" not in o]
    if not rows:
        return
    out.append("| mesh | rays | tracer | timestamps | wall | wall untimed | kernel | streamed | round trip | "
               "floor wall | floor wall untimed | floor kernel | floor streamed | wall - kernel | "
               "floor wall - floor kernel | kernel - floor kernel |")
    out.append("|" + "---|" * 16)
    ms = lambda x: "–" if x is None else f"{x:.3f}"  # noqa: E731
    sub = lambda x, y: None if x is None or y is None else x - y  # noqa: E731
    order = lambda o: (o["mesh"], KINDS.index(o["kind"]) if o["kind"] in KINDS else len(KINDS))  # noqa: E731
    for o in sorted(rows, key=order):
        f = o["floor"]
        stamps = o.get("timestamps", "on")
        if "round" in o:
            stamps += f", round {o['round']}"
        out.append(f"| {o['mesh']} | {o['kind']} | {o.get('tracer', '–')} | {stamps} | {ms(o.get('trace_ms'))} | "
                   f"{ms(o.get('untimed_ms'))} | {ms(o.get('gpu_kernel_ms'))} | {ms(o.get('stream_ms'))} | "
                   f"{ms(o.get('round_trip_ms'))} | {ms(f.get('trace_ms'))} | {ms(f.get('untimed_ms'))} | "
                   f"{ms(f.get('gpu_kernel_ms'))} | {ms(f.get('stream_ms'))} | "
                   f"{ms(sub(o.get('trace_ms'), o.get('gpu_kernel_ms')))} | "
                   f"{ms(sub(f.get('trace_ms'), f.get('gpu_kernel_ms')))} | "
                   f"{ms(sub(o.get('gpu_kernel_ms'), f.get('gpu_kernel_ms')))} |")
    out.append("")


def stats_table(by, sms, threads_per_sm, out):
    rows = [(m, k, v, o["gpu_stats"]) for (m, k, v), o in sorted(by.items()) if o.get("gpu_stats")]
    if not rows:
        return
    out.append(f"| mesh | rays | tracer | traversal steps / ray | efficiency | leaf visits / ray | "
               f"efficiency | triangle tests / ray | efficiency | subgroup | peak resident | "
               f"occupancy (of {sms} × {threads_per_sm}) |")
    out.append("|" + "---|" * 12)
    for m, k, v, s in rows:
        steps, eff = s["steps_per_ray"], s["simd_efficiency"]
        peak = s.get("peak_resident_invocations")
        occ = f"{peak / (sms * threads_per_sm):.2f}" if peak else "–"
        out.append(f"| {m} | {k} | {v} | {steps['traversal']:.1f} | {eff['traversal']:.2f} | "
                   f"{steps['leaf']:.2f} | {eff['leaf']:.2f} | {steps['triangle']:.2f} | "
                   f"{eff['triangle']:.2f} | {s.get('subgroup_size', '–')} | {peak or '–'} | {occ} |")
    out.append("")


def checks(lines, out):
    bad = [o for o in lines if "check" in o and not o.get("pass")]
    n = sum(1 for o in lines if "check" in o)
    if not n:
        return
    out.append(f"- rays.py check: {n - len(bad)} of {n} passed.")
    for o in bad:
        out.append(f"  - FAILED: {o.get('mesh')} {o.get('kind')} {o['check']}: hit agreement "
                   f"{o.get('hit_agree')}, prim agreement {o.get('prim_agree')}")
    out.append("")


FRAME = re.compile(r"^\[submit (\w+), (\d+) spp\] raystream: wrote .*? render ([\d.]+) ms median of "
                   r"\d+ = ([\d.]+) frames/s")


def log_matches(path, pattern):
    """The matches of `pattern` on render.log's lines, in order."""
    with open(path) as f:
        return [m for m in map(pattern.match, f) if m]


def pairs_table(path, pattern, header, keys, out, reverse=False):
    """render.log's frame times matched by `pattern` (groups: the row, one of the two `keys`,
    the time), one row per row value: each key's times and their medians' ratio."""
    runs = defaultdict(list)
    for m in log_matches(path, pattern):
        runs[(int(m["row"]), m["key"])].append(float(m["ms"]))
    if not runs:
        return
    out.append(header)
    out.append("|---|---|---|---|")
    a, b = keys
    for row in sorted({r for r, _ in runs}, reverse=reverse):
        x, y = runs.get((row, a), []), runs.get((row, b), [])
        ratio = f"{statistics.median(y) / statistics.median(x):.2f}" if x and y else "–"
        out.append(f"| {row} | {', '.join(f'{v:.1f}' for v in x)} | {', '.join(f'{v:.1f}' for v in y)} | {ratio} |")
    out.append("")


FRAME = re.compile(r"^\[submit (?P<key>\w+), (?P<row>\d+) spp\] raystream: wrote .*? render (?P<ms>[\d.]+) ms median of "
                   r"\d+ = [\d.]+ frames/s")
# The "cpuframes" part: base against new at each thread count.
CPU_FRAME = re.compile(r"^\[cpuframes (?P<key>base|new), (?P<row>\d+) threads, round \d+\] raystream: wrote .*? "
                       r"render (?P<ms>[\d.]+) ms median")


# The "cpuframes" part's waves: the CPU frame on every thread in waves of N samples.
CPU_WAVE = re.compile(r"^\[cpuwave (?P<row>\d+), round \d+\] raystream: wrote .*? render (?P<ms>[\d.]+) ms median")


def cpuwave_table(path, out):
    runs = defaultdict(list)
    for m in log_matches(path, CPU_WAVE):
        runs[int(m["row"])].append(float(m["ms"]))
    if not runs:
        return
    default = runs.get(1 << 18)
    out.append("| CPU wave, samples | frame ms | against 2^18 (medians) |")
    out.append("|---|---|---|")
    for w in sorted(runs):
        ratio = f"{statistics.median(runs[w]) / statistics.median(default):.2f}" if default else "–"
        out.append(f"| {w} | {', '.join(f'{v:.1f}' for v in runs[w])} | {ratio} |")
    out.append("")


def render_table(path, out):
    pairs_table(path, FRAME, "| spp | `--submit depth` frame ms | `--submit wave` frame ms | wave / depth (medians) |",
                ("depth", "wave"), out, reverse=True)


def cpuframes_table(path, out):
    pairs_table(path, CPU_FRAME, "| CPU threads | base frame ms | new frame ms | new / base (medians) |",
                ("base", "new"), out)


# The interpolation ("trilinear", "cubic B-spline") follows the mode since 2026-12-03.
CINEMATIC = re.compile(r"raystream: wrote (\S+) \((\d+x\d+), --mode cinematic(?:, [a-zA-Z -]+)?, (\d+) paths a pixel")
DENOISED = re.compile(r"denoised \(guides ([\d.]+) ms, filter ([\d.]+) ms\)")
RENDER_MS = re.compile(r": load [\d.]+ ms, render ([\d.]+) ms")


def cinematic_table(path, out):
    """render.log's cinematic pictures (open questions 12 and 13): the frame's time and, when
    denoised, what the guides and the filter took."""
    rows = []
    with open(path) as f:
        for line in f:
            m = CINEMATIC.search(line)
            r = RENDER_MS.search(line)
            if not (m and r):
                continue
            d = DENOISED.search(line)
            rows.append((os.path.basename(m.group(1)), m.group(2), m.group(3), float(r.group(1)),
                         d and float(d.group(1)), d and float(d.group(2))))
    if not rows:
        return
    out.append("| picture | size | paths a pixel | render ms | denoised: guides ms | filter ms |")
    out.append("|---|---|---|---|---|---|")
    def ms_or_dash(x):
        return "–" if x is None else f"{x:.1f}"
    for name, size, spp, ms, guides, filt in rows:
        out.append(f"| {name} | {size} | {spp} | {ms:.1f} | {ms_or_dash(guides)} | {ms_or_dash(filt)} |")
    out.append("")


FLY = re.compile(r"^\[fly (\w+)\] raystream: wrote (\d+) frames .*?\((\d+x\d+), --mode (\w+).*?median render ([\d.]+) ms")


def fly_table(path, out):
    """render.log's fly-throughs (open question 20): the median frame's time on each device."""
    rows = []
    with open(path) as f:
        for line in f:
            m = FLY.match(line)
            if m:
                rows.append(m.groups())
    if not rows:
        return
    out.append("| fly-through | device | frames | size | median frame ms |")
    out.append("|---|---|---|---|---|")
    for dev, n, size, mode, ms in rows:
        out.append(f"| {mode} | {dev} | {n} | {size} | {float(ms):.1f} |")
    out.append("")


def volume_table(lines, out):
    """The volume benches (`bench VOLUME --mode … --json`, tagged "volume"): frames/s by wall
    and kernel time, and samples/s."""
    rows = [o for o in lines if o.get("kind") == "volume" and "frame_ms" in o]
    if not rows:
        return
    out.append("| bench | mode | interpolation | shadows | paths a pixel | device | dims | size | frames/s | kernel frames/s | M samples/frame | G samples/s (kernel) |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for o in rows:
        dims = "×".join(str(n) for n in o.get("dims", []))
        name = o.get("volume", "–")
        if o.get("binary"):
            name += f" ({o['binary']}, round {o.get('round', '–')})"
        kernel = o.get("msamples_per_s_kernel")
        out.append(
            f"| {name} | {o.get('mode')} | {o.get('interpolation', 'linear')} "
            f"| {'yes' if o.get('shadows') else 'no'} "
            f"| {o.get('spp') or '–'} | {o.get('device')} | {dims} | {o.get('size')} "
            f"| {fmt(o.get('frames_per_s'))} | {fmt(o.get('kernel_frames_per_s'))} "
            f"| {(o.get('samples_per_frame') or 0) / 1e6:,.0f} | {fmt(kernel / 1e3 if kernel else None)} |")
    out.append("")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("results", help="results.jsonl from scripts/device-bench.sh")
    p.add_argument("--render", help="render.log from the same run")
    p.add_argument("--sms", type=int, default=132, help="streaming multiprocessors (H100 SXM: 132)")
    p.add_argument("--threads-per-sm", type=int, default=2048)
    a = p.parse_args()
    lines = load(a.results)
    by = index(lines)
    out = []
    machine = next((o for o in lines if "machine" in o), None)
    adapter = next((o["adapter"] for o in lines if o.get("device") == "gpu" and "adapter" in o), None)
    commit = next((o["commit"] for o in lines if "commit" in o), None)
    if machine:
        out.append(f"Machine: {machine['machine']}, {machine.get('date', '')}; adapter: {adapter}; "
                   f"commit: {commit or 'not recorded'}"
                   + (f", base {machine['base_commit']}." if "base_commit" in machine else "."))
        out.append("")
    query_table(by, out)
    variants_table(by, out)
    entry_table(lines, out)
    ab_table(lines, out)
    build_table(lines, out)
    simplify_table(lines, out)
    floor_table(lines, out)
    stats_table(by, a.sms, a.threads_per_sm, out)
    checks(lines, out)
    volume_table(lines, out)
    if a.render:
        render_table(a.render, out)
        cpuframes_table(a.render, out)
        cpuwave_table(a.render, out)
        cinematic_table(a.render, out)
        fly_table(a.render, out)
    print("\n".join(out))


if __name__ == "__main__":
    main()
