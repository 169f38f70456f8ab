"""Hypothesis profile: a modest, derandomised example budget keeps the suite fast and stable."""

from hypothesis import settings

settings.register_profile("project", max_examples=40, derandomize=True, deadline=None)
settings.load_profile("project")
