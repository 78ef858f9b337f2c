"""The engineer's answers: in tolerance (check), what changed (history), did it work (compare)."""
