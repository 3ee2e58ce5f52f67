#!/usr/bin/env python3
"""The lane keeper of lane_keeper.py, in-process: the same plan (straight, a left bend, straight, a right bend)
and the same correction by what the frames show (the dynamics probe's read-back), with the world model inside
this Python process through the `gaia` module instead of `gaia sim serve` over HTTP (docs/python.md):

    PYTHONPATH=build/python examples/lane_keeper_inprocess.py --seconds 30

The prompt is an episode of a token dataset (--tokens DIR --episode ID), a video file (--video FILE), or nothing.
It prints a line a second and the same summary as lane_keeper.py.
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from lane_keeper import RATE, plan, spearman  # noqa: E402  (the plan and the score are the HTTP example's)

import gaia  # noqa: E402

MODELS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "models")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--world", default=os.path.join(MODELS, "world.safetensors"))
    ap.add_argument("--tokenizer", default=os.path.join(MODELS, "tokenizer.safetensors"))
    ap.add_argument("--probe", default=os.path.join(MODELS, "probe-dynamics.safetensors"))
    ap.add_argument("--tokens", help="token dataset whose episode is the prompt")
    ap.add_argument("--episode", default="0", help="episode id or index in --tokens")
    ap.add_argument("--video", help="a video file as the prompt instead")
    ap.add_argument("--prompt-frames", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=30)
    ap.add_argument("--speed", type=float, default=8)
    ap.add_argument("--bend", type=float, default=0.01)
    ap.add_argument("--period", type=float, default=16)
    ap.add_argument("--gain", type=float, default=0.5)
    ap.add_argument("--guidance", type=float, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1, help="LibTorch threads (closed loop: 1 is fastest)")
    a = ap.parse_args()
    gaia.set_threads(a.threads)

    sim = gaia.Sim(a.world, a.tokenizer, probe=a.probe)
    prompt = actions = None
    if a.tokens:
        ds = gaia.Dataset(a.tokens)
        ep = ds[int(a.episode) if a.episode.isdigit() else a.episode]
        prompt, actions = ep.tokens[:a.prompt_frames], ep.actions[:a.prompt_frames]
    elif a.video:
        prompt = sim.tokenizer.encode_video(a.video, a.prompt_frames)
    session = sim.create(prompt=prompt, prompt_actions=actions, seed=a.seed, guidance=a.guidance)

    window, read, planned, got = [], None, [], []
    start = time.perf_counter()
    total = int(round(a.seconds * RATE))
    for k in range(total):
        t = k / RATE
        target = plan(t, a.bend, a.period)
        curvature, speed = target, a.speed
        if read is not None:
            curvature += a.gain * (sum(window) / len(window) - read["curvature"])
            speed += a.gain * (a.speed - read["speed"])
        curvature = max(-0.05, min(0.05, curvature))
        speed = max(0.0, min(30.0, speed))
        r = session.step(speed, curvature)  # r["frame"]: the frame as an RGB array, for a policy that looks
        window = (window + [target])[-4:]
        read = r["read_back"]
        if read is not None:
            planned.append(sum(window) / len(window))
            got.append(read["curvature"])
        if k % int(RATE) == 0:
            rb = f"read back {read['speed']:.1f} m/s, {1000 * read['curvature']:+.1f} 1/km" if read else "no read-back yet"
            print(f"t {t:5.1f} s  plan {1000 * target:+5.1f} 1/km  command {1000 * curvature:+6.1f} 1/km "
                  f"{speed:4.1f} m/s  {rb}", flush=True)
    wall = time.perf_counter() - start
    turning = [(p, g) for p, g in zip(planned, got) if abs(p) >= 0.002]
    if got:
        sign = sum((p > 0) == (g > 0) for p, g in turning) / len(turning) if turning else float("nan")
        print(f"read-back against the plan over {len(got)} steps: curvature Spearman {spearman(planned, got):.3f}, "
              f"sign right on {100 * sign:.1f}% of {len(turning)} turning steps")
    print(f"{total} steps in {wall:.1f} s: {total / wall:.2f} frames/s (real time: {RATE})")


if __name__ == "__main__":
    main()
