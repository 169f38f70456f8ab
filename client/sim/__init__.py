"""The car-following world: lead-vehicle speed profiles and the simulator.

Importing this package registers ``CarFollowing-v0`` with Gymnasium (800 steps an episode), so
``gym.make("client.sim:CarFollowing-v0")`` works without an import of its own.
"""

from client.sim.car_following import ENV_ID, CarFollowingEnv

__all__ = ["ENV_ID", "CarFollowingEnv"]
