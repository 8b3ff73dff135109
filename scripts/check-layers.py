#!/usr/bin/env python3
"""Checks that no include runs upward inside the libraries (docs/architecture.md).

The libraries stack as base < libanim < libtsah < cuda_kernels, and inside each the rooms (header
folders) stack as listed below. A file may include headers of its own room, of rooms below it and
of libraries below its own; nothing else. A project header that no rule places is an error too,
so a new header has to be given its room here.

usage: scripts/check-layers.py [--list]   (exit 0: clean; 1: violations, one line each)
"""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

LIBRARY_RANK = {"base": 0, "anim": 1, "tsah": 2, "cuda": 3}

# libtsah's rooms, lowest first (libtsah/include/tsah/<room>/, libtsah/src/<room>/).
TSAH_ROOMS = ["core", "build", "layout", "io", "optimize", "inspect", "runtime", "render"]
TSAH_FRONT_DOOR = len(TSAH_ROOMS)  # tsah/pipeline.hpp and pipeline.cpp
# Above the front door: two-level scenes, built from scene sources with the pipeline's steps.
TSAH_ABOVE_FRONT_DOOR = {"scene": TSAH_FRONT_DOOR + 1}

# libanim: the model and the importers' options, the importers, scenes, the front door.
ANIM_RANK = {"animation.hpp": 0, "load_options.hpp": 0, "mesh_check.hpp": 0,
             "scene.hpp": 2, "load.hpp": 3}
ANIM_IMPORTER = 1  # every other libanim header (one file format or generator each)
ANIM_SOURCE = 3    # libanim/src/*.cpp: may use the whole library

# cuda_kernels: small shared types, the private kernels' headers, the front doors.
CUDA_RANK = {"cuda_check.hpp": 0, "device.hpp": 0, "device_buffer.hpp": 0, "rebuild_types.hpp": 0,
             "gpu_runtime.hpp": 2, "gpu_optimizer.hpp": 2, "runtime_impl.hpp": 2, "device_array_checks.hpp": 2,
             "gpu_queries.hpp": 2, "gpu_two_level.hpp": 2,
             "gpu_two_level_render.hpp": 2, "render_passes.cuh": 2, "two_level_render.hpp": 2}
CUDA_PRIVATE = 1   # cuda_kernels/src/*.hpp, *.cuh
CUDA_SOURCE = 2    # cuda_kernels/src/*.cu, *.cpp

# libtsah rooms whose files may see the animation model (device code never does).
ROOMS_SEEING_ANIM = {"render", "pipeline", "scene"}


def place(path):
    """(library, rank, room) of a file given by its path from the repository root, or None."""
    parts = path.split("/")
    name = parts[-1]
    if path.startswith("libtsah/include/tsah/base/") or path.startswith("libtsah/src/base/"):
        return ("base", 0, "base")
    if path.startswith("libtsah/include/tsah/") or path.startswith("libtsah/src/"):
        inner = parts[3:-1] if parts[1] == "include" else parts[2:-1]
        if not inner:
            return ("tsah", TSAH_FRONT_DOOR, "pipeline") if name.startswith("pipeline.") else None
        room = inner[0]
        if room in TSAH_ABOVE_FRONT_DOOR:
            return ("tsah", TSAH_ABOVE_FRONT_DOOR[room], "/".join(inner))
        if room not in TSAH_ROOMS:
            return None
        return ("tsah", TSAH_ROOMS.index(room), "/".join(inner))
    if path.startswith("libanim/include/anim/"):
        return ("anim", ANIM_RANK.get(name, ANIM_IMPORTER), "anim")
    if path.startswith("libanim/src/"):
        if name.endswith(".hpp"):
            return ("anim", ANIM_RANK.get(name, ANIM_IMPORTER), "anim")
        return ("anim", ANIM_SOURCE, "anim")
    if path.startswith("cuda_kernels/include/tsah_cuda/"):
        return ("cuda", CUDA_RANK.get(name, CUDA_SOURCE), "cuda") if name in CUDA_RANK else None
    if path.startswith("cuda_kernels/src/"):
        if name in CUDA_RANK:
            return ("cuda", CUDA_RANK[name], "cuda")
        rank = CUDA_PRIVATE if name.endswith((".hpp", ".cuh")) else CUDA_SOURCE
        return ("cuda", rank, "cuda")
    return None


def resolve(including, target):
    """The repository path of an included header, or None for a system or third-party header."""
    for prefix, folder in (("tsah/", "libtsah/include/"), ("anim/", "libanim/include/"),
                           ("tsah_cuda/", "cuda_kernels/include/")):
        if target.startswith(prefix):
            return folder + target
    candidates = [os.path.join(os.path.dirname(including), target)]
    if including.startswith("libtsah/src/"):
        candidates.append("libtsah/src/" + target)
    if including.startswith("cuda_kernels/"):
        candidates.append("cuda_kernels/src/" + target)
    for c in candidates:
        c = os.path.normpath(c)
        if os.path.exists(os.path.join(ROOT, c)):
            return c
    return None


def library_files():
    for top in ("libtsah", "libanim", "cuda_kernels"):
        for folder, _, names in os.walk(os.path.join(ROOT, top)):
            for n in sorted(names):
                if n.endswith((".hpp", ".cpp", ".cu", ".cuh", ".inl", ".h")):
                    yield os.path.relpath(os.path.join(folder, n), ROOT)


INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.M)


def check():
    problems = []
    edges = 0
    for path in sorted(library_files()):
        me = place(path)
        if me is None:
            problems.append(f"{path}: in no room (give its folder a rank in scripts/check-layers.py)")
            continue
        text = open(os.path.join(ROOT, path), encoding="utf-8").read()
        for target in INCLUDE.findall(text):
            dep_path = resolve(path, target)
            if dep_path is None:
                problems.append(f"{path}: includes \"{target}\", which is no file of the project")
                continue
            dep = place(dep_path)
            if dep is None:
                problems.append(f"{path}: includes {dep_path}, which is in no room")
                continue
            edges += 1
            my_lib, dep_lib = LIBRARY_RANK[me[0]], LIBRARY_RANK[dep[0]]
            upward = dep_lib > my_lib or (dep_lib == my_lib and dep[1] > me[1])
            if upward:
                problems.append(f"{path} ({me[0]}/{me[2]}): includes {dep_path} ({dep[0]}/{dep[2]}), a room above it")
            if dep[0] == "anim" and me[0] == "tsah" and me[2].split("/")[0] not in ROOMS_SEEING_ANIM:
                problems.append(f"{path} ({me[2]}): includes {dep_path}; only the render, pipeline and scene rooms "
                                "see the animation model")
            if dep[2] == "optimize/detail" and not (me[2].startswith("optimize") or me[0] == "cuda"):
                problems.append(f"{path}: includes {dep_path}, the optimizer's internals")
    return problems, edges


def main():
    problems, edges = check()
    for p in problems:
        print(p)
    if problems:
        print(f"check-layers: {len(problems)} problem(s)", file=sys.stderr)
        return 1
    print(f"check-layers: {edges} project includes in libtsah, libanim and cuda_kernels, none upward")
    return 0


if __name__ == "__main__":
    sys.exit(main())
