"""cdam_core.report."""
