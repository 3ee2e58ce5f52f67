"""gaia.env.DrivingEnv: Gymnasium's API over a closed-loop session, with a reward the user passes."""
import numpy as np
import pytest

import gaia
from gaia.env import DrivingEnv, lane_keeping_reward


@pytest.fixture(scope="module")
def env(world, tokenizer, models, drive):
    sim = gaia.Sim(world, tokenizer, probe=str(models / "probe-dynamics.safetensors"))
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    return DrivingEnv(sim, prompt=ep, prompt_frames=3, reward=lane_keeping_reward(lambda step: 0.01), max_steps=6,
                      guidance=8)


def test_reset_and_step_follow_gymnasiums_api(env):
    obs, info = env.reset(seed=3)
    assert obs["frame"].shape == (72, 128, 3) and obs["tokens"].shape == (9, 16)
    assert info["prompt_frames"] == 3
    assert env.action_space.contains(np.array([8.0, 0.01], np.float32))
    rewards, truncated, steps = [], False, 0
    while not truncated:
        obs, reward, terminated, truncated, info = env.step(np.array([8.0, 0.01], np.float32))
        steps += 1
        assert not terminated and obs["frame"].dtype == np.uint8
        rewards.append(reward)
        if info["read_back"] is not None:  # the probe has its frames: the reward is the gap to the plan
            rb = info["read_back"]
            assert reward == pytest.approx(-1000 * abs(rb["curvature"] - 0.01) - 0.1 * abs(rb["speed"] - 8.0))
    assert steps == 6 and any(r < 0 for r in rewards)
    np.testing.assert_array_equal(env.render(), obs["frame"])
    # The same seed, the same future.
    first = env.reset(seed=3)[0]
    again = env.step([8.0, 0.01])[0]
    env.reset(seed=3)
    np.testing.assert_array_equal(env.step([8.0, 0.01])[0]["tokens"], again["tokens"])
    np.testing.assert_array_equal(first["tokens"], env.reset(seed=3)[0]["tokens"])


def test_bad_actions_and_settings_are_clear_errors(env, world):
    env.reset()
    with pytest.raises(ValueError, match="action"):
        env.step([8.0])
    with pytest.raises(ValueError, match="action"):
        env.step([np.nan, 0.0])
    with pytest.raises(ValueError, match="max_steps"):
        DrivingEnv(gaia.Sim(world), max_steps=0)
    obs, _ = DrivingEnv(gaia.Sim(world)).reset()  # tokens only, from nothing
    assert "frame" not in obs and obs["tokens"].shape == (9, 16)
