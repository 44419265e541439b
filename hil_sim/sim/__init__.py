"""The simulated world: trajectories, walking, and the sensor that turns them into samples."""
