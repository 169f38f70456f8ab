from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from app.core.clustering import EvolvingClusterer
from app.core.config import ClusteringConfig
from tests.core import reference


def direct_potential(z: np.ndarray, samples: list[np.ndarray]) -> float:
    """P_k(z) = 1 / (1 + mean_l ||z - z_l||^2) over the k-1 earlier samples (spec §2.2)."""
    return 1.0 / (1.0 + float(np.mean([float(np.sum((z - s) ** 2)) for s in samples])))


def test_hand_computed_stream() -> None:
    c = EvolvingClusterer(ClusteringConfig(rho=0.7, epsilon=0.3), dim=1, max_states=10)
    first = c.learn_one(np.array([0.0]))
    assert (first.kind, first.index) == ("new", 0)
    assert c.potentials == pytest.approx([1.0])

    # k = 2: both potentials are 1 / 1.01, a tie: the sample joins state 0
    second = c.learn_one(np.array([0.1]))
    assert (second.kind, second.index) == ("assigned", 0)
    assert c.potentials == pytest.approx([1 / 1.01])
    # r = rho * eps + (1 - rho) * sqrt(scatter / N) = 0.21 + 0.3 * sqrt(0.01 / 2)
    assert c.radii == pytest.approx([0.21 + 0.3 * np.sqrt(0.005)])

    # k = 3: P(z3) = 2 / 3.81 is below every centre potential and z3 is 1.0 away: new state
    third = c.learn_one(np.array([1.0]))
    assert (third.kind, third.index) == ("new", 1)
    assert c.potentials == pytest.approx([2 * (1 / 1.01) / (1 + (1 / 1.01) * 2), 2 / 3.81])
    assert c.sq_distances(np.array([1.0])) == pytest.approx([1.0, 0.0])


def test_recursive_potentials_equal_the_direct_formula() -> None:
    rng = np.random.default_rng(3)
    c = EvolvingClusterer(ClusteringConfig(), dim=3, max_states=100)
    samples: list[np.ndarray] = []
    for _ in range(60):
        z = rng.uniform(0, 1, 3)
        if samples:
            k = len(samples) + 1
            beta = np.sum(samples, axis=0)
            sigma = float(np.sum(np.square(samples)))
            recursive = (k - 1) / ((k - 1) * (z @ z + 1) + sigma - 2 * z @ beta)
            assert recursive == pytest.approx(direct_potential(z, samples))
        c.learn_one(z)
        samples.append(z)


def test_a_dense_close_sample_replaces_the_nearest_centre_without_renumbering() -> None:
    c = EvolvingClusterer(ClusteringConfig(epsilon=0.3), dim=1, max_states=10)
    c.learn_one(np.array([0.0]))
    c.learn_one(np.array([0.02]))
    # 0.04 has the highest potential (P > max) and lies within epsilon: state 0 moves onto it
    update = c.learn_one(np.array([0.04]))
    assert (update.kind, update.index) == ("replaced", 0)
    assert c.centres[:, 0] == pytest.approx([0.04])
    assert c.learn_one(np.array([1.0])).index == 1
    assert c.centres[:, 0] == pytest.approx([0.04, 1.0])


def test_max_states_absorbs_novel_observations_into_the_nearest_state() -> None:
    c = EvolvingClusterer(ClusteringConfig(epsilon=0.1), dim=1, max_states=3)
    # the second sample always ties with the first (equal potentials at k = 2) and joins it
    kinds = [c.learn_one(np.array([z])).kind for z in (0.0, 0.05, 1.0, 2.0, 3.0, 4.0)]
    assert kinds == ["new", "assigned", "new", "new", "assigned", "assigned"]
    assert c.n_states == 3
    assert c.capacity_hits == 2  # 3.0 and 4.0 would each have made a state
    assert c.support.tolist() == [2, 1, 3]


def test_far_observations_create_states_and_states_are_never_removed() -> None:
    c = EvolvingClusterer(ClusteringConfig(), dim=2, max_states=100)
    counts = []
    rng = np.random.default_rng(0)
    for _ in range(300):
        c.learn_one(rng.uniform(0, 3, 2))
        counts.append(c.n_states)
    assert counts == sorted(counts)
    assert counts[-1] > 3


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_clustering_gives_the_numpy_reading(seed: int) -> None:
    rng = np.random.default_rng(seed)
    config = ClusteringConfig(epsilon=0.15)
    clusterer = EvolvingClusterer(config, 3, max_states=12)
    state: dict[str, Any] = {"centres": np.zeros((0, 3)), "beta": np.zeros(3), "sigma": 0.0, "k": 0}
    z = rng.uniform(0, 1, 3)
    for _ in range(3000):
        z = np.clip(z + rng.normal(0, 0.08, 3), 0, 1)
        kind = clusterer.learn_one(z).kind
        assert kind == reference.cluster(state, z, config.epsilon, config.rho, 12)
    np.testing.assert_allclose(clusterer.centres, state["centres"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(clusterer.potentials, state["potentials"], rtol=1e-12)
    np.testing.assert_allclose(clusterer.radii, state["radii"], rtol=1e-12)
