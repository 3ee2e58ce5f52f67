#!/usr/bin/env python3
"""A driving policy inside the world model, closed loop: it follows a curvature plan (straight, a left bend,
straight, a right bend, ...) at a steady speed, and corrects its commands by what the frames show, the speed and
curvature the dynamics probe reads back from the last frames (docs/sim.md). Standard library only; it talks to
`gaia sim serve` over HTTP:

    gaia sim serve TOKENS --world models/world.safetensors --tokenizer models/tokenizer.safetensors \\
        --probe models/probe-dynamics.safetensors --port 8080 &
    examples/lane_keeper.py --server http://127.0.0.1:8080 --episode 0 --seconds 60 --out drive.json

It prints a line a second and, at the end, how closely the read-back followed the plan (Spearman correlation and
sign accuracy of the curvature, mean speed). --out writes every step (plan, command, read-back, tokens) as JSON.
"""
import argparse
import json
import sys
import time
import urllib.error
import urllib.request

RATE = 6.25  # Hz: the world model's frame rate (paper §2.3)


def post(server, op, body):
    req = urllib.request.Request(f"{server}/api/{op}", json.dumps(body).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=600) as r:
            return json.loads(r.read())
    except urllib.error.HTTPError as e:  # the server's one-line error
        sys.exit(f"lane_keeper: {op}: {json.loads(e.read()).get('error', e.reason)}")
    except urllib.error.URLError as e:
        sys.exit(f"lane_keeper: cannot reach {server} ({e.reason}); is `gaia sim serve` running?")


def plan(t, bend, period):
    """The planned curvature (1/m, + = left) at t seconds: straight, left, straight, right, each a quarter period."""
    phase = int(4 * (t % period) / period)
    return [0.0, bend, 0.0, -bend][phase]


def ranks(xs):
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    r = [0.0] * len(xs)
    i = 0
    while i < len(order):  # ties share their mean rank
        j = i
        while j + 1 < len(order) and xs[order[j + 1]] == xs[order[i]]:
            j += 1
        for k in range(i, j + 1):
            r[order[k]] = (i + j) / 2
        i = j + 1
    return r


def spearman(a, b):
    ra, rb = ranks(a), ranks(b)
    ma, mb = sum(ra) / len(ra), sum(rb) / len(rb)
    cov = sum((x - ma) * (y - mb) for x, y in zip(ra, rb))
    va = sum((x - ma) ** 2 for x in ra) ** 0.5
    vb = sum((y - mb) ** 2 for y in rb) ** 0.5
    return cov / (va * vb) if va > 0 and vb > 0 else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--server", default="http://127.0.0.1:8080", help="gaia sim serve's address")
    ap.add_argument("--episode", help="prompt episode of the server's TOKENS (default: start from nothing)")
    ap.add_argument("--prompt-frames", type=int, default=4, help="prompt frames of that episode")
    ap.add_argument("--seconds", type=float, default=60, help="how long to drive (simulated time)")
    ap.add_argument("--speed", type=float, default=8, help="speed to hold, m/s")
    ap.add_argument("--bend", type=float, default=0.01, help="curvature of the planned bends, 1/m")
    ap.add_argument("--period", type=float, default=16, help="seconds of one straight-left-straight-right cycle")
    ap.add_argument("--plan", help="a JSON file of [speed m/s, curvature 1/m] per step (6.25 Hz) to follow instead "
                                   "of the bends, e.g. a recorded drive's")
    ap.add_argument("--gain", type=float, default=0.5, help="how strongly the read-back corrects the command")
    ap.add_argument("--guidance", type=float, default=16,
                    help="action guidance scale against the mirrored command (gaia eval and gaia generate steer with 16)")
    ap.add_argument("--negative", choices=["mirror", "turn", "null"], default="mirror",
                    help="what guidance contrasts a command with: its mirror image at the prompt's speed, at its own "
                         "speed (the turn alone), or no command")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", help="write every step as JSON here")
    a = ap.parse_args()
    server = a.server.rstrip("/")

    recorded = None
    if a.plan:
        with open(a.plan) as f:
            recorded = json.load(f)
        if not isinstance(recorded, list) or not all(isinstance(r, list) and len(r) == 2 for r in recorded):
            sys.exit(f"lane_keeper: {a.plan}: expected a JSON list of [speed, curvature] pairs")
    create = {"seed": a.seed, "guidance": a.guidance, "action_negative": a.negative}
    if a.episode is not None:
        create["prompt"] = {"episode": int(a.episode) if a.episode.isdigit() else a.episode, "frames": a.prompt_frames}
    session = post(server, "create", create)["session"]
    steps, window = [], []  # window: the last 4 plans, what the probe's 4 frames were driven under
    start = time.perf_counter()
    read = None
    total = int(round(a.seconds * RATE))
    if recorded is not None:
        total = min(total, len(recorded))
    for k in range(total):
        t = k / RATE
        target, held = plan(t, a.bend, a.period), a.speed
        if recorded is not None:
            held, target = recorded[k]
        curvature, speed = target, held
        if read is not None:  # feedback: what the frames show against what was planned for them
            curvature += a.gain * (sum(window) / len(window) - read["curvature"])
            speed += a.gain * (held - read["speed"])
        curvature = max(-0.05, min(0.05, curvature))
        speed = max(0.0, min(30.0, speed))
        r = post(server, "step", {"session": session, "speed": speed, "curvature": curvature})
        window = (window + [target])[-4:]
        read = r.get("read_back")
        steps.append({"t": t, "plan": target, "plan_window": sum(window) / len(window),
                      "command": {"speed": speed, "curvature": curvature}, "read_back": read, "tokens": r["tokens"],
                      "ms": r["ms"]})
        if k % int(RATE) == 0:
            rb = f"read back {read['speed']:.1f} m/s, {1000 * read['curvature']:+.1f} 1/km" if read else "no read-back yet"
            print(f"t {t:5.1f} s  plan {1000 * target:+5.1f} 1/km  command {1000 * curvature:+6.1f} 1/km "
                  f"{speed:4.1f} m/s  {rb}", flush=True)
    wall = time.perf_counter() - start
    post(server, "close", {"session": session})

    with_read = [s for s in steps if s["read_back"]]
    summary = {"steps": len(steps), "seconds": a.seconds, "wall_s": wall, "frames_per_s": len(steps) / wall}
    if with_read:
        planned = [s["plan_window"] for s in with_read]
        got = [s["read_back"]["curvature"] for s in with_read]
        turning = [(p, g) for p, g in zip(planned, got) if abs(p) >= 0.002]
        summary.update({
            "curvature_spearman": spearman(planned, got),
            "curvature_sign_accuracy": sum((p > 0) == (g > 0) for p, g in turning) / len(turning) if turning else None,
            "read_back_speed_mean": sum(s["read_back"]["speed"] for s in with_read) / len(with_read),
        })
        print(f"read-back against the plan over {len(with_read)} steps: curvature Spearman "
              f"{summary['curvature_spearman']:.3f}, sign right on {100 * summary['curvature_sign_accuracy']:.1f}% of "
              f"{len(turning)} turning steps, mean speed {summary['read_back_speed_mean']:.1f} m/s (held {a.speed})")
    else:
        print("no read-back: start the server with --probe and --tokenizer to close the loop")
    print(f"{len(steps)} steps in {wall:.1f} s: {summary['frames_per_s']:.2f} frames/s (real time: {RATE})")
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"summary": summary, "steps": steps}, f)


if __name__ == "__main__":
    main()
