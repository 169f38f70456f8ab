"""The controller side: clients of the shield service (and, later, the simulator and DDPG)."""
