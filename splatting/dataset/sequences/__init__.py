"""Street sequences: cyclists moving through a driving scene (docs/sequences.md)."""
