"""The runtime error model every stage shares: effects beyond the PIGEs, excitation projections, test trajectories."""
