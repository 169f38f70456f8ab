"""Prometheus metrics of one app: its own registry, counters and a collector of model gauges."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from app.service.registry import ModelRegistry, UnknownModel


class ModelCollector(Collector):
    """States, episodes, interventions and decisions of every model, read at scrape time
    (so that a step costs the metrics nothing)."""

    def __init__(self, models: ModelRegistry) -> None:
        self.models = models

    def collect(self) -> Iterator[Metric]:
        states = GaugeMetricFamily("efsm_states", "States of each model", labels=["model"])
        episodes = CounterMetricFamily("efsm_episodes", "Finished episodes", labels=["model"])
        steps = CounterMetricFamily("efsm_learning_steps", "Learning steps", labels=["model"])
        interventions = CounterMetricFamily(
            "efsm_interventions", "Revised actions", labels=["model", "criterion"]
        )
        decisions = CounterMetricFamily(
            "efsm_decisions",
            "Decisions served by this process, by reason",
            labels=["model", "reason"],
        )
        for name in self.models.names():
            try:
                model = self.models.get(name)
            except UnknownModel:  # deleted while scraping
                continue
            shield = model.shield
            states.add_metric([name], shield.n_states)
            episodes.add_metric([name], shield.counters.episodes)
            steps.add_metric([name], shield.counters.steps)
            for criterion, count in shield.counters.interventions.items():
                interventions.add_metric([name, criterion], count)
            for reason, count in dict(model.decisions).items():  # (a copy: steps go on)
                decisions.add_metric([name, reason], count)
        yield from (states, episodes, steps, interventions, decisions)


class AppMetrics:
    """The metrics an app exposes on /metrics."""

    def __init__(self, models: ModelRegistry) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "efsm_http_requests",
            "HTTP requests",
            ["route", "method", "status"],
            registry=self.registry,
        )
        self.latency = Histogram(
            "efsm_http_request_seconds",
            "HTTP request latency",
            ["route"],
            registry=self.registry,
            buckets=(1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 0.1, 1),
        )
        self.registry.register(ModelCollector(models))
