"""Prometheus metrics of one app: its own registry, counters and a collector of model gauges."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from app.service.registry import ModelRegistry, UnknownModel


class ModelCollector(Collector):
    """States, episodes and interventions of every model, read at scrape time."""

    def __init__(self, models: ModelRegistry) -> None:
        self.models = models

    def collect(self) -> Iterator[Metric]:
        states = GaugeMetricFamily("efsm_states", "States of each model", labels=["model"])
        episodes = CounterMetricFamily("efsm_episodes", "Finished episodes", labels=["model"])
        steps = CounterMetricFamily("efsm_learning_steps", "Learning steps", labels=["model"])
        interventions = CounterMetricFamily(
            "efsm_interventions", "Revised actions", labels=["model", "criterion"]
        )
        for name in self.models.names():
            try:
                shield = self.models.get(name).shield
            except UnknownModel:  # deleted while scraping
                continue
            states.add_metric([name], shield.n_states)
            episodes.add_metric([name], shield.counters.episodes)
            steps.add_metric([name], shield.counters.steps)
            for criterion, count in shield.counters.interventions.items():
                interventions.add_metric([name, criterion], count)
        yield from (states, episodes, steps, interventions)


class AppMetrics:
    """The metrics an app exposes on /metrics."""

    def __init__(self, models: ModelRegistry) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter("efsm_http_requests", "HTTP requests",
                                ["route", "method", "status"], registry=self.registry)
        self.latency = Histogram("efsm_http_request_seconds", "HTTP request latency",
                                 ["route"], registry=self.registry,
                                 buckets=(1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 0.1, 1))
        self.decisions = Counter("efsm_decisions", "Decisions by reason",
                                 ["model", "reason"], registry=self.registry)
        self.registry.register(ModelCollector(models))
        self._by_reason: dict[tuple[str, str], Counter] = {}

    def count_decision(self, model: str, reason: str, n: int = 1) -> None:
        """Count ``n`` decisions of a model for a reason (each pair's child counter found
        once: this is on every step's path)."""
        child = self._by_reason.get((model, reason))
        if child is None:
            child = self._by_reason[model, reason] = self.decisions.labels(model, reason)
        child.inc(n)
