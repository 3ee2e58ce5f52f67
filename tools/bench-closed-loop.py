#!/usr/bin/env python3
"""docs/evaluation.md, "Closed loop": examples/lane_keeper.py drives sessions of `gaia sim serve` (the shipped world
model, tokenizer and dynamics probe) for a minute each from prompts of a token dataset, correcting its commands by
the read-back. Reported per drive and pooled: how the read-back curvature follows the plan (Spearman, sign
accuracy), and whether the minute collapses: copy rate and unigram entropy per 10 s window (as the long rollouts of
`gaia eval --only long`), against the same statistics of the dataset's own recorded windows.

    tools/bench-closed-loop.py TOKENS [GAIA_BINARY] [SECONDS] [EPISODES] [LANE_KEEPER FLAGS...]   (standard library only)

With the flag --recorded among the lane keeper's, each drive follows its prompt episode's own recorded commands
(after the 4 prompt frames) instead of the bends, so that its minute is compared with the same drive's record.
With --reference DIR (a token dataset), the real windows are DIR's instead of TOKENS': drives of the kind the plan
drives (e.g. `gaia synth --scene bend` for the bends).
"""
import array, ast, json, math, os, socket, subprocess, sys, tempfile

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
tokens_dir = sys.argv[1]
gaia = os.path.abspath(sys.argv[2] if len(sys.argv) > 2 else os.path.join(root, "build", "gaia"))
seconds = float(sys.argv[3]) if len(sys.argv) > 3 else 60
episodes = [int(e) for e in (sys.argv[4] if len(sys.argv) > 4 else "0,1,2,3").split(",")]
keeper_flags = sys.argv[5:]
recorded = "--recorded" in keeper_flags
keeper_flags = [f for f in keeper_flags if f != "--recorded"]
reference_dir = tokens_dir
if "--reference" in keeper_flags:
    i = keeper_flags.index("--reference")
    if i + 1 >= len(keeper_flags):
        sys.exit("bench-closed-loop: --reference needs a token dataset")
    reference_dir = keeper_flags[i + 1]
    del keeper_flags[i:i + 2]
RATE, WINDOW = 6.25, 62  # Hz; a 10 s window in frames, as gaia eval's long rollouts


def read_npy(path):
    """A little-endian integer or float32 .npy array -> (shape, flat list)."""
    with open(path, "rb") as f:
        if f.read(6) != b"\x93NUMPY":
            sys.exit(f"{path}: not a .npy file")
        major = f.read(2)[0]
        hlen = int.from_bytes(f.read(2 if major == 1 else 4), "little")
        head = ast.literal_eval(f.read(hlen).decode("latin1"))
        codes = {"<i2": "h", "<i4": "i", "<i8": "q", "<u2": "H", "|u1": "B", "<f4": "f"}
        if head["descr"] not in codes or head["fortran_order"]:
            sys.exit(f"{path}: {head['descr']} tokens are not read here")
        data = array.array(codes[head["descr"]])
        data.frombytes(f.read())
        return head["shape"], list(data)


def windows_stats(frames, K=1024):
    """Copy rate and entropy (bits) of each whole 10 s window of frames (lists of n ids)."""
    out = []
    for s in range(0, len(frames) - WINDOW + 1, WINDOW):
        w = frames[s:s + WINDOW]
        same = sum(a == b for prev, cur in zip(w, w[1:]) for a, b in zip(prev, cur))
        copy = same / ((len(w) - 1) * len(w[0]))
        hist = [0] * K
        for f in w:
            for t in f:
                hist[t] += 1
        total = sum(hist)
        ent = -sum(c / total * math.log2(c / total) for c in hist if c)
        out.append((copy, ent))
    return out


def mean(xs):
    return sum(xs) / len(xs)


eps = sorted(os.listdir(os.path.join(tokens_dir, "episodes")))
real = []
reference_eps = sorted(os.listdir(os.path.join(reference_dir, "episodes")))
for e in reference_eps:
    shape, flat = read_npy(os.path.join(reference_dir, "episodes", e, "tokens.npy"))
    n = len(flat) // shape[0]
    real += windows_stats([flat[i * n:(i + 1) * n] for i in range(shape[0])])
real_copy, real_ent = mean([c for c, _ in real]), mean([h for _, h in real])

with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
models = os.path.join(root, "models")
server = subprocess.Popen([gaia, "sim", "serve", tokens_dir, "--world", os.path.join(models, "world.safetensors"),
                           "--tokenizer", os.path.join(models, "tokenizer.safetensors"),
                           "--probe", os.path.join(models, "probe-dynamics.safetensors"), "--port", str(port)],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
server.stdout.readline()  # "serving on ..."
rows, pooled = [], {"planned": [], "got": [], "windows": []}
try:
    for e in episodes:
        with tempfile.NamedTemporaryFile(suffix=".json") as out, tempfile.NamedTemporaryFile("w", suffix=".json") as plan:
            flags = list(keeper_flags)
            if recorded:  # the episode's commands after its 4 prompt frames
                shape, flat = read_npy(os.path.join(tokens_dir, "episodes", eps[e], "actions.npy"))
                json.dump([[flat[2 * i], flat[2 * i + 1]] for i in range(4, shape[0])], plan)
                plan.flush()
                flags += ["--plan", plan.name]
            subprocess.run([sys.executable, os.path.join(root, "examples", "lane_keeper.py"), "--server",
                            f"http://127.0.0.1:{port}", "--episode", eps[e], "--seconds", str(seconds), "--seed", str(e),
                            "--out", out.name] + flags, check=True, stdout=subprocess.DEVNULL)
            d = json.load(open(out.name))
        steps = d["steps"]
        w = windows_stats([s["tokens"] for s in steps])
        pooled["windows"] += w
        for s in steps:
            if s["read_back"]:
                pooled["planned"].append(s["plan_window"])
                pooled["got"].append(s["read_back"]["curvature"])
        sm = d["summary"]
        rows.append((e, sm["curvature_spearman"], sm["curvature_sign_accuracy"], sm["read_back_speed_mean"],
                     mean([c for c, _ in w]), mean([h for _, h in w]), sm["frames_per_s"]))
finally:
    server.terminate()
    server.wait()

sys.path.insert(0, os.path.join(root, "examples"))
from lane_keeper import spearman  # noqa: E402

turning = [(p, g) for p, g in zip(pooled["planned"], pooled["got"]) if abs(p) >= 0.002]
print(f"real windows ({len(real)} of {len(reference_eps)} episodes of {reference_dir}): copy rate {real_copy:.3f}, "
      f"entropy {real_ent:.2f} bits")
print("| prompt episode | curvature Spearman | sign accuracy | read-back speed | copy rate vs real | entropy vs real | frames/s |")
print("|---:|---:|---:|---:|---:|---:|---:|")
for e, sp, sign, v, c, h, fps in rows:
    print(f"| {e} | {sp:.3f} | {100 * sign:.1f}% | {v:.1f} m/s | {100 * (c / real_copy - 1):+.1f}% | "
          f"{100 * (h / real_ent - 1):+.1f}% | {fps:.2f} |")
pc, ph = mean([c for c, _ in pooled["windows"]]), mean([h for _, h in pooled["windows"]])
print(f"| all | {spearman(pooled['planned'], pooled['got']):.3f} | "
      f"{100 * sum((p > 0) == (g > 0) for p, g in turning) / len(turning):.1f}% | | {100 * (pc / real_copy - 1):+.1f}% | "
      f"{100 * (ph / real_ent - 1):+.1f}% | |")
