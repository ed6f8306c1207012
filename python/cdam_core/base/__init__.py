"""cdam_core.base."""
