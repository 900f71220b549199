"""Free flight: the RK4 step of spheres and of rigid bonded-sphere composites."""
