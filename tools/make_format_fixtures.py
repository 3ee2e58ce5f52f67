#!/usr/bin/python3
"""Writes tests/fixtures/ for the format cross-checks with a peer implementation (numpy; a safetensors file
laid out by hand from the Hugging Face spec, and one through torch's own tensor bytes). Run from the repo root:
    /usr/bin/python3 tools/make_format_fixtures.py
The C++ tests recompute the same values from the same formulas and compare."""
import numpy as np
import torch

import safetensors_py

out = "tests/fixtures/"

# A token file as another tokenizer would write it: [frames, 8, 16] int16, values (7 i + 3) mod 1024.
tokens = ((np.arange(6 * 8 * 16) * 7 + 3) % 1024).astype(np.int16).reshape(6, 8, 16)
np.save(out + "tokens_6x8x16_int16.npy", tokens)
np.save(out + "ramp_f32.npy", (np.arange(10, dtype=np.float32) / 4 - 1).reshape(2, 5))
np.save(out + "ramp_u8.npy", np.arange(17, dtype=np.uint8))

# safetensors: tensors from torch, header per the spec (sorted names, 8-byte aligned header, __metadata__).
tensors = {
    "encoder.weight": torch.arange(12, dtype=torch.float32).reshape(3, 4) / 8 - 0.5,
    "encoder.half": (torch.arange(6, dtype=torch.float32) / 3).to(torch.float16),
    "encoder.bf16": (torch.arange(6, dtype=torch.float32) - 2.5).to(torch.bfloat16),
    "codes": torch.arange(5, dtype=torch.int64) * 1000,
}
safetensors_py.save(tensors, out + "peer.safetensors", {"format": "pt", "made_by": "tools/make_format_fixtures.py"})
print("wrote fixtures")
