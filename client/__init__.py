"""The controller side: clients of the shield service, the car-following simulator and its data."""
