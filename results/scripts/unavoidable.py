"""Which late collisions of an experiment no action could have avoided.

An episode's start (the lead's speed profile, the headway, the ego speed) comes from the
simulator's generator alone, drawn at each reset from the run's seed, whatever the actions
were; so each episode can be started again and driven otherwise. For every collision after
``--after`` in the records under OUT, this replays the episode's start under full braking from
its first step and says whether the collision happens anyway (then nothing could avoid it:
braking harder is impossible, and braking less only closes the gap sooner).

    python results/scripts/unavoidable.py results/paper-protocol-local --after 150

With ``--every-start`` it replays every episode after ``--after`` instead, failed or not, and
says which runs drew a start that no controller survives: the runs that no shield can keep
free of failures there, whatever it does.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from client.experiment.runner import profiles  # noqa: E402
from client.sim.car_following import A_MAX, CarFollowingEnv  # noqa: E402


def collides_under_full_braking(env: CarFollowingEnv) -> bool:
    """From the episode's start, full braking at every step: does the lead still hit?"""
    while True:
        _, _, terminated, truncated, info = env.step(np.array([-A_MAX]))
        if terminated or truncated:
            return bool(info.get("event") == "collision")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--after", type=int, default=150)
    parser.add_argument("--every-start", action="store_true",
                        help="replay every episode after --after, failed or not")
    args = parser.parse_args()
    if args.every_start:
        every_start(args.out, args.after)
        return
    unavoidable = total = 0
    for path in sorted((args.out / "records").glob("*.jsonl")):
        lines = [json.loads(line) for line in path.open()]
        header = lines[0]["header"]
        late = {r["episode"]: r for r in lines[1:]
                if r["outcome"] == "collision" and r["episode"] > args.after}
        if not late:
            continue
        env = CarFollowingEnv(lead=profiles(header["config"]["lead"]))
        env.reset(seed=header["seed"])
        for episode in range(1, max(late) + 1):
            if episode > 1:
                env.reset()
            if episode in late:
                start = env.state()
                anyway = collides_under_full_braking(env)
                env.restore(start)
                total += 1
                unavoidable += anyway
                sys.stdout.write(f"{path.stem} episode {episode}: collision at step "
                                 f"{late[episode]['steps']}, under full braking "
                                 f"{'a collision anyway' if anyway else 'none'}\n")
    sys.stdout.write(f"{unavoidable} of {total} collisions after episode {args.after} "
                     "could not be avoided\n")


def every_start(out: Path, after: int) -> None:
    """Per run, the episodes after ``after`` whose start collides under full braking."""
    doomed_runs = 0
    paths = sorted((out / "records").glob("*.jsonl"))
    for path in paths:
        with path.open() as file:
            header = json.loads(file.readline())["header"]
        episodes = header["config"]["episodes"]
        env = CarFollowingEnv(lead=profiles(header["config"]["lead"]))
        env.reset(seed=header["seed"])
        doomed = []
        for episode in range(1, episodes + 1):
            if episode > 1:
                env.reset()
            if episode > after:
                start = env.state()
                if collides_under_full_braking(env):
                    doomed.append(episode)
                env.restore(start)
        doomed_runs += bool(doomed)
        sys.stdout.write(f"{path.stem}: {len(doomed)} of {episodes - after} starts after "
                         f"episode {after} collide under full braking {doomed}\n")
    sys.stdout.write(f"{doomed_runs} of {len(paths)} runs drew such a start: at most "
                     f"{len(paths) - doomed_runs} can be free of failures after episode "
                     f"{after}\n")


if __name__ == "__main__":
    main()
