"""Sub-models of one grain: the fluid as a grain sees it, fluid forces, spin, the Basset history, random numbers."""
