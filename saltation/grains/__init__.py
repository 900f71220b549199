"""The grains: initial conditions and the bonded-sphere shapes of irregular grains."""
