#!/usr/bin/env python3
"""A PyTorch policy that learns to drive inside the world model (gaia.env.DrivingEnv), scored against the
scripted lane keeper on the same plans and seeds.

The task is lane_keeper.py's: drive the planned curvature (straight, a left bend, straight, a right bend) at a
steady speed, as the frames show it (the dynamics probe's read-back). The policy sees the plan and the read-back
and outputs a correction to the command (a small MLP, Gaussian exploration, REINFORCE with a running baseline),
for --steps environment steps (a few hundred: a minute or two on a laptop's CPU). Then both controllers drive
--eval-episodes episodes each and their mean reward (lane_keeping_reward: minus the read-back's gap to the plan,
1/km) is printed side by side:

    PYTHONPATH=build/python examples/torch_policy.py --steps 300
"""
import argparse
import os
import time

import numpy as np
import torch

import gaia
from gaia.env import DrivingEnv, lane_keeping_reward

MODELS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "models")


def make_plan(bend, phase, period=24):
    """Curvature (1/m) to drive at each step: straight, left, straight, right, a quarter period each."""
    return lambda step: [0.0, bend, 0.0, -bend][int(4 * ((step + phase) % period) / period)]


def features(plan, step, read, speed):
    """What the policy sees: the plan now and over the probe's last frames, and what the frames showed."""
    window = np.mean([plan(max(0, step - j)) for j in range(4)])
    rc, rs = (read["curvature"], read["speed"]) if read else (window, speed)
    return torch.tensor([50 * plan(step), 50 * window, 50 * rc, (rs - speed) / 5], dtype=torch.float32)


class Policy(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.net = torch.nn.Sequential(torch.nn.Linear(4, 32), torch.nn.Tanh(), torch.nn.Linear(32, 2))
        self.log_std = torch.nn.Parameter(torch.tensor([-0.7, -0.7]))
        torch.nn.init.zeros_(self.net[2].weight)
        torch.nn.init.zeros_(self.net[2].bias)

    def forward(self, x):  # -> a Normal over (curvature correction in 1/50 m, speed correction in 5 m/s)
        return torch.distributions.Normal(self.net(x), self.log_std.exp())


def command(plan, step, correction, speed):
    return np.array([np.clip(speed + 5 * correction[1], 0, 30), np.clip(plan(step) + correction[0] / 50, -0.05, 0.05)],
                    np.float32)


def scripted(plan, step, read, speed, gain=0.5):
    """lane_keeper.py's controller: the plan, corrected by the read-back's gap to the plan of its frames."""
    c = plan(step)
    if read:
        c += gain * (np.mean([plan(max(0, step - j)) for j in range(4)]) - read["curvature"])
    return np.array([speed, np.clip(c, -0.05, 0.05)], np.float32)


def episode(env, plan, speed, seed, act):
    env.reward_fn = lane_keeping_reward(plan, speed)
    env.reset(seed=seed)
    read, total, done, step = None, [], False, 0
    while not done:
        _, reward, terminated, truncated, info = env.step(act(step, read))
        read, done = info["read_back"], terminated or truncated
        total.append(reward)
        step += 1
    return total


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--world", default=os.path.join(MODELS, "world.safetensors"))
    ap.add_argument("--tokenizer", default=os.path.join(MODELS, "tokenizer.safetensors"))
    ap.add_argument("--probe", default=os.path.join(MODELS, "probe-dynamics.safetensors"))
    ap.add_argument("--tokens", help="token dataset whose first episode is the prompt (default: from nothing)")
    ap.add_argument("--steps", type=int, default=300, help="environment steps to learn from")
    ap.add_argument("--episode-steps", type=int, default=24)
    ap.add_argument("--eval-episodes", type=int, default=3)
    ap.add_argument("--speed", type=float, default=8)
    ap.add_argument("--bend", type=float, default=0.02)
    ap.add_argument("--lr", type=float, default=0.03)
    a = ap.parse_args()
    gaia.set_threads(1)
    torch.manual_seed(0)

    sim = gaia.Sim(a.world, a.tokenizer, probe=a.probe)
    prompt = gaia.Dataset(a.tokens)[0] if a.tokens else None
    env = DrivingEnv(sim, prompt=prompt, max_steps=a.episode_steps, guidance=16)
    policy = Policy()
    opt = torch.optim.Adam(policy.parameters(), lr=a.lr)
    baseline, learned, start, n = 0.0, 0, time.perf_counter(), 0
    rng = np.random.default_rng(0)
    while learned < a.steps:
        plan = make_plan(a.bend, int(rng.integers(24)))
        logps = []

        def act(step, read):
            dist = policy(features(plan, step, read, a.speed))
            u = dist.sample()
            logps.append(dist.log_prob(u).sum())
            return command(plan, step, u.numpy(), a.speed)

        rewards = episode(env, plan, a.speed, seed=1000 + n, act=act)
        # Reward to go: an action shows in the read-back of the next frames, so it is credited with what follows.
        togo = torch.tensor(np.cumsum(rewards[::-1])[::-1].copy(), dtype=torch.float32)
        loss = -(torch.stack(logps) * (togo - baseline)).mean() / 100
        opt.zero_grad()
        loss.backward()
        opt.step()
        baseline = 0.8 * baseline + 0.2 * float(togo.mean())
        learned += len(rewards)
        n += 1
        print(f"episode {n:3d}  steps {learned:4d}  mean reward {np.mean(rewards):7.2f}  "
              f"{time.perf_counter() - start:5.0f} s", flush=True)

    scores = {"learned": [], "scripted": []}
    for e in range(a.eval_episodes):
        plan = make_plan(a.bend, 6 * e)
        with torch.no_grad():
            scores["learned"] += episode(env, plan, a.speed, 5000 + e,
                                         lambda s, r: command(plan, s, policy(features(plan, s, r, a.speed)).mean.numpy(), a.speed))
        scores["scripted"] += episode(env, plan, a.speed, 5000 + e, lambda s, r: scripted(plan, s, r, a.speed))
    print(f"mean reward over {a.eval_episodes} episodes (minus 1/km of curvature gap): learned "
          f"{np.mean(scores['learned']):.2f}, scripted {np.mean(scores['scripted']):.2f} "
          f"({time.perf_counter() - start:.0f} s in all)")


if __name__ == "__main__":
    main()
