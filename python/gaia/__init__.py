"""gaia: a generative world model for autonomous driving (GAIA-1), in-process from Python.

The classes are thin layers over the C++ library the `gaia` command runs, so the same seed and settings give the
same tokens as the CLI. Arrays in and out are NumPy arrays (`torch.from_numpy` makes a tensor of one without a
copy): frames RGB uint8 [N, H, W, 3], tokens int16 [N, h, w], signals float32 (speed m/s, curvature 1/m, + = left).

    import gaia
    tok = gaia.Tokenizer("models/tokenizer.safetensors")
    world = gaia.WorldModel("models/world.safetensors")
    tokens = tok.encode(frames)                                 # [N, 9, 16] int16
    futures = world.rollout(prompt=tokens[-4:], steer="left", frames=8, futures=2, seed=0)
    video = tok.decode(futures[0])                              # [12, 72, 128, 3] uint8

docs/python.md has the whole API, the closed-loop Sim and the gaia.env.DrivingEnv environment.
"""
from ._gaia import (Dataset, Episode, Session, Sim, Tokenizer, VideoDecoder, WorldModel, set_threads,
                    threads)

__all__ = ["Dataset", "Episode", "Session", "Sim", "Tokenizer", "VideoDecoder", "WorldModel", "set_threads",
           "threads", "env"]
__version__ = "0.1.0"


def __getattr__(name):  # gaia.env on first use (it imports Gymnasium where present)
    if name == "env":
        import importlib
        return importlib.import_module(".env", __name__)
    raise AttributeError(f"module 'gaia' has no attribute {name!r}")
