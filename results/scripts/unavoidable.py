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
free of failures there, whatever it does. The runs come from OUT's records, or, without OUT,
from a base seed as the experiment runner derives them (``--seed 1000 --runs 10 --episodes
1500``: the paper's protocol on the evaluation seeds). ``--braking`` replays a weaker full
braking (1.9: what the risk reviser applied at most before its end bins applied the range's
ends).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from client.experiment.runner import ExperimentConfig, profiles, run_seeds  # noqa: E402
from client.sim.car_following import A_MAX, CarFollowingEnv  # noqa: E402


def collides_under_full_braking(env: CarFollowingEnv, braking: float = A_MAX) -> bool:
    """From the episode's start, braking at ``braking`` m/s^2 every step: does the lead
    still hit?"""
    while True:
        _, _, terminated, truncated, info = env.step(np.array([-braking]))
        if terminated or truncated:
            return bool(info.get("event") == "collision")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, nargs="?")
    parser.add_argument("--after", type=int, default=150)
    parser.add_argument(
        "--every-start",
        action="store_true",
        help="replay every episode after --after, failed or not",
    )
    parser.add_argument("--braking", type=float, default=A_MAX, help="m/s^2 (default: 2)")
    parser.add_argument("--seed", type=int, help="without OUT: the runs' base seed")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=1500)
    args = parser.parse_args()
    if args.out is None:
        if args.seed is None:
            parser.error("give OUT, or --every-start with --seed")
        lead = ExperimentConfig().lead
        runs = [
            (f"run {i}", seed, args.episodes, lead)
            for i, seed in enumerate(run_seeds(args.seed, args.runs))
        ]
        every_start(runs, args.after, args.braking)
        return
    if args.every_start:
        every_start(recorded_runs(args.out), args.after, args.braking)
        return
    unavoidable = total = 0
    for path in sorted((args.out / "records").glob("*.jsonl")):
        lines = [json.loads(line) for line in path.open()]
        header = lines[0]["header"]
        late = {
            r["episode"]: r
            for r in lines[1:]
            if r["outcome"] == "collision" and r["episode"] > args.after
        }
        if not late:
            continue
        env = CarFollowingEnv(lead=profiles(header["config"]["lead"]))
        env.reset(seed=header["seed"])
        for episode in range(1, max(late) + 1):
            if episode > 1:
                env.reset()
            if episode in late:
                start = env.state()
                anyway = collides_under_full_braking(env, args.braking)
                env.restore(start)
                total += 1
                unavoidable += anyway
                sys.stdout.write(
                    f"{path.stem} episode {episode}: collision at step "
                    f"{late[episode]['steps']}, under full braking "
                    f"{'a collision anyway' if anyway else 'none'}\n"
                )
    sys.stdout.write(
        f"{unavoidable} of {total} collisions after episode {args.after} could not be avoided\n"
    )


def recorded_runs(out: Path) -> list[tuple[str, int, int, str]]:
    """Each run under OUT's records: its name, seed, episodes and lead data."""
    runs = []
    for path in sorted((out / "records").glob("*.jsonl")):
        with path.open() as file:
            header = json.loads(file.readline())["header"]
        runs.append(
            (path.stem, header["seed"], header["config"]["episodes"], header["config"]["lead"])
        )
    return runs


def every_start(runs: list[tuple[str, int, int, str]], after: int, braking: float) -> None:
    """Per run, the episodes after ``after`` whose start collides under full braking."""
    doomed_runs = 0
    for name, seed, episodes, lead in runs:
        env = CarFollowingEnv(lead=profiles(lead))
        env.reset(seed=seed)
        doomed = []
        for episode in range(1, episodes + 1):
            if episode > 1:
                env.reset()
            if episode > after:
                start = env.state()
                if collides_under_full_braking(env, braking):
                    doomed.append(episode)
                env.restore(start)
        doomed_runs += bool(doomed)
        sys.stdout.write(
            f"{name}: {len(doomed)} of {episodes - after} starts after "
            f"episode {after} collide under braking at {braking:g} m/s^2 "
            f"{doomed}\n"
        )
    sys.stdout.write(
        f"{doomed_runs} of {len(runs)} runs drew such a start: at most "
        f"{len(runs) - doomed_runs} can be free of failures after episode "
        f"{after}\n"
    )


if __name__ == "__main__":
    main()
