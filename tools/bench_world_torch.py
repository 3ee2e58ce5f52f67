#!/usr/bin/python3
"""PyTorch-Python peer of gaia's world model (src/gaia/world/{model,transformer}.cpp, layout.h).

The modules below mirror the C++ WorldModel and use the same parameter names (token_embedding.weight,
word_embedding.weight, text_proj.*, speed_proj.*, curvature_proj.*, null_text, null_action, temporal_pos,
spatial_pos, blocks.{i}.{ln1,attn.qkv,attn.proj,ln2,fc,fc_proj}.*, ln_f.*, head.weight), so weights written here
load into the C++ model with gaia::load_module's strict name and shape checks, and gaia world files load here.
Semantics follow the C++ code:
  - per step t the sequence is [m text | n image | l = 2 action] tokens (S = m + n + l), steps concatenated;
  - text: word_embedding(text_ids clamped to [0, text_vocab)) -> text_proj, or precomputed text_emb -> text_proj;
    the learned null_text where use_text is false (or no text is given);
  - actions: speed_proj / curvature_proj (Linear(1, d)) on each scalar; a NaN entry -> that null_action token;
    use_action false (or no actions) -> null_action for the whole example;
  - every token gets + temporal_pos[t] + spatial_pos[slot];
  - pre-LN blocks: x + attn(ln1(x)), then + fc_proj(gelu(fc(ln2(x)))) with exact (erf) GELU and a 4d MLP;
    attention is the manual causal softmax (the LibTorch 1.13 path of transformer.cpp attend());
  - ln_f, then head (no bias) only at the outputs that predict image tokens, flat index t*S + m + i - 1;
    logits [B, T, n, K]; loss = mean cross-entropy over image tokens (image_token_loss).

Modes:
  --make-fixture OUT_DIR
      tiny-config world model (configs/tiny.yaml world: d_model 48, n_layers 2, n_heads 4, context_steps 4,
      text_tokens 2, text_dim 16, text_vocab 128) with n = 6 image tokens and K = 32 codes, seeded random weights
      (normal std 0.1 everywhere, LayerNorm gains 1 + N(0, 0.1^2)), and a batch B = 2, T = 3 (one NaN action
      entry in example 0, use_action = [true, false], use_text = [true, true]). Writes
        OUT_DIR/world_peer.safetensors     the weights (F32), loadable by gaia::load_module
        OUT_DIR/world_peer_io.safetensors  tokens I64 [B,T,n], actions F32 [B,T,2], text_ids I64 [B,T,m],
                                           use_action U8 [B], use_text U8 [B], logits F32 [B,T,n,K], loss F32 [1]
      The checked-in copies in tests/fixtures/world_peer/ were made with (default --threads 2; --threads 1 moves the
      logits by ~3e-7 relative through OpenBLAS's summation order, far inside the test's 1e-4)
        /usr/bin/python3 tools/bench_world_torch.py --make-fixture tests/fixtures/world_peer
      and are read by tests/world_peer_test.cpp. Before writing, the peer checks itself (head at the predictor
      positions = full head gathered by hand, causality, loss = manual mean NLL, strict reload reproduces logits).
  --bench [--threads N] [--repeats R]
      time one AdamW training step (zero_grad, forward, loss, backward, step) of the default-config world model
      (config.h WorldConfig defaults: d_model 192, n_layers 4, n_heads 6, context_steps 8, text_tokens 16,
      text_dim 128, text_vocab 2048; n = 144, K = 1024) at the default batch 4 with random tokens, actions and text ids, the
      same case as bench/world_bench.cpp BM_WorldTrainStep (AdamW lr 1e-4, betas (0.9, 0.95), weight decay 0.1 on
      tensors with dim >= 2 and 0 on the rest, as train::make_adamw; no gradient clipping; use_action / use_text
      left unset = all true, as the C++ bench). Prints training tokens/s = B * T * S / median step time (median of
      R timed steps after 2 warm-ups) as JSON. --threads N sets torch.set_num_threads(N) and OpenBLAS's own thread
      pool (which does the matmuls of Debian's LibTorch and otherwise starts one thread per core) to N, as gaia's
      set_torch_threads; for the C++ side that means running build/gaia_bench_world with GAIA_BENCH_THREADS=N.

Runs with Debian's /usr/bin/python3 (torch 1.13, numpy).
"""
import argparse
import ctypes
import json
import math
import os
import platform
import statistics
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import safetensors_py  # noqa: E402  (tools/safetensors_py.py)

# WorldConfig defaults from src/gaia/world/config.h; n and K from the default data/tokenizer config
# (72x128 frames, D = 8 -> 9 x 16 = 144 tokens; codebook_size 1024).
DEFAULT_WORLD = {"d_model": 192, "n_layers": 4, "n_heads": 6, "context_steps": 8, "text_tokens": 16,
                 "text_dim": 128, "text_vocab": 2048, "action_tokens": 2}
DEFAULT_N, DEFAULT_K = 144, 1024
# configs/tiny.yaml world section (the rest from the defaults).
TINY_WORLD = dict(DEFAULT_WORLD, d_model=48, n_layers=2, n_heads=4, context_steps=4, text_tokens=2, text_dim=16,
                  text_vocab=128)
FIXTURE_N, FIXTURE_K = 6, 32


# ----------------------------------------------------------------------------------------------------- model ----

class CausalSelfAttention(nn.Module):
    """transformer.cpp CausalSelfAttentionImpl without the KV cache: qkv -> [3, B, H, L, hd], causal softmax."""

    def __init__(self, d, heads):
        super().__init__()
        if d % heads:
            raise ValueError(f"d_model {d} is not divisible by n_heads {heads}")
        self.heads, self.d = heads, d
        self.qkv = nn.Linear(d, 3 * d)
        self.proj = nn.Linear(d, d)

    def forward(self, x):
        b, L, _ = x.shape
        hd = self.d // self.heads
        q, k, v = self.qkv(x).view(b, L, 3, self.heads, hd).permute(2, 0, 3, 1, 4)  # each [B, H, L, hd]
        att = torch.matmul(q, k.transpose(-2, -1)) * (1.0 / math.sqrt(hd))          # [B, H, L, L]
        if L > 1:
            qi = torch.arange(L).unsqueeze(1)
            kj = torch.arange(L).unsqueeze(0)
            att = att.masked_fill(kj > qi, float("-inf"))
        y = torch.matmul(torch.softmax(att, -1), v)                                  # [B, H, L, hd]
        return self.proj(y.transpose(1, 2).reshape(b, L, self.d))


class Block(nn.Module):
    """transformer.cpp BlockImpl: pre-LN attention and 4d GELU MLP, both residual."""

    def __init__(self, d, heads):
        super().__init__()
        self.ln1 = nn.LayerNorm(d)
        self.attn = CausalSelfAttention(d, heads)
        self.ln2 = nn.LayerNorm(d)
        self.fc = nn.Linear(d, 4 * d)
        self.fc_proj = nn.Linear(4 * d, d)

    def forward(self, x):
        h = x + self.attn(self.ln1(x))
        return h + self.fc_proj(F.gelu(self.fc(self.ln2(h))))  # exact erf GELU, as F::gelu's default


def _choose(mask, a, b):
    """model.cpp choose(): per-example mask [B] -> where(mask, a, b) over the trailing dims; None = all true."""
    if mask is None:
        return a
    m = mask.to(torch.bool).view(-1, *([1] * (a.dim() - 1)))
    return torch.where(m, a, b)


class WorldModel(nn.Module):
    """model.cpp WorldModelImpl (training / scoring forward)."""

    def __init__(self, cfg, n, K):
        super().__init__()
        c = dict(DEFAULT_WORLD, **cfg)
        if c["action_tokens"] != 2:
            raise ValueError(f"world.action_tokens must be 2, got {c['action_tokens']}")
        self.cfg, self.n, self.K, self.d = c, n, K, c["d_model"]
        self.m, self.l, self.T = c["text_tokens"], c["action_tokens"], c["context_steps"]
        self.S = self.m + n + self.l
        d = self.d
        self.token_embedding = nn.Embedding(K, d)
        self.word_embedding = nn.Embedding(c["text_vocab"], c["text_dim"])
        self.text_proj = nn.Linear(c["text_dim"], d)
        self.speed_proj = nn.Linear(1, d)
        self.curvature_proj = nn.Linear(1, d)
        self.null_text = nn.Parameter(torch.randn(self.m, d) * 0.02)
        self.null_action = nn.Parameter(torch.randn(self.l, d) * 0.02)
        self.temporal_pos = nn.Parameter(torch.randn(self.T, d) * 0.02)
        self.spatial_pos = nn.Parameter(torch.randn(self.S, d) * 0.02)
        self.blocks = nn.ModuleList([Block(d, c["n_heads"]) for _ in range(c["n_layers"])])
        self.ln_f = nn.LayerNorm(d)
        self.head = nn.Linear(d, K, bias=False)
        # The C++ initialisation (GPT-2 style), for the benchmark; fixtures overwrite it.
        with torch.no_grad():
            for k, p in self.named_parameters():
                if "weight" in k and p.dim() == 2:
                    p.normal_(0.0, 0.02)
                if "bias" in k:
                    p.zero_()
                if "proj.weight" in k and "blocks" in k:
                    p.normal_(0.0, 0.02 / math.sqrt(2.0 * c["n_layers"]))

    # -- pieces, as in model.cpp --
    def _pos(self, T, slot0, count):
        return self.temporal_pos[:T].view(1, T, 1, self.d) + self.spatial_pos[slot0:slot0 + count].view(1, 1, count, self.d)

    def embed_text(self, B, T, text_ids=None, text_emb=None, use_text=None):
        null = self.null_text.view(1, 1, self.m, self.d).expand(B, T, self.m, self.d)
        feats = None
        if text_emb is not None:
            if text_emb.shape[2] != self.m or text_emb.shape[3] != self.cfg["text_dim"]:
                raise ValueError(f"text embeddings {list(text_emb.shape)}, want [B, T, {self.m}, {self.cfg['text_dim']}]")
            feats = text_emb
        elif text_ids is not None:
            feats = self.word_embedding(text_ids.clamp(0, self.cfg["text_vocab"] - 1))
        x = _choose(use_text, self.text_proj(feats), null) if feats is not None else null
        return x + self._pos(T, 0, self.m)

    def embed_image(self, tokens):
        B, T, k = tokens.shape
        return self.token_embedding(tokens) + self._pos(T, self.m, k)

    def embed_actions(self, B, T, actions=None, use_action=None):
        null = self.null_action.view(1, 1, self.l, self.d).expand(B, T, self.l, self.d)
        x = null
        if actions is not None:
            a = actions.to(torch.float32)
            missing = torch.isnan(a)                                   # [B, T, 2]
            a0 = torch.where(missing, torch.zeros_like(a), a)          # keep NaN out of the graph
            e = torch.stack([self.speed_proj(a0[..., 0:1]), self.curvature_proj(a0[..., 1:2])], 2)  # [B, T, 2, d]
            x = torch.where(missing.unsqueeze(-1), null, e)
            x = _choose(use_action, x, null)
        return x + self._pos(T, self.m + self.n, self.l)

    def embed(self, tokens, actions=None, text_ids=None, text_emb=None, use_action=None, use_text=None):
        B, T, n = tokens.shape
        if T > self.T:
            raise ValueError(f"{T} steps exceed the context of {self.T} steps")
        if n != self.n:
            raise ValueError(f"image tokens have {n} per frame but the model was built for n = {self.n}")
        x = torch.cat([self.embed_text(B, T, text_ids, text_emb, use_text), self.embed_image(tokens),
                       self.embed_actions(B, T, actions, use_action)], 2)  # [B, T, S, d]
        return x.reshape(B, T * self.S, self.d)

    def body(self, x):
        for blk in self.blocks:
            x = blk(x)
        return self.ln_f(x)

    def predictor_index(self, T):
        """Flat output positions that predict z_{t,i}: t * S + m + i - 1 (layout.h predictor())."""
        return torch.tensor([t * self.S + self.m + i - 1 for t in range(T) for i in range(self.n)], dtype=torch.long)

    def forward(self, tokens, actions=None, text_ids=None, text_emb=None, use_action=None, use_text=None):
        B, T, _ = tokens.shape
        h = self.body(self.embed(tokens, actions, text_ids, text_emb, use_action, use_text))  # [B, T*S, d]
        return self.head(h.index_select(1, self.predictor_index(T))).view(B, T, self.n, self.K)

    def load_gaia(self, tensors, path="weights"):
        """Strict load (as gaia::load_module): same names, same shapes, float tensors widened to float32."""
        own = dict(self.named_parameters())
        extra, missing = sorted(set(tensors) - set(own)), sorted(set(own) - set(tensors))
        if extra or missing:
            raise ValueError(f"{path}: name mismatch; unexpected {extra[:5]}, missing {missing[:5]}")
        with torch.no_grad():
            for k, p in own.items():
                if tuple(tensors[k].shape) != tuple(p.shape):
                    raise ValueError(f"{path}: {k} has shape {list(tensors[k].shape)}, the model wants {list(p.shape)}")
                p.copy_(tensors[k].to(torch.float32))


def image_token_loss(logits, tokens):
    """model.cpp image_token_loss: mean cross-entropy over all image tokens."""
    return F.cross_entropy(logits.reshape(-1, logits.shape[-1]), tokens.reshape(-1).long())


def make_adamw(model, lr=1e-4, weight_decay=0.1, beta1=0.9, beta2=0.95):
    """train::make_adamw: decay on tensors with dim >= 2, none on biases and norm gains. foreach=False is the
    per-tensor loop of LibTorch's C++ AdamW (and torch 1.13's default on CPU)."""
    ps = [p for p in model.parameters() if p.requires_grad]
    groups = [{"params": [p for p in ps if p.dim() >= 2], "weight_decay": weight_decay},
              {"params": [p for p in ps if p.dim() < 2], "weight_decay": 0.0}]
    return torch.optim.AdamW(groups, lr=lr, betas=(beta1, beta2), weight_decay=weight_decay, foreach=False)


# ----------------------------------------------------------------------------------------------------- modes ----

def _self_check(model, batch, logits, loss):
    """Consistency checks of the peer on the fixture batch (raises AssertionError on failure)."""
    B, T, n = batch["tokens"].shape
    with torch.no_grad():
        # Head at the predictor positions = full head over every position, gathered by hand.
        h = model.body(model.embed(**batch))
        full = model.head(h)                              # [B, T*S, K]
        for t in range(T):
            for i in range(n):
                p = t * model.S + model.m + i - 1
                assert torch.allclose(full[:, p], logits[:, t, i], rtol=1e-5, atol=1e-6), (t, i)
        # Loss = mean of -log softmax at the true tokens.
        lp = torch.log_softmax(logits.double(), -1)
        manual = -lp.gather(-1, batch["tokens"].unsqueeze(-1)).mean().item()
        assert abs(manual - loss.item()) < 1e-5, (manual, loss.item())
        # Causality: changing z_{1,2} leaves every earlier predictor unchanged and moves the later ones.
        b2 = dict(batch, tokens=batch["tokens"].clone())
        b2["tokens"][0, 1, 2] = (b2["tokens"][0, 1, 2] + 1) % model.K
        changed = model(**b2)
        pos = 1 * model.S + model.m + 2
        for t in range(T):
            for i in range(n):
                same = torch.equal(changed[0, t, i], logits[0, t, i])
                assert same == (t * model.S + model.m + i - 1 < pos), (t, i)
        # The NaN action entry (in an example with use_action true) is embedded as its null_action token.
        e = model.embed_actions(B, T, batch["actions"], batch["use_action"])
        nan_b, nan_t, nan_j = [int(x) for x in torch.nonzero(torch.isnan(batch["actions"]))[0]]
        want = model.null_action[nan_j] + model.temporal_pos[nan_t] + model.spatial_pos[model.m + model.n + nan_j]
        assert torch.allclose(e[nan_b, nan_t, nan_j], want), "NaN action is not the null action"
        assert torch.isfinite(logits).all(), "non-finite logits"


def run_make_fixture(out_dir):
    os.makedirs(out_dir, exist_ok=True)
    torch.manual_seed(0)
    model = WorldModel(TINY_WORLD, FIXTURE_N, FIXTURE_K).eval()
    with torch.no_grad():  # non-trivial weights so the comparison exercises every tensor
        for k, p in model.named_parameters():
            p.normal_(0.0, 0.1)
            parts = k.split(".")
            if len(parts) >= 2 and parts[-2] in ("ln1", "ln2", "ln_f") and parts[-1] == "weight":
                p.add_(1.0)  # LayerNorm gains around 1
    B, T, m, n, K = 2, 3, model.m, model.n, model.K
    tokens = torch.randint(0, K, (B, T, n), dtype=torch.long)
    actions = torch.randn(B, T, 2)
    actions[0, 1, 1] = float("nan")  # example 0 uses its actions: this curvature entry becomes the null action
    text_ids = torch.randint(0, TINY_WORLD["text_vocab"], (B, T, m), dtype=torch.long)
    use_action = torch.tensor([1, 0], dtype=torch.uint8)
    use_text = torch.tensor([1, 1], dtype=torch.uint8)
    batch = {"tokens": tokens, "actions": actions, "text_ids": text_ids,
             "use_action": use_action.bool(), "use_text": use_text.bool()}
    with torch.no_grad():
        logits = model(**batch)
        loss = image_token_loss(logits, tokens)
    _self_check(model, batch, logits, loss)

    wpath = os.path.join(out_dir, "world_peer.safetensors")
    iopath = os.path.join(out_dir, "world_peer_io.safetensors")
    made_by = {"made_by": "tools/bench_world_torch.py --make-fixture"}
    safetensors_py.save(dict(model.named_parameters()), wpath, made_by)
    safetensors_py.save({"tokens": tokens, "actions": actions, "text_ids": text_ids, "use_action": use_action,
                         "use_text": use_text, "logits": logits, "loss": loss.reshape(1)}, iopath, made_by)

    # Round trip: a fresh model strictly loaded from the file reproduces the logits bit for bit.
    torch.manual_seed(123)
    again = WorldModel(TINY_WORLD, FIXTURE_N, FIXTURE_K).eval()
    again.load_gaia(safetensors_py.load(wpath)[0], wpath)
    io = safetensors_py.load(iopath)[0]
    with torch.no_grad():
        re = again(io["tokens"], io["actions"], io["text_ids"], None, io["use_action"].bool(), io["use_text"].bool())
    assert torch.equal(re, io["logits"]), "reloaded model gives different logits"
    print(json.dumps({"weights": wpath, "weights_bytes": os.path.getsize(wpath),
                      "parameters": sum(p.numel() for p in model.parameters()),
                      "io": iopath, "io_bytes": os.path.getsize(iopath),
                      "logits_shape": list(logits.shape), "loss": loss.item(),
                      "logits_abs_mean": logits.abs().mean().item()}, indent=2))


def _openblas():
    """The OpenBLAS library LibTorch loaded (Debian's libtorch sends matmuls to the system BLAS), or None. It is
    loaded with local symbols, so it is found by path in /proc/self/maps (dlopen of a loaded path returns it)."""
    libs = [None]
    try:
        with open("/proc/self/maps") as f:
            libs += sorted({ln.split()[-1] for ln in f if "libopenblas" in ln})
    except OSError:
        pass
    for lib in libs:
        try:
            h = ctypes.CDLL(lib)
            h.openblas_set_num_threads, h.openblas_get_num_threads  # noqa: B018  (both must exist)
            return h
        except (AttributeError, OSError):
            continue
    return None


def _set_openblas_threads(n):
    """gaia's set_torch_threads also sets OpenBLAS's own pthread pool to the same count; do the same here.
    Returns the OpenBLAS thread count afterwards, or None without OpenBLAS."""
    h = _openblas()
    if h is None:
        return None
    h.openblas_set_num_threads(ctypes.c_int(n))
    return int(h.openblas_get_num_threads())


def openblas_core():
    """The core type whose kernels OpenBLAS runs now ("haswell", "skylakex"), or None without OpenBLAS."""
    h = _openblas()
    if h is None or not hasattr(h, "openblas_get_corename"):
        return None
    h.openblas_get_corename.restype = ctypes.c_char_p
    return h.openblas_get_corename().decode().lower()


def run_bench(args):
    torch.manual_seed(0)
    model = WorldModel({}, DEFAULT_N, DEFAULT_K)
    model.train()
    opt = make_adamw(model)
    B, T = 4, model.T  # WorldConfig batch_size
    tokens = torch.randint(0, DEFAULT_K, (B, T, DEFAULT_N), dtype=torch.long)
    actions = torch.randn(B, T, 2)
    text_ids = torch.randint(0, model.cfg["text_vocab"], (B, T, model.m), dtype=torch.long)
    times, losses = [], []
    for i in range(2 + args.repeats):  # 2 warm-ups, then timed steps
        t0 = time.perf_counter()
        opt.zero_grad()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=args.precision == "bf16"):
            loss = image_token_loss(model(tokens, actions, text_ids), tokens)
        loss.backward()
        opt.step()
        dt = time.perf_counter() - t0
        losses.append(loss.item())
        if i >= 2:
            times.append(dt)
    med = statistics.median(times)
    seq_tokens = B * T * model.S
    print(json.dumps({
        "torch": torch.__version__, "python": platform.python_version(), "threads": torch.get_num_threads(),
        "openblas_threads": args.openblas_threads, "load_avg_before": args.load_before, "load_avg_after": os.getloadavg(),
        "case": "world train step, default config", "precision": args.precision, "openblas_core": openblas_core(),
        "batch": B, "steps": T, "S": model.S,
        "sequence_tokens_per_step": seq_tokens, "parameters": sum(p.numel() for p in model.parameters()),
        "runs": len(times), "median_s": med, "tokens_per_s": seq_tokens / med,
        "min_tokens_per_s": seq_tokens / max(times), "max_tokens_per_s": seq_tokens / min(times),
        "step_times_s": [round(t, 4) for t in times], "first_loss": losses[0], "last_loss": losses[-1]}, indent=2))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--make-fixture", metavar="OUT_DIR", help="write the tiny cross-check fixture into OUT_DIR")
    ap.add_argument("--bench", action="store_true", help="time one AdamW training step of the default world model")
    ap.add_argument("--threads", type=int, default=2, help="torch.set_num_threads (default 2)")
    ap.add_argument("--repeats", type=int, default=7, help="timed steps for --bench (>= 3; default 7)")
    ap.add_argument("--precision", choices=("fp32", "bf16"), default="fp32",
                    help="--bench: forward and loss under torch.autocast bf16, as gaia's --precision bf16 (default fp32)")
    args = ap.parse_args()
    args.load_before = os.getloadavg()
    torch.set_num_threads(args.threads)
    args.openblas_threads = _set_openblas_threads(args.threads)
    if args.bench:
        if args.repeats < 3:
            ap.error("--repeats must be >= 3")
        run_bench(args)
    elif args.make_fixture:
        run_make_fixture(args.make_fixture)
    else:
        ap.error("give --make-fixture OUT_DIR or --bench")


if __name__ == "__main__":
    main()
