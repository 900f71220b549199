"""The bed: virtual-bed rebound, the packed bed of fixed spheres (spheres and composites), what a jump is."""
