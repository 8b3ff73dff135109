"""check_trace_totals.py STATS: in a `tsah trace --stats` file, every frame's and the average's
total_ms is update_ms + frame_ms (the whole frame), and frame_ms is positive."""
import json
import sys

run = json.load(open(sys.argv[1]))
for entry in run["frames"] + [run["average"]]:
    update, frame, total = entry["update_ms"], entry["frame_ms"], entry["total_ms"]
    if not frame > 0 or abs(update + frame - total) > 1e-9 * max(1.0, total):
        sys.exit(f"total_ms {total} is not update_ms {update} + frame_ms {frame}")
print(f"{len(run['frames'])} frames: total_ms = update_ms + frame_ms")
