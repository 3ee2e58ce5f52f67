#!/usr/bin/env python3
"""docs/benchmarks.md, "Closed-loop sessions": per-step latency of `gaia sim serve` with the shipped world model,
1, 2 and 4 sessions stepped at once (each by its own client) from a full context, so that every step slides the
window (§2.3), frames as tokens (no decoding), or with a decoded JPEG frame each step where the server setting
names a --tokenizer. Each server setting named on the command line runs in turn (default: gaia sim's own, then
`--threads 2`); paths in it are relative to the checkout.

    tools/bench-sim.py [GAIA_BINARY] [STEPS] [SERVER FLAGS | -]...      (standard library only)
"""
import json, os, random, socket, statistics, subprocess, sys, threading, time, urllib.request

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
gaia = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "build", "gaia"))
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 20
settings = sys.argv[3:] or ["-", "--threads 2"]


def post(op, body):
    req = urllib.request.Request(url + op, json.dumps(body).encode(), method="POST")
    with urllib.request.urlopen(req, timeout=600) as r:
        return json.loads(r.read())


def run(flags):
  with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
  global url
  url = f"http://127.0.0.1:{port}/api/"
  extra = [] if flags == "-" else flags.split()
  server = subprocess.Popen([gaia, "sim", "serve", "--world", os.path.join(root, "models", "world.safetensors"),
                             "--port", str(port)] + extra, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            cwd=root)
  while "serving on" not in (server.stdout.readline() or "serving on"):  # notes before it (a bf16 fallback) skipped
    pass
  print(f"server flags: {flags if extra else '(gaia sim defaults)'}")
  try:
    # Sessions start from a full context (7 random prompt frames), so that every step measured slides the window.
    probe = post("create", {})["session"]
    n = len(post("step", {"session": probe})["tokens"])
    post("close", {"session": probe})
    rng = random.Random(0)
    prompt = {"tokens": [[rng.randrange(1024) for _ in range(n)] for _ in range(7)], "actions": [[8, 0]] * 7}
    step = {"speed": 8, "tokens": False}
    if "--tokenizer" in extra:
        step["frame"] = "jpeg"
    for sessions in (1, 2, 4):
        times, spans, lock = [], {}, threading.Lock()

        def drive(i):
            sid = post("create", {"seed": i, "prompt": prompt})["session"]
            post("step", {"session": sid, "speed": 8, "curvature": 0})  # warm-up
            start = time.perf_counter()
            for k in range(steps):
                t0 = time.perf_counter()
                post("step", dict(step, session=sid, curvature=0.01 if k % 2 else -0.01))
                with lock:
                    times.append(1000 * (time.perf_counter() - t0))
            with lock:
                spans[i] = (start, time.perf_counter())
            post("close", {"session": sid})

        threads = [threading.Thread(target=drive, args=(i,)) for i in range(sessions)]
        for t in threads: t.start()
        for t in threads: t.join()
        # Frames of all sessions over the time they stepped together; each session's own rate over its own steps.
        wall = max(e for _, e in spans.values()) - min(b for b, _ in spans.values())
        rates = sorted(steps / (e - b) for b, e in spans.values())
        times.sort()
        p99 = times[min(len(times) - 1, int(0.99 * len(times)))]
        print(f"{sessions} session(s): p50 {statistics.median(times):.0f} ms, p99 {p99:.0f} ms, "
              f"{sessions * steps / wall:.2f} frames/s in all, sessions {rates[0]:.2f} to {rates[-1]:.2f} frames/s "
              f"(slowest {rates[0] / rates[-1]:.0%} of fastest)")
  finally:
    server.terminate()
    server.wait()


for flags in settings:
    run(flags)
