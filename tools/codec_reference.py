#!/usr/bin/python3
"""What a classical image codec reaches at the tokenizer's bit budget: the rate-distortion reference of
docs/evaluation.md ("Tokenizer", the codec column).

Each frame of a token grid carries n x log2(K) bits (144 x 10 = 1440 at 72x128). HEVC intra (x265, every frame a key
frame, 4:4:4, constant quality) codes the same frames; a frame's bits are its packet's, the stream's headers left
out (the first packet's). For each episode it prints the best PSNR at or under the budget and the fewest bits that
reach a target PSNR, then the median and worst episode, as the tokenizer's figures are given.

    PYTHONPATH=build/python /usr/bin/python3 tools/codec_reference.py DATASET --episodes ID [ID ...]
        [--frames 24] [--bits 1440] [--target-db 25] [--json FILE]

Needs ffmpeg with libx265 and the gaia module (frames as the dataset stores them, at its size).
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np


def psnr(a, b):
    """Mean over frames of each frame's PSNR (uint8 [F, H, W, 3])."""
    mse = ((a.astype(np.float64) - b.astype(np.float64)) ** 2).reshape(len(a), -1).mean(1)
    return float(np.mean(10 * np.log10(255.0 ** 2 / np.maximum(mse, 1e-10))))


def hevc_intra(frames, crf, workdir):
    """(bits per frame, PSNR) of x265 intra at this constant-quality setting (0..51)."""
    f, h, w, _ = frames.shape
    path = os.path.join(workdir, "x.mkv")
    subprocess.run(["ffmpeg", "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}",
                    "-i", "-", "-c:v", "libx265", "-pix_fmt", "yuv444p", "-x265-params",
                    f"keyint=1:crf={crf}:log-level=error:info=0:aud=0:hash=0", path],
                   input=frames.tobytes(), check=True)
    probe = subprocess.run(["ffprobe", "-v", "error", "-show_packets", "-of", "json", path], capture_output=True,
                           text=True, check=True)
    sizes = [int(p["size"]) * 8 for p in json.loads(probe.stdout)["packets"]]
    if len(sizes) != f:
        raise RuntimeError(f"x265 gave {len(sizes)} packets for {f} frames")
    out = subprocess.run(["ffmpeg", "-loglevel", "error", "-i", path, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
                         capture_output=True, check=True).stdout
    decoded = np.frombuffer(out, np.uint8).reshape(frames.shape)
    return float(np.mean(sizes[1:] if f > 1 else sizes)), psnr(frames, decoded)


def curve(frames, workdir, crfs=range(20, 52)):
    """[(crf, bits per frame, PSNR)] over constant-quality settings."""
    return [(crf,) + hevc_intra(frames, crf, workdir) for crf in crfs]


def reference(points, bits, target_db):
    """The best PSNR within `bits` and the fewest bits reaching `target_db`, from a curve's points."""
    within = [c for c in points if c[1] <= bits]
    reaching = [c for c in points if c[2] >= target_db]
    return {
        "curve": [{"crf": c, "bits": b, "psnr": p} for c, b, p in points],
        "psnr_at_budget": max(within, key=lambda c: c[2])[2] if within else None,
        "fewest_bits": min(c[1] for c in points),
        "bits_for_target": min(reaching, key=lambda c: c[1])[1] if reaching else None,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", help="episode dataset (gaia ingest / gaia synth)")
    ap.add_argument("--episodes", nargs="+", required=True, help="episode ids (e.g. the held-out clips)")
    ap.add_argument("--frames", type=int, default=24, help="frames spread evenly over each episode")
    ap.add_argument("--bits", type=float, default=144 * 10, help="bits per frame (n tokens x log2 K)")
    ap.add_argument("--target-db", type=float, default=25.0)
    ap.add_argument("--json", help="also write the figures here")
    a = ap.parse_args()
    import gaia  # the module of this build (PYTHONPATH=build/python)

    ds = gaia.Dataset(a.dataset)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for eid in a.episodes:
            ep = ds[eid]
            n = len(ep.time_s)
            idx = np.linspace(0, n - 1, min(a.frames, n)).astype(int)
            frames = np.stack([ep.frames(int(i), int(i) + 1)[0] for i in idx])
            r = reference(curve(frames, tmp), a.bits, a.target_db)
            results[eid] = r
            at = f"{r['psnr_at_budget']:.2f} dB" if r["psnr_at_budget"] is not None else \
                f"none: the coarsest setting needs {r['fewest_bits']:.0f} bits"
            need = f"{r['bits_for_target']:.0f} bits" if r["bits_for_target"] is not None else "more than the finest"
            print(f"{eid}: at {a.bits:.0f} bits {at}; {a.target_db:g} dB needs {need}", flush=True)
    at = sorted(r["psnr_at_budget"] if r["psnr_at_budget"] is not None else -math.inf for r in results.values())
    med = float(np.median(at))
    print(f"median episode {med:.2f} dB, worst {at[0]:.2f} dB (-inf: over the budget at every setting)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"bits": a.bits, "target_db": a.target_db, "median": med, "worst": at[0], "episodes": results},
                      f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
