"""Experiments: arms x runs x episodes against a shield, their records and the paper's report."""
