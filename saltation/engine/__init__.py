"""The run: one simulation's set-up and run loop (spheres, composites), the stepping, the jump statistics."""
