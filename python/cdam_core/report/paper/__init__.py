"""cdam_core.report.paper."""
