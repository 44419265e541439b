"""The simulated world: trajectories, walking, and the sensor that turns them into samples."""

# its modules, which users import by name (``from accelnav.hil_sim.sim import sensor``)
__all__ = [
    "sensor",
    "trajectories",
    "walking",
]
