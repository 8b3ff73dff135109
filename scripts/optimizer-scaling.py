#!/usr/bin/env python3
"""Optimizer scaling bench: time, peak memory and resulting T-SAH cost against the triangle count.

Runs `tsah optimize --json` once per (input, optimizer, thread count) as a child process, so that
the peak resident memory of every run is its own (os.wait4). Inputs are generated explode
animations (`tsah generate explode --triangles N --frames 10`, cached in the output folder) and any
animation given with --scene (BART .aff, .tanim, sequences: whatever `tsah optimize` reads).

Writes OUT/scaling.json (every run), OUT/scaling.dat and, with gnuplot, OUT/scaling-time.png,
OUT/scaling-memory.png. Prints one JSON object per run as it goes. Timings depend on other load:
the runs record user CPU time next to wall time, and `uptime` before the first run.

  scripts/optimizer-scaling.py --tsah build/release/apps/tsah --out out/scaling \
      --triangles 100000 300000 1000000 --threads 1 2 --scene ../shared/data/.../robots.aff
"""
import argparse
import json
import os
import subprocess
import sys
import time


def run(cmd):
    """Runs cmd; returns (stdout, wall seconds, user+sys CPU seconds, peak RSS bytes)."""
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out = proc.stdout.read()
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - start
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"optimizer-scaling: {' '.join(cmd)} failed: {err.decode(errors='replace').strip()}")
    return out.decode(), wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss * 1024


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tsah", default="build/release/apps/tsah")
    parser.add_argument("--out", default="out/scaling")
    parser.add_argument("--triangles", type=int, nargs="*", default=[100000, 300000, 1000000])
    parser.add_argument("--scene", action="append", default=[], help="an animation to include (repeatable)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="thread counts of the parallel optimizer")
    parser.add_argument("--frames", type=int, default=5, help="representative frames")
    parser.add_argument("--no-sequential", action="store_true", help="skip the sequential optimizer")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)

    inputs = []
    for n in args.triangles:
        path = os.path.join(args.out, f"explode-{n}.tanim")
        if not os.path.exists(path):
            subprocess.run([args.tsah, "generate", "explode", "-o", path, "--triangles", str(n), "--frames", "10"],
                           check=True, stdout=subprocess.DEVNULL)
        inputs.append((f"explode-{n}", path))
    inputs += [(os.path.splitext(os.path.basename(s))[0], s) for s in args.scene]

    configs = [] if args.no_sequential else [("sequential", 1)]
    configs += [("parallel", t) for t in args.threads]
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    runs = []
    tbvh = os.path.join(args.out, "scratch.tbvh")
    for name, path in inputs:
        for optimizer, threads in configs:
            cmd = [args.tsah, "optimize", path, "-o", tbvh, "--optimizer", optimizer, "--threads", str(threads),
                   "--frames", str(args.frames), "--eval-frames", "1", "--json"]
            out, wall, cpu, peak = run(cmd)
            j = json.loads(out)
            o = j["optimization"]
            r = {"input": name, "path": path, "triangles": j["triangles"], "optimizer": optimizer, "threads": threads,
                 "optimize_s": o["seconds"], "build_s": j["build_s"], "process_wall_s": wall, "process_cpu_s": cpu,
                 "peak_rss_bytes": peak, "bytes_per_triangle": peak / j["triangles"],
                 "initial_cost": o["initial_cost"], "final_cost": o["final_cost"], "rounds_or_batches": o["batches"],
                 "searches_or_steps": o["steps"]}
            runs.append(r)
            print(json.dumps(r), flush=True)
    os.remove(tbvh) if os.path.exists(tbvh) else None

    # Ratios against the sequential optimizer and the 1-thread parallel run of the same input.
    for r in runs:
        same = [s for s in runs if s["input"] == r["input"]]
        seq = next((s for s in same if s["optimizer"] == "sequential"), None)
        one = next((s for s in same if s["optimizer"] == "parallel" and s["threads"] == 1), None)
        if seq:
            r["cost_vs_sequential"] = r["final_cost"] / seq["final_cost"]
        if one and r["optimizer"] == "parallel":
            r["speedup_vs_1_thread"] = one["optimize_s"] / r["optimize_s"]
    with open(os.path.join(args.out, "scaling.json"), "w") as f:
        json.dump({"load_before": load, "runs": runs}, f, indent=1)

    labels = [f"{o}-{t}" for o, t in configs]
    dat = os.path.join(args.out, "scaling.dat")
    with open(dat, "w") as f:
        f.write("# triangles " + " ".join(f"{l}_s {l}_Bpt {l}_cost" for l in labels) + "\n")
        for name, _ in inputs:
            row = [r for r in runs if r["input"] == name]
            f.write(f"{row[0]['triangles']} " + " ".join(
                f"{r['optimize_s']:.4f} {r['bytes_per_triangle']:.1f} {r['final_cost']:.4f}" for r in row) + "\n")
    script = "set terminal png size 960,540\nset logscale x\nset key left top\nset xlabel 'triangles'\n"
    for what, column, ylabel in (("time", 0, "optimization time [s]"), ("memory", 1, "peak memory [bytes per triangle]")):
        script += f"set output '{args.out}/scaling-{what}.png'\nset ylabel '{ylabel}'\nplot "
        script += ", ".join(f"'{dat}' using 1:{2 + 3 * i + column} with linespoints title '{l}'"
                            for i, l in enumerate(labels)) + "\n"
    try:
        subprocess.run(["gnuplot"], input=script, text=True, check=True)
    except (OSError, subprocess.CalledProcessError) as e:
        print(f"optimizer-scaling: no plots ({e})", file=sys.stderr)


if __name__ == "__main__":
    main()
