"""Per-paper experiments of the repro suite (registered via entry points)."""
