#!/usr/bin/env python3
"""Markdown results table from `tsah bench` results files.

Usage:
    scripts/results-table.py RESULTS.json [RESULTS.json ...]            # print the table
    scripts/results-table.py RESULTS.json ... --update README.md        # replace the README block
    scripts/results-table.py RESULTS.json ... --all-methods             # every runtime method

RESULTS.json is the `results.json` that `tsah bench` writes (docs/bench.md describes it), or a
file of the same structure holding only the fields the table reads, such as
docs/results/bench-h200.json and docs/results/bench-cpu.json:

    command, started / finished (the date is their first 10 characters), machine {cpu,
    logical_cores, memory_gib, os, gpu {name, runtime_version}}, versions {compiler, embree},
    options {device, frames, eval_frames, trace_frames, width, height, ao_rays, shadow_rays,
    ground, max_leaf, ct, ci}, notes [],
    scenes[]: name, kind, triangles,
              table1 {eval_frames, methods[]: name, average},
              segments {count, k_trees {average}},
              paper {same_scene, table1[]: method, average},
              runtime {device, frames, methods[]: name, label, update, average {total_ms}},
              embree {frames, methods[]: name, label, average {total_ms}}

Every key but `scenes` (and `name` of each scene) may be missing; what is missing is left out of
the table. The output is a list of the runs (date, machine, command), a tree-quality table (the
paper's Table 1: Eq. 1 cost averaged over the evaluation frames, from the first file that has it
for a scene) and a frame-time table (the paper's Table 2: total ms per frame = update + trace,
one group of columns per file). Numbers are printed as `tsah bench`'s results.md prints them
(about three significant digits).

--update FILE replaces the lines between `<!-- results-table:begin -->` and
`<!-- results-table:end -->` in FILE (both markers must be there, once each) and rewrites FILE.

Errors are one line on stderr; exit status 1 for a missing or malformed file, 2 for bad usage.
Python 3 standard library only.
"""

import argparse
import json
import math
import os
import sys

BEGIN = "<!-- results-table:begin -->"
END = "<!-- results-table:end -->"
PROG = "results-table.py"

TABLE1 = [("rebuild", "SAH-rebuild"), ("sah0", "SAH0"), ("sahstar", "SAH\\*"), ("tsah0", "T-SAH k=0")]
RUNTIME_LABELS = {
    "tsah0": "T-SAH refit",
    "sah0": "SAH0 refit",
    "sahstar": "SAH\\* refit",
    "tsah0-budget": "T-SAH, budget set",
    "lbvh": "LBVH rebuild",
    "hlbvh-sah": "HLBVH-SAH rebuild",
    "rebuild-sweep": "sweep SAH rebuild",
    "rebuild-binned": "binned SAH rebuild",
}
KIND_LABELS = {"bart": "BART", "md2": "MD2", "model": "model"}


class Failed(Exception):
    """A one-line error for the user; exit status 1."""


class Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2
        sys.stderr.write(f"{PROG}: {message} (--help shows the usage)\n")
        sys.exit(2)


# ---------------------------------------------------------------------------------------------
# Reading

def load(path):
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise Failed(f"{path}: no such file")
    except IsADirectoryError:
        raise Failed(f"{path}: is a folder, not a results file")
    except (OSError, UnicodeDecodeError) as e:
        raise Failed(f"{path}: cannot read: {getattr(e, 'strerror', None) or e}")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise Failed(f"{path}: not valid JSON: {e.msg} at line {e.lineno}, column {e.colno}")
    check(path, data)
    return data


def check(path, data):
    """Refuses a file whose keys the table reads have the wrong type (one line naming the key)."""
    def fail(where, what):
        raise Failed(f"{path}: {where}: {what}")

    def need(obj, key, where, kind, required=False):
        if key not in obj:
            if required:
                fail(where, f"'{key}' is missing")
            return None
        value = obj[key]
        ok = {
            "object": isinstance(value, dict),
            "array": isinstance(value, list),
            "string": isinstance(value, str),
            "number": isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value),
        }[kind]
        if not ok:
            fail(f"{where}.{key}" if where else key, f"expected a {kind}, got {json.dumps(value)[:40]}")
        return value

    if not isinstance(data, dict) or "scenes" not in data:
        fail("top level", "not a tsah bench results file (no \"scenes\" array)")
    need(data, "scenes", "", "array", True)
    for key in ("command", "started", "finished"):
        need(data, key, "", "string")
    for key in ("machine", "versions", "options"):
        need(data, key, "", "object")
    need(data, "notes", "", "array")
    for i, scene in enumerate(data["scenes"]):
        w = f"scenes[{i}]"
        if not isinstance(scene, dict):
            fail(w, "expected an object")
        need(scene, "name", w, "string", True)
        need(scene, "triangles", w, "number")
        t1 = need(scene, "table1", w, "object")
        if t1 is not None:
            for j, m in enumerate(need(t1, "methods", w + ".table1", "array", True)):
                mw = f"{w}.table1.methods[{j}]"
                if not isinstance(m, dict):
                    fail(mw, "expected an object")
                need(m, "name", mw, "string", True)
                need(m, "average", mw, "number", True)
        seg = need(scene, "segments", w, "object")
        if seg is not None:
            need(seg, "count", w + ".segments", "number")
            kt = need(seg, "k_trees", w + ".segments", "object")
            if kt is not None:
                need(kt, "average", w + ".segments.k_trees", "number")
        paper = need(scene, "paper", w, "object")
        if paper is not None:
            for j, m in enumerate(need(paper, "table1", w + ".paper", "array") or []):
                mw = f"{w}.paper.table1[{j}]"
                if not isinstance(m, dict):
                    fail(mw, "expected an object")
                need(m, "method", mw, "string", True)
                need(m, "average", mw, "number", True)
        for part in ("runtime", "embree"):
            block = need(scene, part, w, "object")
            if block is None or "methods" not in block:
                continue
            for j, m in enumerate(need(block, "methods", f"{w}.{part}", "array", True)):
                mw = f"{w}.{part}.methods[{j}]"
                if not isinstance(m, dict):
                    fail(mw, "expected an object")
                need(m, "name", mw, "string", True)
                avg = need(m, "average", mw, "object", True)
                need(avg, "total_ms", mw + ".average", "number", True)


# ---------------------------------------------------------------------------------------------
# Formatting (the rules of apps/bench/report.cpp: formatSignificant, withThousands)

def significant(value):
    a = abs(value)
    if a == 0:
        return "0"
    decimals = 0 if a >= 100 else 1 if a >= 10 else 2 if a >= 1 else 3 if a >= 0.1 else 4
    return f"{value:.{decimals}f}"


def thousands(n):
    return f"{int(round(n)):,}"


def plain(value):
    """A number as written, without a trailing .0 (the paper's figures)."""
    return f"{value:g}"


def date_of(data):
    for key in ("finished", "started"):
        if data.get(key):
            return data[key][:10]
    return "undated"


def device_label(data):
    gpu = data.get("machine", {}).get("gpu")
    if data.get("options", {}).get("device") == "cuda" and isinstance(gpu, dict) and gpu.get("name"):
        name = gpu["name"].replace("NVIDIA ", "")
        return next((w for w in name.split() if any(c.isdigit() for c in w)), name)  # "H100 80GB HBM3": H100
    return "CPU"


def cuda_version(code):
    return f"{int(code) // 1000}.{int(code) % 1000 // 10}"


def machine_text(data):
    m = data.get("machine", {})
    v = data.get("versions", {})
    parts = []
    gpu = m.get("gpu")
    if isinstance(gpu, dict) and gpu.get("name"):
        g = gpu["name"]
        extra = []
        if isinstance(gpu.get("memory_mib"), (int, float)):
            extra.append(f"{gpu['memory_mib'] / 1024:.0f} GiB")
        if isinstance(gpu.get("runtime_version"), (int, float)):
            extra.append(f"CUDA {cuda_version(gpu['runtime_version'])}")
        if isinstance(gpu.get("driver_version"), (int, float)):
            extra.append(f"driver API {cuda_version(gpu['driver_version'])}")
        parts.append(g + (f" ({', '.join(extra)})" if extra else "") + ", host")
    cpu = m.get("cpu", "")
    if isinstance(m.get("logical_cores"), (int, float)):
        cpu += f"{', ' if cpu else ''}{int(m['logical_cores'])} logical cores"
    if isinstance(m.get("memory_gib"), (int, float)):
        cpu += f", {m['memory_gib']:.1f} GiB"
    if m.get("os"):
        cpu += f", {m['os']}"
    if cpu:
        parts.append(cpu)
    text = " ".join(parts) if parts else "unknown machine"
    build = [x for x in (v.get("compiler"), ("Embree " + v["embree"]) if v.get("embree") else None) if x]
    if build:
        text += "; " + ", ".join(build)
    return text


def settings_text(data):
    o = data.get("options", {})
    if not o:
        return ""
    def n(key):
        value = o.get(key)
        return plain(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else "?"
    text = (f"{n('frames')} representative and {n('eval_frames')} evaluation frames, leaves of at most "
            f"{n('max_leaf')} triangles, cT = {n('ct')}, cI = {n('ci')}; {n('trace_frames')} traced frames per "
            f"method at {n('width')}×{n('height')}, 1 primary + {n('ao_rays')} AO + {n('shadow_rays')} shadow "
            f"rays per pixel, {'with the ground plane' if o.get('ground') else 'mesh only'}")
    return text


def scene_label(scene):
    kind = KIND_LABELS.get(scene.get("kind", ""))
    return f"{scene['name']} ({kind})" if kind else scene["name"]


def markdown_table(header, rows, numeric_from):
    align = ["---" if i < numeric_from else "--:" for i in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return lines


# ---------------------------------------------------------------------------------------------
# The tables

def scene_order(files):
    names = []
    for _, data in files:
        for s in data["scenes"]:
            if s["name"] not in names:
                names.append(s["name"])
    return names


def find_scene(data, name):
    for s in data["scenes"]:
        if s["name"] == name:
            return s
    return None


def quality_table(files, names):
    """Rows of Table 1 (from the first file holding a scene's table1), or [] when none has one."""
    def source(name):
        for _, data in files:
            s = find_scene(data, name)
            if s is not None and "table1" in s:
                return s
        return None

    scenes = [source(n) for n in names]
    if not any(scenes):
        return []
    seg_k = sorted({int(s["segments"].get("count", 0)) for s in scenes
                    if s and "k_trees" in s.get("segments", {})})
    has_paper = any(s and s.get("paper", {}).get("same_scene") and s["paper"].get("table1") for s in scenes)
    header = ["scene", "triangles"] + [label for _, label in TABLE1]
    if seg_k:
        header.append(f"T-SAH, {seg_k[0]} trees" if len(seg_k) == 1 else "T-SAH, K trees")
    if has_paper:
        header.append("paper: rebuild / SAH0 / T-SAH")
    rows = []
    for name, s in zip(names, scenes):
        if s is None:
            continue
        by_name = {m["name"]: m["average"] for m in s["table1"]["methods"]}
        row = [scene_label(s), thousands(s["triangles"]) if "triangles" in s else ""]
        row += [significant(by_name[k]) if k in by_name else "" for k, _ in TABLE1]
        if seg_k:
            kt = s.get("segments", {}).get("k_trees")
            row.append(significant(kt["average"]) if kt else "")
        if has_paper:
            p = s.get("paper", {})
            cells = ""
            if p.get("same_scene"):
                pb = {m["method"]: m["average"] for m in p.get("table1", [])}
                if all(k in pb for k in ("rebuild", "sah0", "tsah0")):
                    cells = " / ".join(plain(pb[k]) for k in ("rebuild", "sah0", "tsah0"))
            row.append(cells)
        rows.append(row)
    eval_frames = {s["table1"].get("eval_frames") for s in scenes if s}
    frames = f" over {plain(eval_frames.pop())} evaluation frames" if len(eval_frames) == 1 and None not in eval_frames else ""
    return [f"**Tree quality** (the paper's Table 1: average Eq. 1 cost{frames}; lower is better)", ""] + \
        markdown_table(header, rows, 1)


def wanted(method, all_methods):
    if all_methods:
        return True
    name = method["name"]
    return (name in ("tsah0", "sah0") or name.startswith("tsah0-seg") or method.get("update") == "rebuild"
            or name in ("lbvh", "hlbvh-sah", "rebuild-sweep", "rebuild-binned"))


def runtime_rank(name):
    """Column order: the T-SAH tree and its sets, the other refitted trees, then the rebuilds."""
    order = ["tsah0", "tsah0-seg", "tsah0-count", "tsah0-budget", "sah0", "sahstar",
             "lbvh", "hlbvh-sah", "rebuild-sweep", "rebuild-binned"]
    for i, key in enumerate(order):
        if name == key or (key.endswith(("-seg", "-count")) and name.startswith(key)):
            return i
    return len(order)


def runtime_label(method):
    name = method["name"]
    if name in RUNTIME_LABELS:
        return RUNTIME_LABELS[name]
    if name.startswith("tsah0-seg"):
        return f"T-SAH, {name[len('tsah0-seg'):]} trees"
    if name.startswith("tsah0-count"):
        return f"T-SAH, {name[len('tsah0-count'):]} trees (count mode)"
    return method.get("label") or name


def time_columns(data, names, all_methods):
    """[(header, {scene: cell})] of one file: its runtime methods, then the Embree comparison."""
    columns = []
    prefix = device_label(data) + ": "

    def add(key, header, name, cell):
        for c in columns:
            if c[0] == key:
                c[2][name] = cell
                return
        columns.append((key, header, {name: cell}))

    for name in names:
        s = find_scene(data, name)
        if s is None:
            continue
        for m in sorted(s.get("runtime", {}).get("methods", []), key=lambda m: runtime_rank(m["name"])):
            if wanted(m, all_methods):
                add("runtime:" + m["name"], prefix + runtime_label(m), name, significant(m["average"]["total_ms"]))
        methods = s.get("embree", {}).get("methods", [])
        own = [m for m in methods if not m["name"].startswith("embree")]
        if own:  # the toolkit's default layout comes first, then the Embree peers
            add("embree:own", "CPU, same rays: toolkit T-SAH", name, significant(own[0]["average"]["total_ms"]))
        for m in methods:
            if m["name"].startswith("embree") and (all_methods or m["name"] == "embree-refit"):
                label = m.get("label") or m["name"]
                add("embree:" + m["name"], "CPU, same rays: " + label, name, significant(m["average"]["total_ms"]))
    return [(header, cells) for _, header, cells in columns]


def time_table(files, names, all_methods):
    columns = []
    for _, data in files:
        columns += time_columns(data, names, all_methods)
    if not columns:
        return []
    labels = {}
    for _, data in files:
        for s in data["scenes"]:
            labels.setdefault(s["name"], scene_label(s))
    header = ["scene"] + [h for h, _ in columns]
    rows = [[labels[n]] + [cells.get(n, "") for _, cells in columns] for n in names
            if any(n in cells for _, cells in columns)]
    return ["**Frame time** (the paper's Table 2: ms per frame = update + trace, mean over the traced "
            "frames; the Embree columns trace the same rays with the toolkit's traversal and with Embree)",
            ""] + markdown_table(header, rows, 1)


def render(paths, files, all_methods):
    names = scene_order(files)
    lines = [f"<!-- generated by scripts/results-table.py {' '.join(paths)}: edit those files, not this block -->"]
    for path, data in files:
        command = data.get("command", "")
        line = f"- **{device_label(data)}**, {date_of(data)}: {machine_text(data)}"
        if command:
            line += f"; `{command}`"
        lines.append(line + f" ([{os.path.basename(path)}]({path}))")
    settings = {settings_text(d) for _, d in files} - {""}
    if len(settings) == 1:
        lines += ["", "Settings: " + settings.pop() + "."]
    elif settings:
        for _, data in files:
            lines += ["", f"Settings ({device_label(data)}): " + settings_text(data) + "."]
    for block in (quality_table(files, names), time_table(files, names, all_methods)):
        if block:
            lines += [""] + block
    return "\n".join(lines) + "\n"


def update(target, block):
    try:
        with open(target, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise Failed(f"{target}: no such file")
    except (OSError, UnicodeDecodeError) as e:
        raise Failed(f"{target}: cannot read: {getattr(e, 'strerror', None) or e}")
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise Failed(f"{target}: needs one '{BEGIN}' line and, after it, one '{END}' line")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    new = head + BEGIN + "\n" + block + END + tail
    if new == text:
        return False
    tmp = target + ".tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(new)
        os.replace(tmp, target)
    except OSError as e:
        raise Failed(f"{target}: cannot write: {e.strerror or e}")
    return True


def main(argv):
    parser = Parser(prog=PROG, description="Markdown results table from tsah bench results files.")
    parser.add_argument("results", nargs="+", metavar="RESULTS.json", help="tsah bench results.json files")
    parser.add_argument("--update", metavar="FILE", help="replace the results-table block of FILE (e.g. README.md)")
    parser.add_argument("--all-methods", action="store_true", help="a column for every runtime and Embree method")
    args = parser.parse_args(argv)
    try:
        files = [(p, load(p)) for p in args.results]
        block = render(args.results, files, args.all_methods)
        if args.update:
            changed = update(args.update, block)
            print(f"{PROG}: {args.update}: {'updated' if changed else 'already up to date'}")
        else:
            sys.stdout.write(block)
    except Failed as e:
        sys.stderr.write(f"{PROG}: {e}\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
