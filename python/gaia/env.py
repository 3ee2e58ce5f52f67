"""gaia.env.DrivingEnv: a driving policy inside the world model, as a Gymnasium environment.

It follows Gymnasium's API (reset(seed, options) -> (observation, info); step(action) -> (observation, reward,
terminated, truncated, info)) without needing Gymnasium; where Gymnasium is importable, its spaces describe the
observation and the action (and the class is a gymnasium.Env).

Observation: {"frame": RGB uint8 [H, W, 3], "tokens": int16 [h, w]}. Action: [speed m/s, curvature 1/m] (+ =
left). The reward is a callable the user passes, reward(observation, action, info) -> float, where info holds
"read_back" (speed and curvature the dynamics probe reads from the last frames, once there are enough) and
"step"; `lane_keeping_reward` is an example. `truncated` comes at max_steps; the world has no end of its own, so
`terminated` is True only where the reward callable's `terminated(observation, info)` (if it has one) says so.
"""
import numpy as np

from . import _gaia

try:  # optional: Gymnasium is not a dependency
    import gymnasium as _gym
except ImportError:  # pragma: no cover - depends on the machine
    _gym = None

MAX_SPEED = 100.0     # m/s, as gaia sim accepts
MAX_CURVATURE = 0.5   # 1/m


class Box:
    """The part of gymnasium.spaces.Box the environment needs, where Gymnasium is absent."""

    def __init__(self, low, high, shape, dtype):
        self.low = np.broadcast_to(np.asarray(low, dtype=dtype), shape).copy()
        self.high = np.broadcast_to(np.asarray(high, dtype=dtype), shape).copy()
        self.shape, self.dtype = tuple(shape), np.dtype(dtype)
        self._rng = np.random.default_rng()

    def sample(self):
        if np.issubdtype(self.dtype, np.integer):
            return self._rng.integers(self.low, self.high, endpoint=True, dtype=self.dtype)
        return self._rng.uniform(self.low, self.high).astype(self.dtype)

    def contains(self, x):
        x = np.asarray(x)
        return x.shape == self.shape and bool(np.all(x >= self.low) and np.all(x <= self.high))

    def seed(self, seed=None):
        self._rng = np.random.default_rng(seed)


def _box(low, high, shape, dtype):
    return _gym.spaces.Box(low=low, high=high, shape=shape, dtype=dtype) if _gym else Box(low, high, shape, dtype)


def _dict(spaces):
    return _gym.spaces.Dict(spaces) if _gym else spaces


def lane_keeping_reward(plan=None, speed=8.0):
    """An example reward: the frames should show the planned curvature and speed.

    plan(step) -> curvature (1/m) the policy should drive (default: straight). The reward is minus the gap, in
    1/km, between the curvature the dynamics probe reads back from the last frames and the plan, minus a tenth of
    the speed gap in m/s; 0 until the probe has its frames. Needs a Sim with a dynamics probe.
    """
    plan = plan or (lambda step: 0.0)

    def reward(observation, action, info):
        rb = info.get("read_back")
        if rb is None:
            return 0.0
        return -1000.0 * abs(rb["curvature"] - plan(info["step"])) - 0.1 * abs(rb["speed"] - speed)

    return reward


class DrivingEnv(_gym.Env if _gym else object):
    """Closed-loop driving in the world model (gaia.Sim) as an environment.

    sim: a gaia.Sim (with a tokenizer for frames; with a dynamics probe for read-back), or the keyword arguments
        of one (world=..., tokenizer=..., probe=...).
    prompt: int16 tokens [P, h, w] (e.g. gaia.Dataset(TOKENS)[0].tokens[:4]), a gaia.Episode of a token dataset
        (its first prompt_frames steps and their actions), a video file (encoded by the Sim's tokenizer), or None
        (from nothing).
    reward: reward(observation, action, info) -> float (default: 0).
    max_steps: steps after which `truncated` is True.
    create: further settings of each session (guidance, top_k, temperature, action_negative, text), as
        gaia.Sim.create takes them.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 6.25}

    def __init__(self, sim=None, prompt=None, prompt_frames=4, reward=None, max_steps=200, seed=0,
                 render_mode=None, **create):
        if sim is None or isinstance(sim, dict):
            sim = _gaia.Sim(**(sim or {}))
        if not isinstance(sim, _gaia.Sim):
            raise ValueError("sim: a gaia.Sim or the keyword arguments of one expected")
        if max_steps < 1:
            raise ValueError(f"max_steps: at least 1 expected, got {max_steps}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: None or 'rgb_array' expected, got {render_mode!r}")
        self.sim, self.reward_fn, self.max_steps, self.render_mode = sim, reward, max_steps, render_mode
        self._create, self._seed = create, seed
        self._prompt, self._prompt_actions = self._prompt_of(prompt, prompt_frames)
        h, w = sim.world.grid
        spaces = {"tokens": _box(0, sim.world.K - 1, (h, w), np.int16)}
        if sim.tokenizer is not None:
            H, W = sim.tokenizer.frame_size
            spaces["frame"] = _box(0, 255, (H, W, 3), np.uint8)
        self.observation_space = _dict(spaces)
        self.action_space = _box([0.0, -MAX_CURVATURE], [MAX_SPEED, MAX_CURVATURE], (2,), np.float32)
        self.session, self._steps, self._last = None, 0, None

    def _prompt_of(self, prompt, frames):
        if prompt is None:
            return None, None
        if isinstance(prompt, str):
            if self.sim.tokenizer is None:
                raise ValueError("prompt: a video file needs a Sim with a tokenizer")
            return self.sim.tokenizer.encode_video(prompt, frames), None
        if isinstance(prompt, _gaia.Episode):
            return prompt.tokens[:frames], prompt.actions[:frames]
        return np.asarray(prompt), None

    def reset(self, seed=None, options=None):
        """A new session from the prompt; options may replace "prompt" and "text" (as the constructor takes them)."""
        options = options or {}
        if seed is not None:
            self._seed = seed
        prompt, actions = self._prompt, self._prompt_actions
        if "prompt" in options:
            prompt, actions = self._prompt_of(options["prompt"], options.get("prompt_frames", 4))
        create = dict(self._create)
        if "text" in options:
            create["text"] = options["text"]
        self.session = self.sim.create(prompt=prompt, prompt_actions=actions, seed=self._seed, **create)
        self._seed += 1  # the next reset draws another future unless told a seed
        self._steps = 0
        tokens = self.session.tokens
        obs = {"tokens": tokens[-1] if len(tokens) else np.zeros(self.sim.world.grid, np.int16)}
        if self.sim.tokenizer is not None:
            obs["frame"] = self.sim.tokenizer.decode(obs["tokens"])
        self._last = obs
        return obs, {"step": self.session.steps - 1, "read_back": None, "prompt_frames": self.session.prompt_frames}

    def step(self, action):
        if self.session is None:
            raise RuntimeError("DrivingEnv: call reset() before step()")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (2,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action: [speed m/s, curvature 1/m] expected, got {action!r}")
        speed = float(np.clip(a[0], 0.0, MAX_SPEED))
        curvature = float(np.clip(a[1], -MAX_CURVATURE, MAX_CURVATURE))
        r = self.session.step(speed, curvature, frame=self.sim.tokenizer is not None)
        obs = {"tokens": r["tokens"]}
        if r["frame"] is not None:
            obs["frame"] = r["frame"]
        self._steps += 1
        info = {"step": self._steps - 1, "read_back": r["read_back"], "command": (speed, curvature)}
        reward = float(self.reward_fn(obs, a, info)) if self.reward_fn else 0.0
        ends = getattr(self.reward_fn, "terminated", None)
        terminated = bool(ends(obs, info)) if ends else False
        truncated = self._steps >= self.max_steps
        self._last = obs
        return obs, reward, terminated, truncated, info

    def render(self):
        if self._last is None or "frame" not in self._last:
            return None
        return self._last["frame"]

    def close(self):
        self.session = None
