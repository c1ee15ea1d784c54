"""A random agent choosing the backstepping gains (Kx, Ky, Ktheta) every control period, for one episode.

python examples/random_agent.py [--steps N] [--seed S]
"""

# test-args: --steps 200
import argparse
from pathlib import Path

import gymnasium

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=None, help="stop after this many steps (default: the episode)")
parser.add_argument("--seed", type=int, default=0)
args = parser.parse_args()

scenario = Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml"
# "ddtrack.envs:" imports ddtrack.envs, which registers the environment (Gymnasium 1.x has no plugins)
env = gymnasium.make("ddtrack.envs:ddtrack/DiffDriveTracking-v0", scenario=scenario, action_mode="gains")
env.action_space.seed(args.seed)
obs, info = env.reset(seed=args.seed)
total, steps, done = 0.0, 0, False
while not done and (args.steps is None or steps < args.steps):
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())  # a in [-1, 1]^3 -> gains
    total, steps, done = total + reward, steps + 1, terminated or truncated
print(f"{steps} steps ({info['t']:g} s), status {info['status']}, final e_tr {info['e_tr']:.3f} m, return {total:.1f}")
env.close()
