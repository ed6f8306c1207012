"""cdam_core.record."""
