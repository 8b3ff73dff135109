#!/usr/bin/env python3
"""How soon Ctrl-C stops the module's long calls: SIGINT is sent from another thread while the call
runs, and the seconds from the signal to the KeyboardInterrupt are printed as JSON (the target:
under 0.2 s). The pytest suite runs the same measurement with a bound that a loaded machine meets.

usage: PYTHONPATH=build/release/python python3 python/bench/cancel_latency.py [--triangles 100000] [--runs 5]
"""
import argparse
import json
import os
import signal
import statistics
import threading
import time


def seconds_to_interrupt(call, after=0.4):
    """Seconds from a SIGINT sent `after` seconds into call() to its KeyboardInterrupt; raises
    AssertionError when the call ends before the signal or without KeyboardInterrupt."""
    fired = []

    def interrupt():
        fired.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)

    timer = threading.Timer(after, interrupt)
    timer.start()
    try:
        call()
    except KeyboardInterrupt:
        stopped = time.monotonic()
    else:
        raise AssertionError("the call ended without KeyboardInterrupt")
    finally:
        timer.cancel()
    assert fired, "the call ended before the signal"
    return stopped - fired[0]


def calls(tsah, animation):
    """The long calls, each taking seconds without a cancel (time_limit bounds a failure)."""
    return {
        "optimize_sequential": lambda: tsah.optimize(animation, optimizer="sequential", min_improvement=0, time_limit=5),
        "optimize_parallel": lambda: tsah.optimize(animation, optimizer="parallel", min_improvement=0, time_limit=5),
        "tree_set": lambda: tsah.optimize(animation, segments=4, min_improvement=0, time_limit=5),
        "evaluate": lambda: tsah.evaluate(animation, "tsah0,sahstar", min_improvement=0, time_limit=5),
    }


def main():
    import tsah

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=int, default=100000)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    animation = tsah.generate("explode", triangles=args.triangles, frames=10)
    report = {"triangles": args.triangles, "runs": args.runs, "cpus": os.cpu_count(), "seconds": {}}
    for name, call in calls(tsah, animation).items():
        late = [seconds_to_interrupt(call) for _ in range(args.runs)]
        report["seconds"][name] = {"median": statistics.median(late), "max": max(late)}
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
