#!/usr/bin/env python3
"""One closed-loop step three ways, same model, settings and commands: in-process (the `gaia` module), over
`gaia sim --stdio` (JSON lines) and over `gaia sim serve` (HTTP on loopback); tokens only and with a decoded frame
(an RGB array in-process, a JPEG data URI over the wire). Then a thousand steps of one in-process session with its
resident size along the way (does the module leak?). docs/benchmarks.md records the figures:

    PYTHONPATH=build/python bench/python_sim_bench.py --gaia build/gaia --steps 150
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import time
import urllib.request

import gaia

MODELS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "models")


def commands(n):
    return [(8.0, 0.02 if (k // 20) % 2 else -0.02) for k in range(n)]


def summary(ms):
    ms = sorted(ms)
    return {"mean": statistics.mean(ms), "median": statistics.median(ms), "p99": ms[int(0.99 * (len(ms) - 1))]}


def in_process(sim, steps, frame, seed):
    s = sim.create(seed=seed, guidance=8)
    wall, inner = [], []
    for v, c in commands(steps):
        t0 = time.perf_counter()
        r = s.step(v, c, frame=frame)
        wall.append(1000 * (time.perf_counter() - t0))
        inner.append(r["ms"])
    return wall, inner


def stdio(binary, args, steps, frame, seed):
    p = subprocess.Popen([binary, "sim", "--stdio", *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         text=True, bufsize=1)

    def ask(req):
        p.stdin.write(json.dumps(req) + "\n")
        p.stdin.flush()
        return json.loads(p.stdout.readline())

    sid = ask({"op": "create", "seed": seed, "guidance": 8})["session"]
    wall = []
    for v, c in commands(steps):
        req = {"op": "step", "session": sid, "speed": v, "curvature": c}
        if frame:
            req["frame"] = "jpeg"
        t0 = time.perf_counter()
        r = ask(req)
        wall.append(1000 * (time.perf_counter() - t0))
        assert r["status"] == 200, r
    p.stdin.close()
    p.wait()
    return wall


def http(binary, args, steps, frame, seed):
    p = subprocess.Popen([binary, "sim", "serve", "--port", "0", *args], stdout=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    url = line[line.index("http://"):].split()[0].rstrip("/")

    def post(op, body):
        req = urllib.request.Request(f"{url}/api/{op}", json.dumps(body).encode(), method="POST",
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=600) as r:
            return json.loads(r.read())

    try:
        sid = post("create", {"seed": seed, "guidance": 8})["session"]
        wall = []
        for v, c in commands(steps):
            body = {"session": sid, "speed": v, "curvature": c}
            if frame:
                body["frame"] = "jpeg"
            t0 = time.perf_counter()
            post("step", body)
            wall.append(1000 * (time.perf_counter() - t0))
    finally:
        p.terminate()
        p.wait()
    return wall


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gaia", default="build/gaia", help="the gaia binary")
    ap.add_argument("--steps", type=int, default=150, help="steps of each measured session")
    ap.add_argument("--leak-steps", type=int, default=1000)
    a = ap.parse_args()
    world, tok = os.path.join(MODELS, "world.safetensors"), os.path.join(MODELS, "tokenizer.safetensors")
    args = ["--world", world, "--tokenizer", tok, "--threads", "1"]
    gaia.set_threads(1)  # as gaia sim runs a session: one intra-op thread (and the lookahead's)
    sim = gaia.Sim(world, tok)
    out = {}
    for frame in (False, True):
        key = "frame" if frame else "tokens"
        in_process(sim, 10, frame, 1)  # warm-up
        wall, inner = in_process(sim, a.steps, frame, 0)
        out[f"in-process/{key}"] = summary(wall)
        out[f"in-process/{key}"]["added"] = statistics.mean(w - i for w, i in zip(wall, inner))
        out[f"stdio/{key}"] = summary(stdio(a.gaia, args, a.steps, frame, 0))
        out[f"http/{key}"] = summary(http(a.gaia, args, a.steps, frame, 0))
    for k, v in out.items():
        extra = f"  module adds {v['added']:.3f} ms" if "added" in v else ""
        print(f"{k:20s} mean {v['mean']:7.1f} ms  median {v['median']:7.1f}  p99 {v['p99']:7.1f}{extra}")
    s = sim.create(seed=0)
    marks = {}
    for k in range(1, a.leak_steps + 1):
        s.step(8.0, 0.0, frame=False)
        if k in (100, 250, 500, 750, 1000) or k == a.leak_steps:
            marks[k] = rss_mb()
    print("resident size (MB) after steps: " + ", ".join(f"{k}: {v:.1f}" for k, v in marks.items()))
    out["rss_mb"] = marks
    print(json.dumps(out))


if __name__ == "__main__":
    main()
