"""The shield service across processes and machines: models sharded by name.

An ingress answers the same HTTP and WebSocket contract as ``python -m app serve`` and hands
each request to the shard that owns its model; a shard is the plain service (its registry, its
journals and snapshots) over a data directory of its own, so every model has exactly one
writer. :mod:`app.cluster.placement` says which shard owns a name, :mod:`app.cluster.routing`
which models a request is about, :mod:`app.cluster.ingress` routes, :mod:`app.cluster.shard`
runs a shard and hands models over, and :mod:`app.cluster.ray_serve` deploys both on Ray Serve
(``python -m app serve-ray``; the ``ray`` extra).
"""
