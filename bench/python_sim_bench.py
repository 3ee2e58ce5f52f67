#!/usr/bin/env python3
"""One closed-loop step three ways, same model, settings and commands: in-process (the `gaia` module), over
`gaia sim --stdio` (JSON lines) and over `gaia sim serve` (HTTP on loopback); tokens only and with a decoded frame
(an RGB array in-process, a JPEG data URI over the wire, its bytes decoded from base64). The three sessions step in
lockstep; each answer's "ms" (the library's own time for the step) against the wall time the caller saw gives what
each way adds. Then a thousand steps of one in-process session with its
resident size along the way (does the module leak?). docs/benchmarks.md records the figures:

    PYTHONPATH=build/python bench/python_sim_bench.py --gaia build/gaia --steps 150
"""
import argparse
import base64
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


def summary(wall, inner):
    wall, over = sorted(wall), sorted(w - i for w, i in zip(wall, inner))
    return {"median": statistics.median(wall), "p99": wall[int(0.99 * (len(wall) - 1))],
            "library_median": statistics.median(inner),
            "overhead_median": statistics.median(over), "overhead_mean": statistics.mean(over)}


class InProcess:
    def __init__(self, sim, seed):
        self.s = sim.create(seed=seed, guidance=8)

    def step(self, v, c, frame):
        t0 = time.perf_counter()
        r = self.s.step(v, c, frame=frame)
        return 1000 * (time.perf_counter() - t0), r["ms"]

    def close(self):
        pass


class Stdio:
    def __init__(self, binary, args, seed):
        self.p = subprocess.Popen([binary, "sim", "--stdio", *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  text=True, bufsize=1)
        self.sid = self.ask({"op": "create", "seed": seed, "guidance": 8})["session"]

    def ask(self, req):
        self.p.stdin.write(json.dumps(req) + "\n")
        self.p.stdin.flush()
        return json.loads(self.p.stdout.readline())

    def step(self, v, c, frame):
        req = {"op": "step", "session": self.sid, "speed": v, "curvature": c}
        if frame:
            req["frame"] = "jpeg"
        t0 = time.perf_counter()
        r = self.ask(req)
        if frame:  # the bytes of the JPEG, as a client would take them
            base64.b64decode(r["frame"].split(",", 1)[1])
        wall = 1000 * (time.perf_counter() - t0)
        assert r["status"] == 200, r
        return wall, r["ms"]

    def close(self):
        self.p.stdin.close()
        self.p.wait()


class Http:
    def __init__(self, binary, args, seed):
        self.p = subprocess.Popen([binary, "sim", "serve", "--port", "0", *args], stdout=subprocess.PIPE, text=True)
        line = self.p.stdout.readline()
        self.url = line[line.index("http://"):].split()[0].rstrip("/")
        self.sid = self.post("create", {"seed": seed, "guidance": 8})["session"]

    def post(self, op, body):
        req = urllib.request.Request(f"{self.url}/api/{op}", json.dumps(body).encode(), method="POST",
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=600) as r:
            return json.loads(r.read())

    def step(self, v, c, frame):
        body = {"session": self.sid, "speed": v, "curvature": c}
        if frame:
            body["frame"] = "jpeg"
        t0 = time.perf_counter()
        r = self.post("step", body)
        if frame:
            base64.b64decode(r["frame"].split(",", 1)[1])
        return 1000 * (time.perf_counter() - t0), r["ms"]

    def close(self):
        self.p.terminate()
        self.p.wait()


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gaia", default="build/gaia", help="the gaia binary")
    ap.add_argument("--steps", type=int, default=150, help="steps of each measured session")
    ap.add_argument("--leak-steps", type=int, default=1000, help="steps of the resident-size session (0: none)")
    a = ap.parse_args()
    world, tok = os.path.join(MODELS, "world.safetensors"), os.path.join(MODELS, "tokenizer.safetensors")
    args = ["--world", world, "--tokenizer", tok, "--threads", "1"]
    gaia.set_threads(1)  # as gaia sim runs a session: one intra-op thread (and the lookahead's)
    sim = gaia.Sim(world, tok)
    out = {}
    for frame in (False, True):
        # The three ways in lockstep, the order turning each step, so that the machine's drift falls on all alike.
        ways = {"in-process": InProcess(sim, 0), "stdio": Stdio(a.gaia, args, 0), "http": Http(a.gaia, args, 0)}
        times = {k: ([], []) for k in ways}
        names = list(ways)
        for k, (v, c) in enumerate(commands(a.steps)):
            for name in names[k % 3:] + names[:k % 3]:
                wall, inner = ways[name].step(v, c, frame)
                times[name][0].append(wall)
                times[name][1].append(inner)
        for name, w in ways.items():
            w.close()
            out[f"{name}/{'frame' if frame else 'tokens'}"] = summary(*times[name])
    for k, v in out.items():
        print(f"{k:20s} median {v['median']:7.1f} ms  p99 {v['p99']:7.1f} ms  library {v['library_median']:7.1f} ms  "
              f"beyond the library's own step: "
              f"median {v['overhead_median']:.3f} ms, mean {v['overhead_mean']:.3f} ms")
    if a.leak_steps <= 0:
        return
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
