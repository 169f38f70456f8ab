"""The e-FSM safety shield: an online evolving model that revises a controller's actions."""

__version__ = "0.1.0"
