"""The car-following world: lead-vehicle speed profiles and the simulator."""
