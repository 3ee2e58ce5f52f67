"""A plain-PyTorch T5 encoder, the cross-check for gaia's C++ one (src/gaia/text/t5.cpp, paper §2.1: each step's text
is encoded by a frozen T5 into m tokens). It follows Hugging Face's T5EncoderModel in eval mode: RMS layer norms,
unscaled dot-product attention with a bucketed relative position bias from block 0, pre-norm residuals, a ReLU or a
gated-GELU feed-forward. The transformers library is not needed.

  /usr/bin/python3 tools/t5_peer.py --make-fixture     # writes tests/fixtures/t5/ (run from the repository root)
  /usr/bin/python3 tools/t5_peer.py --make-encoder DIR --captions FILE [--vocab 1000 --d-model 128 --layers 2]

--make-encoder writes a small random-weight T5 v1.1 encoder in Hugging Face's layout, with a SentencePiece model
trained on FILE's captions (one a line): a stand-in text encoder where no pretrained T5 can be had (docs/evaluation.md,
"Text control": the built-in words against T5 embeddings on the same data).

The fixture: a tiny SentencePiece model trained on captions written like the procedural world's, two tiny
random-weight encoders in Hugging Face's naming (relu/: T5, F32, with decoder tensors the encoder must ignore;
gated/: T5 v1.1, BF16, embedding stored as encoder.embed_tokens.weight) and t5_io.safetensors holding, for a few
captions, the token ids and both encoders' outputs at m = 12.
"""
import argparse
import io
import json
import math
import os
import random
import shutil
import sys

import sentencepiece as spm
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import safetensors_py  # noqa: E402

EOS, PAD = 1, 0
M = 12
IO_CAPTIONS = [  # short (padded), empty, longer than M (truncated), and outside the training text (unknown pieces)
    "night, rain",
    "dusk, fog, stopped",
    "",
    "a sunny day in the city, driving straight at 12 m/s, a car ahead",
    "Zebra café",
]


# ---- the encoder ----------------------------------------------------------------------------------------------

def bucket(rel, num_buckets, max_distance):
    """Relative position (key - query) -> bucket: half the buckets per sign, exact below a quarter, log-spaced
    beyond up to max_distance (Hugging Face's _relative_position_bucket, bidirectional)."""
    half = num_buckets // 2
    out = (rel > 0).long() * half
    rel = rel.abs()
    exact = half // 2
    far = exact + (torch.log(rel.float() / exact) / math.log(max_distance / exact) * (half - exact)).long()
    far = torch.minimum(far, torch.full_like(far, half - 1))
    return out + torch.where(rel < exact, rel, far)


def rms_norm(x, w, eps):
    return w * (x * torch.rsqrt(x.float().pow(2).mean(-1, keepdim=True) + eps))


def gelu_new(x):
    return 0.5 * x * (1.0 + torch.tanh(math.sqrt(2.0 / math.pi) * (x + 0.044715 * x.pow(3))))


def encode(w, cfg, ids, mask):
    """ids, mask: [N, L] -> [N, L, d] (Hugging Face's last_hidden_state; padded positions not zeroed)."""
    n, length = ids.shape
    heads, dkv = cfg["num_heads"], cfg["d_kv"]
    eps = cfg.get("layer_norm_epsilon", 1e-6)
    emb = w["shared.weight"] if "shared.weight" in w else w["encoder.embed_tokens.weight"]
    x = emb[ids]
    pos = torch.arange(length)
    buckets = bucket(pos[None, :] - pos[:, None], cfg.get("relative_attention_num_buckets", 32),
                     cfg.get("relative_attention_max_distance", 128))
    bias = w["encoder.block.0.layer.0.SelfAttention.relative_attention_bias.weight"][buckets]  # [L, L, H]
    bias = bias.permute(2, 0, 1)[None] + (1.0 - mask[:, None, None, :].float()) * torch.finfo(torch.float32).min
    for i in range(cfg["num_layers"]):
        p = f"encoder.block.{i}.layer."
        h = rms_norm(x, w[p + "0.layer_norm.weight"], eps)
        q, k, v = (torch.nn.functional.linear(h, w[p + f"0.SelfAttention.{t}.weight"])
                   .view(n, length, heads, dkv).transpose(1, 2) for t in "qkv")
        att = torch.softmax(q @ k.transpose(2, 3) + bias, dim=-1)  # T5 does not scale by 1/sqrt(d_kv)
        x = x + torch.nn.functional.linear((att @ v).transpose(1, 2).reshape(n, length, heads * dkv),
                                           w[p + "0.SelfAttention.o.weight"])
        h = rms_norm(x, w[p + "1.layer_norm.weight"], eps)
        f = p + "1.DenseReluDense."
        if cfg["feed_forward_proj"] == "gated-gelu":
            h = gelu_new(h @ w[f + "wi_0.weight"].T) * (h @ w[f + "wi_1.weight"].T)
        else:
            h = torch.relu(h @ w[f + "wi.weight"].T)
        x = x + h @ w[f + "wo.weight"].T
    return rms_norm(x, w["encoder.final_layer_norm.weight"], eps)


def tokenize(sp, text):
    """SentencePiece ids + </s>, as Hugging Face's T5 tokenizers give them."""
    return sp.encode(text) + [EOS]


def batch(sp, captions, m):
    """[N, m] ids and mask: truncated keeping </s> last, padded with 0; an empty caption is all padding."""
    ids, mask = torch.zeros(len(captions), m, dtype=torch.long), torch.zeros(len(captions), m, dtype=torch.long)
    for i, c in enumerate(captions):
        t = tokenize(sp, c)[:m] if c else []
        if t:
            t[-1] = EOS
        ids[i, :len(t)] = torch.tensor(t, dtype=torch.long)
        mask[i, :len(t)] = 1
    return ids, mask


def encode_captions(w, cfg, sp, captions, m):
    ids, mask = batch(sp, captions, m)
    with torch.no_grad():
        return encode(w, cfg, ids, mask) * mask[..., None]


# ---- the fixture ----------------------------------------------------------------------------------------------

def captions(count, seed=0):
    """Captions in the procedural world's manner: time of day, weather, road, manoeuvre, speed, other agents."""
    r = random.Random(seed)
    times = ["a sunny day", "night", "dusk", "dawn", "an overcast afternoon", "early morning", "evening"]
    weather = ["", "rain", "heavy rain", "fog", "snow", "light drizzle", "clear sky"]
    roads = ["in the city", "on a country road", "on the motorway", "in a residential street", "at a junction",
             "near a roundabout", "on a wet road"]
    moves = ["driving straight", "turning left", "turning right", "slowing down", "speeding up", "stopped",
             "changing lanes", "overtaking"]
    agents = ["", "a car ahead", "a bus ahead", "a cyclist on the left", "pedestrians crossing", "a truck behind",
              "traffic lights ahead", "no other traffic"]
    out = []
    for _ in range(count):
        parts = [r.choice(times), r.choice(weather), r.choice(roads)]
        move = r.choice(moves)
        parts.append(move if move == "stopped" else f"{move} at {r.randint(2, 30)} m/s")
        parts.append(r.choice(agents))
        out.append(", ".join(p for p in parts if p))
    return out


def train_spm(texts, vocab_size=200):
    """A unigram model with T5's special ids (pad 0, </s> 1, unk 2, no <s>). The identity normalization keeps the
    file small (nmt_nfkc would add its ~200 KB character map); both sides run the same SentencePiece library."""
    model = io.BytesIO()
    spm.SentencePieceTrainer.train(sentence_iterator=iter(texts), model_writer=model, vocab_size=vocab_size,
                                   model_type="unigram", pad_id=0, eos_id=1, unk_id=2, bos_id=-1,
                                   hard_vocab_limit=False, normalization_rule_name="identity",
                                   minloglevel=2)
    return model.getvalue()


def random_weights(cfg, gen, extra):
    d, inner, dff, vocab = cfg["d_model"], cfg["num_heads"] * cfg["d_kv"], cfg["d_ff"], cfg["vocab_size"]

    def lin(o, i):
        return torch.randn(o, i, generator=gen) / math.sqrt(i)

    def norm():
        return 1.0 + 0.2 * torch.randn(d, generator=gen)

    w = {"shared.weight": torch.randn(vocab, d, generator=gen), "encoder.final_layer_norm.weight": norm(),
         "encoder.block.0.layer.0.SelfAttention.relative_attention_bias.weight":
             torch.randn(cfg["relative_attention_num_buckets"], cfg["num_heads"], generator=gen)}
    for i in range(cfg["num_layers"]):
        p = f"encoder.block.{i}.layer."
        for t in "qkv":
            w[p + f"0.SelfAttention.{t}.weight"] = lin(inner, d)
        w[p + "0.SelfAttention.o.weight"] = lin(d, inner)
        w[p + "0.layer_norm.weight"] = norm()
        w[p + "1.layer_norm.weight"] = norm()
        f = p + "1.DenseReluDense."
        for t in (["wi_0", "wi_1"] if cfg["feed_forward_proj"] == "gated-gelu" else ["wi"]):
            w[f + t + ".weight"] = lin(dff, d)
        w[f + "wo.weight"] = lin(d, dff)
    if extra:  # a seq2seq checkpoint's decoder and head, which the encoder must ignore
        w["decoder.block.0.layer.0.SelfAttention.q.weight"] = lin(inner, d)
        w["decoder.final_layer_norm.weight"] = norm()
        w["lm_head.weight"] = lin(vocab, d)
    return w


def make_encoder(out, captions_file, vocab, d_model, layers):
    texts = [line.strip() for line in open(captions_file, encoding="utf-8") if line.strip()]
    sp_bytes = train_spm(texts, vocab)
    sp = spm.SentencePieceProcessor(model_proto=sp_bytes)
    heads = max(1, d_model // 32)
    cfg = {"d_model": d_model, "d_kv": d_model // heads, "num_heads": heads, "d_ff": 2 * d_model,
           "num_layers": layers, "relative_attention_num_buckets": 32, "relative_attention_max_distance": 128,
           "layer_norm_epsilon": 1e-6, "vocab_size": sp.get_piece_size() + 8, "model_type": "t5",
           "feed_forward_proj": "gated-gelu", "eos_token_id": EOS, "pad_token_id": PAD}
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "config.json"), "w") as f:
        json.dump(cfg, f, indent=2)
    with open(os.path.join(out, "spiece.model"), "wb") as f:
        f.write(sp_bytes)
    safetensors_py.save(random_weights(cfg, torch.Generator().manual_seed(0), extra=False),
                        os.path.join(out, "model.safetensors"))
    lengths = sorted(len(tokenize(sp, t)) for t in texts)
    print(f"wrote {out}: {sp.get_piece_size()} pieces, d_model {d_model}, {layers} layers; tokens per caption: "
          f"median {lengths[len(lengths) // 2]}, max {lengths[-1]}")


def make_fixture(out):
    sp_bytes = train_spm(captions(200))
    sp = spm.SentencePieceProcessor(model_proto=sp_bytes)
    base = {"d_model": 32, "d_kv": 8, "num_heads": 4, "d_ff": 64, "num_layers": 2,
            "relative_attention_num_buckets": 8, "relative_attention_max_distance": 20,
            "layer_norm_epsilon": 1e-6, "vocab_size": sp.get_piece_size() + 8,  # + sentinels, like T5's 32128
            "model_type": "t5", "eos_token_id": EOS, "pad_token_id": PAD}
    if os.path.isdir(out):
        shutil.rmtree(out)
    ids = [tokenize(sp, c) for c in IO_CAPTIONS]
    longest = max(len(t) for t in ids)
    io_tensors = {"ids": torch.tensor([t + [PAD] * (longest - len(t)) for t in ids], dtype=torch.long),
                  "lengths": torch.tensor([len(t) for t in ids], dtype=torch.long)}
    io_tensors["input_ids"], io_tensors["mask"] = batch(sp, IO_CAPTIONS, M)
    gen = torch.Generator().manual_seed(1)
    for name, proj, dtype in [("relu", "relu", torch.float32), ("gated", "gated-gelu", torch.bfloat16)]:
        cfg = dict(base, feed_forward_proj=proj)
        w = random_weights(cfg, gen, extra=name == "relu")
        if name == "gated":
            w["encoder.embed_tokens.weight"] = w.pop("shared.weight")
        w = {k: v.to(dtype) for k, v in w.items()}
        d = os.path.join(out, name)
        os.makedirs(d)
        with open(os.path.join(d, "config.json"), "w") as f:
            json.dump(cfg, f, indent=2)
        with open(os.path.join(d, "spiece.model"), "wb") as f:
            f.write(sp_bytes)
        safetensors_py.save(w, os.path.join(d, "model.safetensors"))
        # The peer encodes with exactly what the file holds, read back as float32 (as the C++ loader does).
        stored, _ = safetensors_py.load(os.path.join(d, "model.safetensors"))
        io_tensors[name] = encode_captions({k: v.float() for k, v in stored.items()}, cfg, sp, IO_CAPTIONS, M)
    safetensors_py.save(io_tensors, os.path.join(out, "t5_io.safetensors"),
                        {"captions": json.dumps(IO_CAPTIONS), "m": str(M)})
    print(f"wrote {out}: {sp.get_piece_size()} pieces; ids {[len(t) for t in ids]}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--make-fixture", action="store_true", help="write the T5 fixture")
    ap.add_argument("--out", default="tests/fixtures/t5")
    ap.add_argument("--make-encoder", metavar="DIR", help="write a small random-weight T5 v1.1 encoder to DIR")
    ap.add_argument("--captions", help="--make-encoder: the captions (one a line) its SentencePiece model learns")
    ap.add_argument("--vocab", type=int, default=1000)
    ap.add_argument("--d-model", type=int, default=128)
    ap.add_argument("--layers", type=int, default=2)
    a = ap.parse_args()
    if a.make_encoder:
        if not a.captions:
            ap.error("--make-encoder needs --captions FILE")
        make_encoder(a.make_encoder, a.captions, a.vocab, a.d_model, a.layers)
    elif a.make_fixture:
        make_fixture(a.out)
    else:
        ap.error("nothing to do: pass --make-fixture or --make-encoder DIR")


if __name__ == "__main__":
    main()
