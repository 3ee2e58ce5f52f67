#!/usr/bin/python3
"""PyTorch-Python peer of gaia's image tokenizer encoder (src/gaia/tokenizer/{blocks,quantizer,autoencoder}.cpp).

The modules below mirror the C++ ones layer for layer and use the same module/parameter names, so a gaia tokenizer
safetensors file (`encoder.conv_in.weight`, `encoder.body.0.conv1.weight`, `quantizer.codebook.weight`, ...) loads
with strict name and shape checks. Only the encode path is built: Encoder -> proj_in -> L2 normalise -> nearest
normalised codebook entry by cosine similarity. Decoder and DINO-head tensors in the file are ignored.

Modes:
  --weights FILE --frames-npy FILE --out FILE
      encode uint8 [N, H, W, 3] RGB frames and write the tokens [N, h, w] as int64 .npy.
  --weights FILE --check-dataset DATASET --check-tokens TOKDIR
      re-encode the frames that `gaia tokenize` used (episode.json "frames" in TOKDIR) from DATASET's raw frames.bin
      and report how many tokens agree with TOKDIR's tokens.npy, as JSON.
  --bench [--threads N] [--repeats R]
      time encode of the default config (config.h defaults, random weights) at 72x128 batch 16 and 288x512 batch 2,
      the same cases as bench/tokenizer_bench.cpp; prints frames/s (median of R runs after 2 warm-ups) as JSON.

Runs with Debian's /usr/bin/python3 (torch 1.13, numpy); PyYAML is used when importable.
"""
import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import safetensors_py  # noqa: E402  (tools/safetensors_py.py)

# TokenizerConfig defaults from src/gaia/tokenizer/config.h (the CPU-sized default config); data size 72x128.
DEFAULT_TOKENIZER = {"downsample": 8, "codebook_size": 1024, "code_dim": 16, "channels": 32,
                     "channel_mult": [1, 2, 2, 4], "res_blocks": 1, "z_channels": 128}
DEFAULT_DATA = {"height": 72, "width": 128}

# The encode cases of bench/tokenizer_bench.cpp (BM_TokenizerEncode): (height, width, batch).
BENCH_CASES = [(72, 128, 16), (288, 512, 2)]


# ----------------------------------------------------------------------------------------------------- config --

def _scalar(text):
    """YAML scalar or flow list -> python value (enough for what Config::to_yaml emits)."""
    text = text.strip()
    if text.startswith("[") and text.endswith("]"):
        inner = text[1:-1].strip()
        return [_scalar(x) for x in inner.split(",")] if inner else []
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    if text in ("true", "false"):
        return text == "true"
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def parse_config_yaml(text):
    """The config YAML from the safetensors metadata -> nested dict. Uses PyYAML when available, else a tiny
    parser for the two-level `section:\\n  key: value` layout that Config::to_yaml writes."""
    try:
        import yaml
        return yaml.safe_load(text) or {}
    except ImportError:
        pass
    out, section = {}, None
    for line in text.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        key, _, value = line.strip().partition(":")
        if line.startswith((" ", "\t")):
            if section is None:
                raise ValueError(f"config YAML: indented line outside a section: {line!r}")
            out[section][key.strip()] = _scalar(value)
        elif value.strip():
            out[key.strip()], section = _scalar(value), None
        else:
            section = key.strip()
            out[section] = {}
    return out


# ----------------------------------------------------------------------------------------------------- model ----

def group_norm(c):
    """GroupNorm with the largest group count <= 32 that divides c, eps 1e-6 (blocks.cpp group_norm)."""
    g = min(32, c)
    while c % g:
        g -= 1
    return nn.GroupNorm(g, c, eps=1e-6)


class ResBlock(nn.Module):
    """GN, SiLU, conv3x3, GN, SiLU, conv3x3, plus a 1x1 skip when widths differ (blocks.cpp ResBlockImpl)."""

    def __init__(self, cin, cout):
        super().__init__()
        self.norm1 = group_norm(cin)
        self.conv1 = nn.Conv2d(cin, cout, 3, padding=1)
        self.norm2 = group_norm(cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, padding=1)
        self.skip = nn.Conv2d(cin, cout, 1) if cin != cout else None

    def forward(self, x):
        h = self.conv1(F.silu(self.norm1(x)))
        h = self.conv2(F.silu(self.norm2(h)))
        return (self.skip(x) if self.skip is not None else x) + h


class Downsample(nn.Module):
    """Stride-2 conv3x3 (blocks.cpp DownsampleImpl)."""

    def __init__(self, c):
        super().__init__()
        self.conv = nn.Conv2d(c, c, 3, stride=2, padding=1)

    def forward(self, x):
        return self.conv(x)


class Encoder(nn.Module):
    """[B, 3, H, W] -> [B, z_channels, H/D, W/D] (autoencoder.cpp EncoderImpl)."""

    def __init__(self, t):
        super().__init__()
        mult = t["channel_mult"]
        c = t["channels"] * mult[0]
        self.conv_in = nn.Conv2d(3, c, 3, padding=1)
        body = []
        for i, m in enumerate(mult):
            co = t["channels"] * m
            for _ in range(t["res_blocks"]):
                body.append(ResBlock(c, co))
                c = co
            if i + 1 < len(mult):
                body.append(Downsample(c))
        body += [ResBlock(c, c), ResBlock(c, c)]
        self.body = nn.Sequential(*body)  # children named body.0, body.1, ... as in torch::nn::Sequential
        self.norm_out = group_norm(c)
        self.conv_out = nn.Conv2d(c, t["z_channels"], 3, padding=1)

    def forward(self, x):
        return self.conv_out(F.silu(self.norm_out(self.body(self.conv_in(x)))))


class VectorQuantizer(nn.Module):
    """Factorised, L2-normalised codes (quantizer.cpp VectorQuantizerImpl), inference path only. proj_out is kept so
    the parameter set matches the C++ module; encode does not use it."""

    def __init__(self, z_channels, code_dim, codebook_size):
        super().__init__()
        self.proj_in = nn.Linear(z_channels, code_dim)
        self.codebook = nn.Embedding(codebook_size, code_dim)
        self.proj_out = nn.Linear(code_dim, z_channels)
        with torch.no_grad():
            self.codebook.weight.normal_()

    def forward(self, z):
        """z [B, z_channels, h, w] -> token ids [B, h, w] int64."""
        b, c, h, w = z.shape
        ze = F.normalize(self.proj_in(z.permute(0, 2, 3, 1).reshape(-1, c)), dim=1)  # [N, code_dim]
        cb = F.normalize(self.codebook.weight, dim=1)                                 # [K, code_dim]
        return torch.matmul(ze, cb.t()).argmax(1).reshape(b, h, w)                   # max cosine


class TokenizerEncoder(nn.Module):
    """The encode half of ImageTokenizerImpl: x [B, 3, H, W] in [-1, 1] -> tokens [B, H/D, W/D]."""

    # Tensors of a gaia tokenizer file that belong to parts we do not build.
    IGNORED_PREFIXES = ("decoder.", "dino_head.")

    def __init__(self, tok_cfg, height, width):
        super().__init__()
        t = dict(DEFAULT_TOKENIZER, **tok_cfg)
        if 2 ** (len(t["channel_mult"]) - 1) != t["downsample"]:
            raise ValueError(f"tokenizer: channel_mult {t['channel_mult']} does not give downsample {t['downsample']}")
        if height % t["downsample"] or width % t["downsample"]:
            raise ValueError(f"tokenizer: {height}x{width} is not divisible by D = {t['downsample']}")
        self.cfg, self.height, self.width = t, height, width
        self.encoder = Encoder(t)
        self.quantizer = VectorQuantizer(t["z_channels"], t["code_dim"], t["codebook_size"])

    def forward(self, x):
        if x.dim() != 4 or x.shape[1] != 3 or x.shape[2] != self.height or x.shape[3] != self.width:
            raise ValueError(f"tokenizer: expected images [B, 3, {self.height}, {self.width}], got {list(x.shape)}")
        return self.quantizer(self.encoder(x))

    def load_gaia(self, tensors, path="weights"):
        """Strict load: every encoder/quantizer tensor in the file must be a parameter here with the same shape,
        and every parameter must be in the file. Half-precision files are widened to float32."""
        own = dict(self.named_parameters())
        mine = {k: v for k, v in tensors.items() if not k.startswith(self.IGNORED_PREFIXES)}
        extra, missing = sorted(set(mine) - set(own)), sorted(set(own) - set(mine))
        if extra or missing:
            raise ValueError(f"{path}: name mismatch; unexpected {extra[:5]}, missing {missing[:5]}")
        with torch.no_grad():
            for k, p in own.items():
                if tuple(mine[k].shape) != tuple(p.shape):
                    raise ValueError(f"{path}: {k} has shape {list(mine[k].shape)}, the model wants {list(p.shape)}")
                p.copy_(mine[k].to(torch.float32))


def load_tokenizer(path):
    """A gaia tokenizer safetensors file -> TokenizerEncoder in eval mode (config from metadata 'gaia.config')."""
    tensors, md = safetensors_py.load(path)
    if "gaia.config" not in md or md.get("gaia.component") != "tokenizer":
        raise ValueError(f"{path}: not a gaia tokenizer weights file (no gaia.config metadata)")
    cfg = parse_config_yaml(md["gaia.config"])
    data = dict(DEFAULT_DATA, **(cfg.get("data") or {}))
    model = TokenizerEncoder(cfg.get("tokenizer") or {}, int(data["height"]), int(data["width"]))
    model.load_gaia(tensors, path)
    return model.eval()


def frames_to_tensor(rgb):
    """uint8 [N, H, W, 3] RGB -> float [N, 3, H, W] in [-1, 1], same ops as autoencoder.cpp image_to_tensor."""
    t = torch.from_numpy(np.ascontiguousarray(rgb))
    return t.permute(0, 3, 1, 2).to(torch.float32).div(127.5).sub(1.0).contiguous()


@torch.no_grad()
def encode_frames(model, rgb, batch=16):
    """uint8 [N, H, W, 3] RGB -> int64 tokens [N, h, w], in batches of 16 like tokenizer/io.cpp encode_frames."""
    out = [model(frames_to_tensor(rgb[s:s + batch])) for s in range(0, len(rgb), batch)]
    return torch.cat(out).numpy().astype(np.int64)


# ----------------------------------------------------------------------------------------------------- modes ----

def run_encode(args):
    model = load_tokenizer(args.weights)
    frames = np.load(args.frames_npy)
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[3] != 3:
        raise SystemExit(f"{args.frames_npy}: expected uint8 [N, H, W, 3], got {frames.dtype} {list(frames.shape)}")
    tokens = encode_frames(model, frames)
    np.save(args.out, tokens)
    print(json.dumps({"frames": int(len(frames)), "tokens_shape": list(tokens.shape), "out": args.out}))


def run_check(args):
    """Compare against `gaia tokenize` output: per episode, the frames listed in TOKDIR's episode.json are read from
    DATASET's raw frames.bin, encoded here, and compared with TOKDIR's tokens.npy."""
    model = load_tokenizer(args.weights)
    ep_root = os.path.join(args.check_tokens, "episodes")
    same = total = 0
    per_episode = {}
    for ep in sorted(os.listdir(ep_root)):
        with open(os.path.join(ep_root, ep, "episode.json")) as f:
            idx = json.load(f)["frames"]
        src = os.path.join(args.check_dataset, "episodes", ep)
        with open(os.path.join(src, "episode.json")) as f:
            m = json.load(f)
        if m["frame_codec"] != "raw":
            raise SystemExit(f"{src}: frame_codec {m['frame_codec']}; only raw frames are supported here")
        frames = np.memmap(os.path.join(src, "frames.bin"), np.uint8, "r",
                           shape=(m["num_frames"], m["height"], m["width"], 3))
        rgb = np.asarray(frames[idx])
        if args.save_frames:  # keep the exact frames so the --frames-npy mode can be rerun on them
            np.save(os.path.join(args.save_frames, ep + ".npy"), rgb)
        ours = encode_frames(model, rgb)
        theirs = np.load(os.path.join(ep_root, ep, "tokens.npy")).astype(np.int64)
        if ours.shape != theirs.shape:
            raise SystemExit(f"{ep}: token shapes differ: python {ours.shape}, gaia {theirs.shape}")
        n = int((ours == theirs).sum())
        per_episode[ep] = {"steps": len(idx), "tokens": int(ours.size), "identical": n}
        same, total = same + n, total + int(ours.size)
    print(json.dumps({"tokens": total, "identical": same, "agreement": same / max(total, 1),
                      "episodes": per_episode}, indent=2))


def run_bench(args):
    results = []
    for h, w, b in BENCH_CASES:
        torch.manual_seed(0)
        model = TokenizerEncoder({}, h, w).eval()  # default config, random weights, data size overridden
        x = torch.rand(b, 3, h, w) * 2 - 1
        times = []
        with torch.no_grad():
            for i in range(2 + args.repeats):  # 2 warm-ups, then timed runs
                t0 = time.perf_counter()
                model(x)
                if i >= 2:
                    times.append(time.perf_counter() - t0)
        med = statistics.median(times)
        results.append({"case": f"{h}x{w}/batch{b}", "height": h, "width": w, "batch": b, "runs": len(times),
                        "median_s": med, "frames_per_s": b / med,
                        "min_frames_per_s": b / max(times), "max_frames_per_s": b / min(times)})
    print(json.dumps({"torch": torch.__version__, "python": platform.python_version(),
                      "threads": torch.get_num_threads(), "load_avg": os.getloadavg(), "results": results}, indent=2))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", help="gaia tokenizer .safetensors (config read from its metadata)")
    ap.add_argument("--frames-npy", help="uint8 [N, H, W, 3] RGB frames to encode")
    ap.add_argument("--out", help="where --frames-npy writes the int64 tokens .npy")
    ap.add_argument("--check-dataset", help="episode dataset whose frames `gaia tokenize` encoded")
    ap.add_argument("--check-tokens", help="token dataset written by `gaia tokenize` from --check-dataset")
    ap.add_argument("--save-frames", help="with --check-*: also save each episode's encoded frames as DIR/<id>.npy")
    ap.add_argument("--bench", action="store_true", help="time encode at 72x128 b16 and 288x512 b2")
    ap.add_argument("--threads", type=int, default=2, help="torch.set_num_threads (default 2)")
    ap.add_argument("--repeats", type=int, default=7, help="timed runs per case for --bench (>= 5; default 7)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    if args.bench:
        if args.repeats < 5:
            ap.error("--repeats must be >= 5")
        run_bench(args)
    elif args.weights and args.frames_npy:
        if not args.out:
            ap.error("--frames-npy needs --out")
        run_encode(args)
    elif args.weights and args.check_dataset and args.check_tokens:
        run_check(args)
    else:
        ap.error("give --bench, or --weights with --frames-npy/--out, or --weights with --check-dataset/--check-tokens")


if __name__ == "__main__":
    main()
