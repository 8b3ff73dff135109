"""tsah export --shutter, checked as a renderer would read it: the header compiles (C11), the key
files have the sizes the header gives, the key times run from 0 to 1, and the first and last keys'
nodes, root boxes and vertices equal a plain export at the shutter's open and close times.
Usage: check_export_motion.py TSAH TREE ANIMATION WORKDIR LAYOUT CC"""
import pathlib
import re
import struct
import subprocess
import sys

tsah, tree, animation, work, layout, cc = sys.argv[1:7]
work = pathlib.Path(work)


def export(out, *args):
    subprocess.run([tsah, "export", tree, animation, "--layout", layout, "-o", str(work / out), *args],
                   check=True, stdout=subprocess.DEVNULL)
    return work / out


blurred = export(f"export_blur_{layout}", "--frame", "2", "--shutter", "0.9")
header = (blurred / "tsah_scene.h").read_text()
subprocess.run([cc, "-std=c11", "-Wall", "-Werror", "-fsyntax-only", "-x", "c", str(blurred / "tsah_scene.h")],
               check=True)
define = {m[0]: m[1] for m in re.findall(r"#define (TSAH_\w+) \(?([-0-9.e]+)", header)}
keys, nodes, vertices = int(define["TSAH_KEY_COUNT"]), int(define["TSAH_NODE_COUNT"]), int(define["TSAH_VERTEX_COUNT"])
node_bytes = (blurred / "nodes.bin").stat().st_size // nodes

times = struct.unpack(f"<{keys}f", (blurred / "key_times.bin").read_bytes())
assert keys >= 2 and times[0] == 0.0 and times[-1] == 1.0, times
assert all(a < b for a, b in zip(times, times[1:])), times
key_nodes = (blurred / "key_nodes.bin").read_bytes()
key_vertices = (blurred / "key_vertices.bin").read_bytes()
key_boxes = (blurred / "key_root_boxes.bin").read_bytes()
assert len(key_nodes) == keys * nodes * node_bytes, (len(key_nodes), keys, nodes, node_bytes)
assert len(key_vertices) == keys * vertices * 12
assert len(key_boxes) == keys * 24

for key, when in ((0, define["TSAH_SHUTTER_OPEN"]), (keys - 1, define["TSAH_SHUTTER_CLOSE"])):
    instant = export(f"export_key{key}_{layout}", "--time", when)
    block = nodes * node_bytes
    assert key_nodes[key * block:(key + 1) * block] == (instant / "nodes.bin").read_bytes(), f"key {key} nodes"
    assert key_vertices[key * vertices * 12:(key + 1) * vertices * 12] == (instant / "vertices.bin").read_bytes()
    lo = re.search(r"TSAH_BOUNDS_LO \{([^}]*)\}", (instant / "tsah_scene.h").read_text())[1]
    hi = re.search(r"TSAH_BOUNDS_HI \{([^}]*)\}", (instant / "tsah_scene.h").read_text())[1]
    expected = [float(v.strip().rstrip("f")) for v in lo.split(",") + hi.split(",")]
    got = struct.unpack("<6f", key_boxes[key * 24:(key + 1) * 24])
    assert all(abs(a - b) <= 1e-6 * max(1.0, abs(b)) for a, b in zip(got, expected)), (got, expected)
print(f"export --shutter {layout}: {keys} keys, {nodes} nodes of {node_bytes} bytes, {vertices} vertices: ok")
