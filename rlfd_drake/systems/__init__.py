"""Drake LeafSystems of the rLfD diagram, one per file."""
