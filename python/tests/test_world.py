"""gaia.WorldModel: rollouts token for token as `gaia generate` makes them, bits per token, bad input."""
import numpy as np
import pytest

import gaia
from conftest import read_rollout, run_gaia


def test_rollout_gives_the_tokens_of_gaia_generate(world, drive, models, tmp_path):
    out = tmp_path / "gen"
    run_gaia("generate", drive["tokens"], "--world", models / "world.safetensors", "--episode", "0", "--start", "3",
             "--prompt-frames", "2", "--frames", "3", "--futures", "2", "--steer", "strong-left", "--guidance", "4",
             "--seed", "5", "--out", out)
    expected = read_rollout(out / "rollout.safetensors")
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    got = world.rollout(prompt=ep.tokens[3:5], prompt_actions=ep.actions[3:5], steer="strong-left", guidance=4,
                        frames=3, futures=2, seed=5)
    assert got.dtype == np.int16 and got.shape == (2, 5, 9, 16)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got[:, :2], np.broadcast_to(ep.tokens[3:5], (2, 2, 9, 16)))  # the prompt first
    # Commands as an array are the same as the preset at the prompt's speed.
    speed = float(ep.actions[4, 0])
    cmd = np.tile(np.array([[speed, 0.033]], np.float32), (3, 1))
    np.testing.assert_array_equal(world.rollout(prompt=ep.tokens[3:5], prompt_actions=ep.actions[3:5], actions=cmd,
                                                guidance=4, frames=3, futures=2, seed=5), expected)


def test_rollout_at_bf16_gives_the_tokens_of_gaia_generate_at_bf16(world, drive, models, tmp_path):
    out = tmp_path / "gen-bf16"
    run_gaia("generate", drive["tokens"], "--world", models / "world.safetensors", "--episode", "0", "--start", "3",
             "--prompt-frames", "2", "--frames", "3", "--steer", "left", "--seed", "5", "--precision", "bf16",
             "--out", out)
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    got = world.rollout(prompt=ep.tokens[3:5], prompt_actions=ep.actions[3:5], steer="left", frames=3, seed=5,
                        precision="bf16")
    np.testing.assert_array_equal(got, read_rollout(out / "rollout.safetensors"))
    with pytest.raises(ValueError, match="precision 'fp64': expected fp32, bf16 or fp16"):
        world.rollout(frames=1, precision="fp64")


def test_rollout_from_nothing_with_text_and_argmax_is_deterministic(world):
    a = world.rollout(frames=2, sampling="argmax", text="night rain")
    b = world.rollout(frames=2, sampling="argmax", text="night rain", seed=9)
    assert a.shape == (1, 2, 9, 16)
    np.testing.assert_array_equal(a, b)  # argmax draws nothing
    c = world.rollout(frames=2, text="night rain", seed=1)
    d = world.rollout(frames=2, text="night rain", seed=2)
    assert not np.array_equal(c, d)  # top-k draws from its seed


def test_bits_per_token_scores_real_tokens_below_shuffled_ones(world, drive):
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    tokens, actions = ep.tokens[:24], ep.actions[:24]
    real = world.bits_per_token(tokens, actions)
    assert 0 < real < 10  # log2(1024) = 10 bits is a uniform guess
    assert world.bits_per_token(tokens.reshape(24, -1), actions) == pytest.approx(real, rel=1e-6)
    rng = np.random.default_rng(0)
    shuffled = rng.permutation(tokens.reshape(-1)).reshape(tokens.shape)
    assert world.bits_per_token(shuffled, actions) > real + 1
    assert world.bits_per_token(tokens) > 0


def test_bad_requests_are_one_clear_error(world, tmp_path):
    with pytest.raises(ValueError, match=r"prompt: an integer dtype .* of shape \[\*, 9, 16\] or \[\*, 144\]"):
        world.rollout(prompt=np.zeros((2, 8, 16), np.int16))
    with pytest.raises(ValueError, match=r"prompt tokens must be in \[0, K = 1024\)"):
        world.rollout(prompt=np.full((2, 9, 16), 2000, np.int16), frames=1)
    with pytest.raises(ValueError, match=r"actions: float32 or float64 of shape \[3, 2\] expected"):
        world.rollout(actions=np.zeros((2, 2), np.float32), frames=3)
    with pytest.raises(ValueError, match="steer: unknown preset 'sideways'"):
        world.rollout(steer="sideways", frames=1)
    with pytest.raises(ValueError, match="prompt_actions: given without a prompt"):
        world.rollout(prompt_actions=np.zeros((1, 2), np.float32))
    with pytest.raises(ValueError, match="sampling"):
        world.rollout(sampling="greedy", frames=1)
    with pytest.raises(ValueError, match="guidance needs something to guide towards"):
        world.rollout(guidance=3, frames=1)
    with pytest.raises(ValueError, match="actions: hold an infinite value"):
        world.bits_per_token(np.zeros((3, 9, 16), np.int16), np.full((3, 2), np.inf, np.float32))
    with pytest.raises(FileNotFoundError, match="world model"):
        gaia.WorldModel(str(tmp_path / "none.safetensors"))


def test_video_decoder_decodes_futures_deterministically(world, tokenizer, models):
    dec = gaia.VideoDecoder(str(models / "decoder.safetensors"), tokenizer)
    z = world.rollout(frames=7, futures=2, seed=3)                       # [2, 7, 9, 16]
    a = dec.decode(z[0], ddim_steps=2, fps=6.25, seed=1)
    assert a.dtype == np.uint8 and a.shape == (7, 72, 128, 3)
    np.testing.assert_array_equal(dec.decode(z[0], ddim_steps=2, fps=6.25, seed=1), a)  # the seed fixes the noise
    both = dec.decode(z, ddim_steps=2, fps=6.25, seed=1)
    assert both.shape == (2, 7, 72, 128, 3)
    # The diffusion decoder refines the tokenizer's frames: close to them, not equal.
    diff = np.abs(a.astype(np.int16) - tokenizer.decode(z[0]).astype(np.int16)).mean()
    assert 0 < diff < 40
    with pytest.raises(ValueError, match="fps: 6.25, 12.5 or 25 expected"):
        dec.decode(z[0], fps=10)
    with pytest.raises(FileNotFoundError):
        gaia.VideoDecoder(str(models / "none.safetensors"), tokenizer)
