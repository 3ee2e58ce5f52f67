#!/usr/bin/python3
"""Tiny teacher fixtures for the tokenizer's VGG16 / ViT cross-checks against torchvision (random init, seed 0).
Run from the repo root:  /usr/bin/python3 tools/make_teacher_fixtures.py
- vgg16_narrow.safetensors: torchvision VGG16 topology (13 convs, 5 pools) with narrow widths; vgg16_narrow_io: input
  and the relu1_2 / relu2_2 / relu3_3 / relu4_3 / relu5_3 activations.
- vit_tv.safetensors (torchvision layout) and vit_timm.safetensors (same weights, timm/DINO names); vit_io: input and
  the final-norm patch tokens [B, D, h, w]."""
import re

import torch
import torchvision
from torchvision.models.vgg import VGG, make_layers

import safetensors_py

out = "tests/fixtures/"
torch.manual_seed(0)

# VGG16 ("D" configuration) at 1/16 width.
cfg = [4, 4, "M", 8, 8, "M", 16, 16, 16, "M", 32, 32, 32, "M", 32, 32, 32, "M"]
vgg = VGG(make_layers(cfg), init_weights=True).eval()
feats = {k: v for k, v in vgg.state_dict().items() if k.startswith("features.")}
safetensors_py.save(feats, out + "vgg16_narrow.safetensors", {"made_by": "tools/make_teacher_fixtures.py"})
x = torch.rand(2, 3, 32, 48) * 2 - 1
mean = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
std = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)
h = ((x + 1) / 2 - mean) / std
taps = {}
with torch.no_grad():
    for i, layer in enumerate(vgg.features):
        h = layer(h)
        if i in (3, 8, 15, 22, 29):
            taps[f"relu{len(taps)}"] = h.clone()
safetensors_py.save({"input": x, **taps}, out + "vgg16_narrow_io.safetensors")

# torchvision ViT, tiny.
vit = torchvision.models.VisionTransformer(image_size=32, patch_size=8, num_layers=2, num_heads=2,
                                           hidden_dim=16, mlp_dim=32).eval()
with torch.no_grad():  # random class token / positions so the test sees them
    vit.class_token.normal_()
    vit.encoder.pos_embedding.normal_(std=0.5)
sd = {k: v for k, v in vit.state_dict().items() if not k.startswith("heads.")}
safetensors_py.save(sd, out + "vit_tv.safetensors", {"num_heads": "2"})
timm = {}
for k, v in sd.items():
    k2 = (k.replace("conv_proj", "patch_embed.proj").replace("class_token", "cls_token")
          .replace("encoder.pos_embedding", "pos_embed").replace("encoder.ln.", "norm."))
    m = re.match(r"encoder\.layers\.encoder_layer_(\d+)\.(.*)", k2)
    if m:
        sub = (m.group(2).replace("ln_1", "norm1").replace("ln_2", "norm2")
               .replace("self_attention.in_proj_weight", "attn.qkv.weight")
               .replace("self_attention.in_proj_bias", "attn.qkv.bias")
               .replace("self_attention.out_proj", "attn.proj").replace("mlp.0", "mlp.fc1").replace("mlp.3", "mlp.fc2"))
        k2 = f"blocks.{m.group(1)}.{sub}"
    timm[k2] = v
safetensors_py.save(timm, out + "vit_timm.safetensors", {"num_heads": "2"})
xi = torch.rand(2, 3, 32, 32) * 2 - 1
with torch.no_grad():
    t = vit._process_input(((xi + 1) / 2 - mean) / std)
    t = torch.cat([vit.class_token.expand(2, -1, -1), t], dim=1)
    t = vit.encoder(t)[:, 1:]  # includes the final LayerNorm
    patches = t.transpose(1, 2).reshape(2, 16, 4, 4)
safetensors_py.save({"input": xi, "patches": patches}, out + "vit_io.safetensors")
print("wrote teacher fixtures")
