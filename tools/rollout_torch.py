#!/usr/bin/python3
"""PyTorch-Python peer of gaia's rollout (src/gaia/world/rollout.cpp RolloutStepper::step), on the model peer of
tools/bench_world_torch.py: the same sampling loop in plain PyTorch, for the token cross-check and the speed figure
of docs/benchmarks.md ("A rollout against a PyTorch peer").

The loop, as the C++ one:
  - every step's tokens enter a KV cache (one [B, H, capacity, hd] key and value tensor per layer);
  - a prompt frame is one step (text, image, actions) appended at once;
  - a generated frame: its text tokens, then n image tokens one at a time, each predicted from the previous
    position's output (head after ln_f), with the copy bias (model.h CopyBias) on the previous frame's
    token at that slot, chosen by argmax or top-k (softmax of the k highest / temperature, one torch.multinomial
    draw, rank -> token: gaia draws from the same distribution with one uniform number, so the sampled tokens
    differ while the work compares), then its action tokens;
  - when the context is full (T steps) the window slides by one (§2.3): the cache is emptied and the last T - 1
    steps re-enter it at temporal positions 0 .. T - 2.
No guidance (the shipped model's default) and no text prompt: actions only, as `gaia generate --steer`.

    /usr/bin/python3 tools/rollout_torch.py --bench [--world models/world.safetensors] [--frames 8] [--threads 1]
        times the peer at 1 and 16 futures (top-k), and gaia's own rollout in the same process where the gaia
        Python module is importable (PYTHONPATH=build/python), and prints JSON.
    /usr/bin/python3 tools/rollout_torch.py --check [--frames 3]
        argmax tokens of the peer and of gaia (in-process) from the same prompt: equal or exit 1.
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

try:  # before torch: gaia chooses OpenBLAS's kernels as it loads (src/gaia/torch/openblas.h), so both run the same
    import gaia
except ImportError:
    gaia = None
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import safetensors_py  # noqa: E402
from bench_tokenizer_torch import parse_config_yaml  # noqa: E402
from bench_world_torch import WorldModel, _set_openblas_threads, openblas_core  # noqa: E402

SPEED_SCALE, CURVATURE_SCALE = 10.0, 0.02  # world/batch.h: actions are fed as speed / 10 m/s, curvature / 0.02 1/m


def load_world(path):
    """The world model and its sampling settings from a gaia world file (its gaia.config metadata)."""
    tensors, meta = safetensors_py.load(path)
    grid = json.loads(meta["gaia.grid"])
    world = parse_config_yaml(meta["gaia.config"])["world"]
    cfg = {key: int(world[key]) for key in ("d_model", "n_layers", "n_heads", "context_steps", "text_tokens",
                                            "text_dim", "text_vocab", "action_tokens")}
    if int(world.get("action_mlp", 0)):
        raise ValueError(f"{path}: world.action_mlp is not in the peer")
    model = WorldModel(cfg, grid["h"] * grid["w"], grid["K"]).eval()
    model.load_gaia(tensors, path)
    sampling = {"top_k": int(world["top_k"]), "temperature": float(world["temperature"]),
                "copy_bias": float(world["copy_bias"]), "copy_bias_run": float(world.get("copy_bias_run", 0))}
    return model, sampling


class Cache:
    def __init__(self, model, B, capacity):
        H = model.cfg["n_heads"]
        hd = model.d // H
        self.k = [torch.empty(B, H, capacity, hd) for _ in model.blocks]
        self.v = [torch.empty(B, H, capacity, hd) for _ in model.blocks]
        self.length = 0


def attend_cached(attn, x, cache, layer):
    """CausalSelfAttention over the cache: x [B, L, d] appended at cache.length."""
    B, L, d = x.shape
    H = attn.heads
    hd = d // H
    q, k, v = attn.qkv(x).view(B, L, 3, H, hd).permute(2, 0, 3, 1, 4)  # each [B, H, L, hd]
    o = cache.length
    cache.k[layer][:, :, o:o + L] = k
    cache.v[layer][:, :, o:o + L] = v
    K, V = cache.k[layer][:, :, :o + L], cache.v[layer][:, :, :o + L]
    att = torch.matmul(q, K.transpose(-2, -1)) * (1.0 / math.sqrt(hd))  # [B, H, L, o + L]
    if L > 1:  # query i sits at o + i and sees keys <= o + i
        att = att.masked_fill(torch.arange(o + L).view(1, -1) > (o + torch.arange(L)).view(-1, 1), float("-inf"))
    y = torch.matmul(torch.softmax(att, -1), V)
    return attn.proj(y.transpose(1, 2).reshape(B, L, d))


def body(model, x, cache):
    """The blocks over x [B, L, d] appended to the cache, then ln_f."""
    for i, blk in enumerate(model.blocks):
        h = x + attend_cached(blk.attn, blk.ln1(x), cache, i)
        x = h + blk.fc_proj(F.gelu(blk.fc(blk.ln2(h))))
    cache.length += x.shape[1]
    return model.ln_f(x)


def rollout(model, prompt, actions, frames, futures=1, strategy="top-k", top_k=50, temperature=1.0, copy_bias=0.0,
            seed=0, copy_bias_run=0.0):
    """prompt: int64 [P, n]; actions: float32 [P + frames, 2] normalised (NaN: none) or None -> [N, P + F, n]."""
    N, P, n, T, d = futures, prompt.shape[0], model.n, model.T, model.d
    steps = P + frames
    gen = torch.Generator().manual_seed(seed)
    tokens = torch.zeros(N, steps, n, dtype=torch.long)
    cache = Cache(model, N, T * model.S)
    acts = None if actions is None else actions.view(1, steps, 2).expand(N, steps, 2)

    def step_actions(a, b):
        return None if acts is None else acts[:, a:b]

    win = 0
    with torch.no_grad():
        for k in range(steps):
            if win == T:  # slide by one: the last T - 1 steps again, at temporal positions 0 .. T - 2
                first = k - (T - 1)
                cache.length = 0
                body(model, model.embed(tokens[:, first:k], step_actions(first, k)), cache)
                win = T - 1
            if k < P:  # a prompt frame: the whole step at once
                tokens[:, k] = prompt[k]
                body(model, embed_at(model, tokens[:, k:k + 1], step_actions(k, k + 1), win), cache)
                win += 1
                continue
            ak = step_actions(k, k + 1)
            h = body(model, embed_at(model, tokens[:, k:k + 1], ak, win, part="text"), cache)
            nxt = model.head(h[:, -1])  # [N, K] predicting z_0
            for i in range(n):
                lg = nxt
                if k > 0 and (copy_bias != 0 or copy_bias_run != 0):
                    # model.h CopyBias: copy_bias_run more where slot i - 1 kept its previous frame's code
                    run = (tokens[:, k, i - 1] == tokens[:, k - 1, i - 1]) if i > 0 else torch.zeros(N, dtype=torch.bool)
                    bias = torch.where(run, torch.tensor(copy_bias + copy_bias_run, dtype=torch.float64),
                                       torch.tensor(copy_bias, dtype=torch.float64)).to(lg.dtype).view(N, 1)
                    lg = lg.scatter_add(-1, tokens[:, k - 1, i:i + 1], bias)
                if strategy == "argmax":
                    tok = lg.argmax(-1)
                else:
                    vals, idx = lg.topk(min(top_k, lg.shape[-1]), -1)
                    pick = torch.multinomial(torch.softmax(vals / temperature, -1), 1, False, generator=gen)
                    tok = idx.gather(-1, pick).squeeze(-1)
                tokens[:, k, i] = tok
                if i + 1 < n:
                    x = model.token_embedding(tok).view(N, 1, d) + model.temporal_pos[win] + \
                        model.spatial_pos[model.m + i]
                    nxt = model.head(body(model, x, cache)[:, 0])
                else:  # the last token only enters the cache
                    x = model.token_embedding(tok).view(N, 1, d) + model.temporal_pos[win] + \
                        model.spatial_pos[model.m + i]
                    body(model, x, cache)
            body(model, embed_at(model, tokens[:, k:k + 1], ak, win, part="actions"), cache)
            win += 1
    return tokens


def embed_at(model, tokens, actions, t0, part="all"):
    """model.embed of one step [N, 1, n] at temporal position t0 (the peer's embed starts at 0): the step's text,
    image and action tokens, or only its text or actions."""
    N = tokens.shape[0]
    shift = model.temporal_pos[t0] - model.temporal_pos[0]
    if part == "text":
        return (model.embed_text(N, 1) + shift).view(N, model.m, model.d)
    if part == "actions":
        return (model.embed_actions(N, 1, actions) + shift).view(N, model.l, model.d)
    return model.embed(tokens, actions) + shift


def prompt_case(model, P, frames, seed=0):
    """Random prompt tokens and a gentle left turn at 8 m/s, as the C++ benchmarks' prompts."""
    g = torch.Generator().manual_seed(seed)
    prompt = torch.randint(0, model.K, (P, model.n), generator=g)
    actions = torch.tensor([[8.0, 0.004]] * (P + frames))
    return prompt, actions


def normalised(actions):
    a = actions.clone()
    a[:, 0] /= SPEED_SCALE
    a[:, 1] /= CURVATURE_SCALE
    return a


def gaia_rollout(world, prompt, actions, frames, futures, strategy, seed):
    grid = world.grid
    p = prompt.numpy().astype("int16").reshape(-1, *grid)
    out = world.rollout(prompt=p, prompt_actions=actions[:prompt.shape[0]].numpy(),
                        actions=actions[prompt.shape[0]:].numpy(), frames=frames, futures=futures,
                        sampling=strategy, guidance=0.0, seed=seed)
    return torch.from_numpy(out.astype("int64")).view(futures, -1, prompt.shape[1])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap.add_argument("--world", default=os.path.join(root, "models", "world.safetensors"))
    ap.add_argument("--bench", action="store_true", help="time the peer (and gaia in-process) at 1 and 16 futures")
    ap.add_argument("--check", action="store_true", help="argmax tokens of the peer against gaia's: equal or exit 1")
    ap.add_argument("--frames", type=int, default=8, help="frames generated after a 7-frame prompt (default 8)")
    ap.add_argument("--threads", type=int, default=1, help="intra-op threads, both sides (default 1, as gaia sim)")
    ap.add_argument("--repeats", type=int, default=3, help="timed rollouts per case (median; default 3)")
    args = ap.parse_args()
    if not (args.bench or args.check):
        ap.error("give --bench or --check")
    torch.set_num_threads(args.threads)
    _set_openblas_threads(args.threads)
    if gaia is not None:
        gaia.set_threads(args.threads)
    model, s = load_world(args.world)
    world = gaia.WorldModel(args.world) if gaia is not None else None
    P = model.T - 1  # a full context from the first generated frame on: every frame slides the window
    prompt, actions = prompt_case(model, P, args.frames)
    if args.check:
        if world is None:
            sys.exit("rollout_torch.py --check: the gaia Python module is not importable (PYTHONPATH=build/python)")
        peer = rollout(model, prompt, normalised(actions), args.frames, strategy="argmax", copy_bias=s["copy_bias"],
                       copy_bias_run=s["copy_bias_run"])
        ours = gaia_rollout(world, prompt, actions, args.frames, 1, "argmax", 0)
        same = torch.equal(peer, ours)
        print(json.dumps({"frames": args.frames, "tokens": peer[:, P:].numel(), "identical": same,
                          "differing": int((peer != ours).sum())}))
        sys.exit(0 if same else 1)
    result = {"torch": torch.__version__, "threads": args.threads, "frames": args.frames, "prompt_frames": P,
              "openblas_core": openblas_core(), "cases": []}
    for futures in (1, 16):
        row = {"futures": futures}
        sides = [("peer", lambda: rollout(model, prompt, normalised(actions), args.frames, futures, "top-k",
                                          s["top_k"], s["temperature"], s["copy_bias"],
                                          copy_bias_run=s["copy_bias_run"]))]
        if world is not None:
            sides.append(("gaia", lambda: gaia_rollout(world, prompt, actions, args.frames, futures, "top-k", 0)))
        for name, run in sides:
            run()  # warm-up
            times = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                run()
                times.append(time.perf_counter() - t0)
            row[name + "_ms_per_frame"] = 1000 * statistics.median(times) / args.frames
        if "gaia_ms_per_frame" in row:
            row["gaia_speedup"] = row["peer_ms_per_frame"] / row["gaia_ms_per_frame"]
        result["cases"].append(row)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
