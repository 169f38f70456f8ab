"""Process concerns around the core: many models, locks, durability. Knows nothing of HTTP."""
